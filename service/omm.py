"""An OMM body validated, bounded and normalised at the door, before anything is stored.

An orbit document is stored and read again by every later retraining and diagnosis, so what is
wrong with it must be refused when it arrives (422 naming ``omm.<KEY>``), never found at the next
use. :func:`normalise_omm` walks every key:

* keys are compared in upper case; two keys equal but for case are refused;
* keys of the OMM standard (CCSDS 502.0-B-3: header, metadata, mean elements, spacecraft
  parameters, TLE-related parameters, covariance) and ``USER_DEFINED_*`` are kept;
* the catalogue columns that Space-Track and CelesTrak add to their GP/OMM JSON (``GP_ID``,
  ``TLE_LINE1``, ``DECAY_DATE``, …) are recognised and dropped: SGP4 does not read them;
* any other key is refused, naming it: a misspelt element must not be silently ignored;
* every value is a string, a finite number or null — never an array or an object — with strings
  of at most :data:`MAX_TEXT_CHARS` characters (``COMMENT`` :data:`MAX_COMMENT_CHARS`) and numbers
  of magnitude below :data:`MAX_ABS_NUMBER` (an integer of 10^30 is refused, not stored);
* ``CLASSIFICATION_TYPE``, when given, is one of ``U``, ``C``, ``S`` (an empty one is refused);
* at most :data:`MAX_KEYS` keys.

The elements themselves (ranges, SGP4's own checks) are then checked by
``orbitcal.orbit.Orbit.from_omm``, as for the CLI.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # orbitcal.orbit (sgp4) is imported when an orbit arrives, not at start-up
    from orbitcal.orbit import OMMError

__all__ = [
    "MAX_ABS_NUMBER",
    "MAX_COMMENT_CHARS",
    "MAX_KEYS",
    "MAX_TEXT_CHARS",
    "OMM_KEYS",
    "normalise_omm",
]

#: Keywords of CCSDS 502.0-B-3 (Orbit Data Messages), section 4 (OMM), as CelesTrak's JSON spells
#: them.
OMM_KEYS = frozenset(
    {
        # header
        "CCSDS_OMM_VERS",
        "COMMENT",
        "CLASSIFICATION",
        "CREATION_DATE",
        "ORIGINATOR",
        "MESSAGE_ID",
        # metadata
        "OBJECT_NAME",
        "OBJECT_ID",
        "CENTER_NAME",
        "REF_FRAME",
        "REF_FRAME_EPOCH",
        "TIME_SYSTEM",
        "MEAN_ELEMENT_THEORY",
        # mean Keplerian elements
        "EPOCH",
        "SEMI_MAJOR_AXIS",
        "MEAN_MOTION",
        "ECCENTRICITY",
        "INCLINATION",
        "RA_OF_ASC_NODE",
        "ARG_OF_PERICENTER",
        "MEAN_ANOMALY",
        "GM",
        # spacecraft parameters
        "MASS",
        "SOLAR_RAD_AREA",
        "SOLAR_RAD_COEFF",
        "DRAG_AREA",
        "DRAG_COEFF",
        # TLE-related parameters
        "EPHEMERIS_TYPE",
        "CLASSIFICATION_TYPE",
        "NORAD_CAT_ID",
        "ELEMENT_SET_NO",
        "REV_AT_EPOCH",
        "BSTAR",
        "BTERM",
        "MEAN_MOTION_DOT",
        "MEAN_MOTION_DDOT",
        "AGOM",
        # covariance (lower triangle of the 6x6 matrix)
        "COV_REF_FRAME",
        *(
            f"C{a}_{b}"
            for i, a in enumerate(("X", "Y", "Z", "X_DOT", "Y_DOT", "Z_DOT"))
            for b in ("X", "Y", "Z", "X_DOT", "Y_DOT", "Z_DOT")[: i + 1]
        ),
    }
)
#: Columns Space-Track's and CelesTrak's GP JSON add beside the OMM keywords: read and dropped.
CATALOGUE_KEYS = frozenset(
    {
        "GP_ID",
        "FILE",
        "DECAY_DATE",
        "TLE_LINE0",
        "TLE_LINE1",
        "TLE_LINE2",
        "SEMIMAJOR_AXIS",
        "PERIOD",
        "APOAPSIS",
        "PERIAPSIS",
        "OBJECT_TYPE",
        "RCS_SIZE",
        "COUNTRY_CODE",
        "LAUNCH_DATE",
        "SITE",
    }
)
MAX_KEYS = 100
MAX_TEXT_CHARS = 256
MAX_COMMENT_CHARS = 4096
#: Larger than any element or covariance term in use (catalogue numbers have 9 digits).
MAX_ABS_NUMBER = 1e15


def _refuse(key: str, reason: str) -> OMMError:
    from orbitcal.orbit import OMMError

    return OMMError(f"OMM {key}: {reason}", field=key)


def _value(key: str, value: Any) -> str | int | float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, str | int | float):
        kind = "an array" if isinstance(value, list) else type(value).__name__
        raise _refuse(key, f"is {kind}; a value must be a string, a number or null")
    if isinstance(value, str):
        limit = MAX_COMMENT_CHARS if key == "COMMENT" else MAX_TEXT_CHARS
        if len(value) > limit:
            raise _refuse(key, f"is {len(value)} characters long (at most {limit})")
        return value
    if isinstance(value, float) and not math.isfinite(value):
        raise _refuse(key, f"is {value}; numbers must be finite")
    if abs(value) >= MAX_ABS_NUMBER:
        raise _refuse(key, f"is too large ({str(value)[:24]}…; |value| < {MAX_ABS_NUMBER:g})")
    return value


def normalise_omm(omm: dict[str, Any]) -> dict[str, str | int | float | None]:
    """The OMM to store: upper-case keys of the standard (and ``USER_DEFINED_*``), scalar values.

    Raises
    ------
    orbitcal.orbit.OMMError
        With ``field`` the key at fault, for any of the refusals in the module's docstring.
    """
    from orbitcal.orbit import OMMError

    if len(omm) > MAX_KEYS:
        raise OMMError(f"OMM has {len(omm)} keys (at most {MAX_KEYS})")
    out: dict[str, str | int | float | None] = {}
    for raw_key, value in omm.items():
        key = str(raw_key).strip().upper()
        if len(key) > 64:
            raise _refuse(key[:64] + "…", "a key longer than 64 characters")
        if key in out:
            raise _refuse(key, "given twice (keys are compared in upper case)")
        if key in CATALOGUE_KEYS:
            _value(key, value)  # bounded even though dropped
            continue
        if key not in OMM_KEYS and not key.startswith("USER_DEFINED_"):
            raise _refuse(
                key,
                "is not a keyword of a CCSDS OMM (CCSDS 502.0-B-3) nor a USER_DEFINED_ "
                "parameter; check its spelling",
            )
        out[key] = _value(key, value)
    classification = out.get("CLASSIFICATION_TYPE")
    if "CLASSIFICATION_TYPE" in out and str(classification or "").strip().upper() not in (
        "U",
        "C",
        "S",
    ):
        raise _refuse(
            "CLASSIFICATION_TYPE",
            f"is {classification!r}; one letter U, C or S (or leave the key out: U)",
        )
    return out
