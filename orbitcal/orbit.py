"""Orbits from TLE or OMM mean elements, propagated with SGP4 (vectorised, many spacecraft).

``Orbit.from_tle(text)`` validates the two lines (layout, length, checksum, matching catalogue
numbers) and raises :class:`TLEError` saying which line is wrong and why; ``Orbit.from_omm(fields)``
reads a CCSDS OMM (as parsed by ``sgp4.omm``: XML/CSV rows or a JSON object). ``Orbit.propagate``
runs SGP4 (Vallado et al. 2006, AIAA 2006-6753; the ``sgp4`` package's C++ core through
``Satrec.sgp4_array``) at every sample time and returns an :class:`Ephemeris` in TEME and ITRS
(:func:`orbitcal.frames.teme_to_itrs`). Failures are *per row*: ``error_code`` holds SGP4's code
(``sgp4.api.SGP4_ERRORS``) and the row's vectors are NaN; :func:`require_valid` turns them into a
:class:`PropagationError` naming the rows. Elements older or newer than ``max_age_days`` (14 days
by default) relative to a sample raise a :class:`StaleElementsWarning`.
"""

from __future__ import annotations

import json
import math
import re
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
from sgp4.api import SGP4_ERRORS, WGS72, Satrec, SatrecArray

from orbitcal.arrays import FloatArray, IntArray
from orbitcal.errors import OrbitProblemError
from orbitcal.frames import teme_to_itrs

__all__ = [
    "DEFAULT_MAX_AGE_DAYS",
    "Ephemeris",
    "OMMError",
    "Orbit",
    "OrbitError",
    "PropagationError",
    "Propagator",
    "StaleElementsError",
    "StaleElementsWarning",
    "TLEError",
    "check_epoch_near",
    "propagate_many",
    "read_orbits",
    "read_tle_sets",
    "require_valid",
    "select_orbit",
    "tle_checksum",
]


#: Default age [d] beyond which SGP4 elements are reported as stale (LEO TLE accuracy degrades to
#: km within days; Vallado et al. 2006 discuss 1–3 km at epoch growing ~1–3 km/day).
DEFAULT_MAX_AGE_DAYS = 14.0

_UNIX_EPOCH_JD = 2_440_587.5
_DAY_S = 86_400.0
_TLE_LINE_LENGTH = 69


class OrbitError(OrbitProblemError):
    """Base class of orbit errors (bad elements or failed propagation).

    Attributes
    ----------
    field : str or None
        The element at fault (an OMM keyword such as ``MEAN_MOTION``, or a TLE field such as
        ``"eccentricity"``), when one is.
    """

    def __init__(self, message: str, *, field: str | None = None) -> None:
        self.field = field
        super().__init__(message)


class TLEError(OrbitError):
    """A two-line element set is malformed; the message names the line and the fault."""


class OMMError(OrbitError):
    """An Orbit Mean-Elements Message lacks a field or holds a malformed value."""


class PropagationError(OrbitError):
    """SGP4 failed at some rows; the message names the rows and SGP4's reason."""

    def __init__(self, message: str, rows: npt.NDArray[np.intp], codes: IntArray) -> None:
        super().__init__(message)
        self.rows = rows
        self.codes = codes


class StaleElementsError(OrbitError):
    """The data lie further from the element set's epoch than the allowed age (see
    :data:`DEFAULT_MAX_AGE_DAYS`); use elements nearer the data or accept them explicitly."""


class StaleElementsWarning(UserWarning):
    """Samples lie further from the element set's epoch than the configured age."""


@dataclass(frozen=True)
class Ephemeris:
    """Positions and velocities at sample times; rows that SGP4 could not compute are NaN.

    Attributes
    ----------
    r_teme_km : ndarray, shape (N, 3) (or (M, N, 3) for many spacecraft)
        Position in TEME [km].
    v_teme_km_s : ndarray, same shape
        Velocity in TEME [km/s].
    r_itrs_km : ndarray, same shape
        Position in ITRS [km].
    v_itrs_km_s : ndarray, same shape
        Velocity relative to the rotating ITRS [km/s].
    error_code : ndarray of int, shape (N,) (or (M, N))
        SGP4 error code per row, 0 = success (meanings: ``sgp4.api.SGP4_ERRORS``).
    t_utc_s : ndarray, shape (N,)
        The sample times, POSIX seconds of UTC [s] (empty when a fake propagator omits them).
    """

    r_teme_km: FloatArray
    v_teme_km_s: FloatArray
    r_itrs_km: FloatArray
    v_itrs_km_s: FloatArray
    error_code: IntArray
    t_utc_s: FloatArray = field(default_factory=lambda: np.empty(0))

    @property
    def valid(self) -> npt.NDArray[np.bool_]:
        """True where SGP4 succeeded."""
        return np.asarray(self.error_code == 0)

    def require_valid(self) -> Ephemeris:
        """Return ``self`` if every row is valid, else raise :class:`PropagationError`."""
        return require_valid(self)


class Propagator(Protocol):
    """Anything that gives an :class:`Ephemeris` at sample times (SGP4 orbits, test fakes)."""

    def propagate(self, t_utc_s: npt.ArrayLike) -> Ephemeris: ...


def tle_checksum(line: str) -> int:
    """TLE checksum of a line's first 68 columns: sum of digits, '-' counts 1, modulo 10."""
    return sum(int(c) if c.isdigit() else (1 if c == "-" else 0) for c in line[:68]) % 10


def _validate_tle_line(line: str, number: int, *, verify_checksum: bool) -> None:
    label = f"TLE line {number}"
    if not line.startswith(f"{number} "):
        raise TLEError(f"{label} must start with '{number} ', got {line[:10]!r}")
    if len(line) != _TLE_LINE_LENGTH:
        raise TLEError(
            f"{label} has {len(line)} characters; a TLE line has exactly {_TLE_LINE_LENGTH}: "
            f"{line!r}"
        )
    if verify_checksum:
        last = line[68]
        if not last.isdigit():
            raise TLEError(f"{label}: column 69 must be the checksum digit, got {last!r}")
        expected = tle_checksum(line)
        if int(last) != expected:
            raise TLEError(
                f"{label}: checksum is {last} but the line's digits give {expected} "
                "(the line is corrupted or was edited)"
            )


# Fixed-column numeric fields (1-based columns, CelesTrak "NORAD Two-Line Element Set Format";
# Vallado et al. 2006 appendix A): (line, first column, last column, name, assumed-decimal form).
_TLE_FIELDS: tuple[tuple[int, int, int, str, str], ...] = (
    (1, 19, 32, "epoch (YYDDD.DDDDDDDD)", "float"),
    (1, 34, 43, "first derivative of mean motion", "float"),
    (1, 45, 52, "second derivative of mean motion", "exp"),
    (1, 54, 61, "BSTAR drag term", "exp"),
    (2, 9, 16, "inclination [deg]", "float"),
    (2, 18, 25, "right ascension of the ascending node [deg]", "float"),
    (2, 27, 33, "eccentricity (assumed leading decimal point)", "int"),
    (2, 35, 42, "argument of perigee [deg]", "float"),
    (2, 44, 51, "mean anomaly [deg]", "float"),
    (2, 53, 63, "mean motion [rev/day]", "float"),
)
_EXP_FIELD_RE = re.compile(r"^\s*[+-]?\d*\s*[+-]\d$")


def _validate_tle_fields(line1: str, line2: str) -> None:
    for number, first, last, what, kind in _TLE_FIELDS:
        line = line1 if number == 1 else line2
        text = line[first - 1 : last]
        ok = True
        if kind == "float":
            try:
                float(text)
            except ValueError:
                ok = False
        elif kind == "int":
            ok = text.strip().isdigit()
        else:
            ok = bool(_EXP_FIELD_RE.match(text)) or text.strip() in {"", "0", "00000-0", "00000+0"}
        if not ok:
            raise TLEError(
                f"TLE line {number}, columns {first}-{last} ({what}): {text!r} is not a number "
                "in TLE format"
            )


# Physical ranges of the mean elements (CCSDS 502.0-B-3 OMM; CelesTrak's TLE format): name of the
# element in words, lower and upper bound, whether the upper bound itself is allowed.
_ELEMENT_RANGES: tuple[tuple[str, str, float, float, bool], ...] = (
    ("MEAN_MOTION", "mean motion [rev/day]", 0.0, 20.0, True),
    ("ECCENTRICITY", "eccentricity", 0.0, 1.0, False),
    ("INCLINATION", "inclination [deg]", 0.0, 180.0, True),
    ("RA_OF_ASC_NODE", "right ascension of the ascending node [deg]", 0.0, 360.0, True),
    ("ARG_OF_PERICENTER", "argument of perigee [deg]", 0.0, 360.0, True),
    ("MEAN_ANOMALY", "mean anomaly [deg]", 0.0, 360.0, True),
)
# Integer fields and the largest value their TLE column width holds (CelesTrak TLE format; the
# NORAD number up to Alpha-5 'Z9999', the largest that SGP4 takes).
_INTEGER_FIELDS: tuple[tuple[str, str, int], ...] = (
    ("NORAD_CAT_ID", "NORAD catalogue number", 339_999),
    ("ELEMENT_SET_NO", "element set number (4 digits)", 9_999),
    ("REV_AT_EPOCH", "revolution number at epoch (5 digits)", 99_999),
    ("EPHEMERIS_TYPE", "ephemeris type (1 digit)", 9),
)
# Drag-like terms: finite and representable in the TLE's fixed columns (|x| < 1).
_SMALL_TERMS: tuple[tuple[str, str], ...] = (
    ("BSTAR", "BSTAR drag term [1/earth radii]"),
    ("MEAN_MOTION_DOT", "first derivative of mean motion [rev/day²]"),
    ("MEAN_MOTION_DDOT", "second derivative of mean motion [rev/day³]"),
)
# The element SGP4's initialisation errors point at (sgp4.api.SGP4_ERRORS; Vallado et al. 2006):
# 1 mean eccentricity/semi-major axis, 2 mean motion < 0, 3 perturbed eccentricity, 4 semi-latus
# rectum < 0, 6 decayed (radius below the Earth's at epoch: the mean motion puts it inside).
_SGP4_ERROR_FIELDS = {
    1: "ECCENTRICITY",
    2: "MEAN_MOTION",
    3: "ECCENTRICITY",
    4: "MEAN_MOTION",
    6: "MEAN_MOTION",
}


def _init_error(satrec: Satrec, label: str, error: type[OrbitError]) -> OrbitError:
    code = int(satrec.error)
    what = SGP4_ERRORS.get(code, "unknown")
    field = _SGP4_ERROR_FIELDS.get(code)
    hint = (
        f": the elements describe a decayed (re-entered) object (check {field})"
        if code == 6
        else f" (check {field})"
        if field
        else ""
    )
    return error(
        f"{label} elements rejected by SGP4 initialisation: error {code} ({what}){hint}",
        field=field,
    )


def _check_element_values(values: Mapping[str, float], label: str, error: type[OrbitError]) -> None:
    """Refuse non-finite and out-of-range mean elements, naming the field.

    ``values`` maps OMM keywords (the TLE's fields translated) to numbers; ``label`` prefixes the
    message (``"OMM"``, ``"TLE"``).
    """
    for key, words, lo, hi, hi_ok in _ELEMENT_RANGES:
        if key not in values:
            continue
        x = values[key]
        inside = math.isfinite(x) and (x > lo if key == "MEAN_MOTION" else x >= lo)
        inside = inside and (x <= hi if hi_ok else x < hi)
        if not inside:
            bound = (
                f"> {lo:g}" if key == "MEAN_MOTION" else f"≥ {lo:g}"
            ) + f" and {'≤' if hi_ok else '<'} {hi:g}"
            raise error(f"{label} {key} ({words}) is {x!r}; it must be finite, {bound}", field=key)
    for key, words in _SMALL_TERMS:
        if key in values and not (math.isfinite(values[key]) and abs(values[key]) < 1.0):
            raise error(
                f"{label} {key} ({words}) is {values[key]!r}; it must be finite with |x| < 1",
                field=key,
            )


def _check_integer_fields(texts: Mapping[str, str], label: str, error: type[OrbitError]) -> None:
    for key, words, largest in _INTEGER_FIELDS:
        if key not in texts:
            continue
        text = texts[key].strip()
        if not (text.isdigit() and text.isascii()):
            raise error(
                f"{label} {key} ({words}) is {text[:40]!r}; it must be a whole number 0…{largest}",
                field=key,
            )
        if len(text) > 12 or int(text) > largest:
            raise error(
                f"{label} {key} ({words}) is {text[:40]}; the largest allowed is {largest}",
                field=key,
            )


def _tle_values(line1: str, line2: str) -> dict[str, float]:
    """The TLE's elements under their OMM keywords (fixed columns; format already validated)."""

    def exp_field(text: str) -> float:
        text = text.strip()
        if not text or text in {"0", "00000-0", "00000+0"}:
            return 0.0
        mantissa, exponent = text[:-2].replace(" ", ""), text[-2:]
        sign = -1.0 if mantissa.startswith("-") else 1.0
        digits = mantissa.lstrip("+-") or "0"
        return sign * float("0." + digits) * 10.0 ** int(exponent)

    return {
        "INCLINATION": float(line2[8:16]),
        "RA_OF_ASC_NODE": float(line2[17:25]),
        "ECCENTRICITY": float("0." + line2[26:33].strip()),
        "ARG_OF_PERICENTER": float(line2[34:42]),
        "MEAN_ANOMALY": float(line2[43:51]),
        "MEAN_MOTION": float(line2[52:63]),
        "MEAN_MOTION_DOT": float(line1[33:43]),
        "MEAN_MOTION_DDOT": exp_field(line1[44:52]),
        "BSTAR": exp_field(line1[53:61]),
    }


def _check_age(epoch_utc_s: float, t: FloatArray, max_age_days: float | None, what: str) -> None:
    if max_age_days is None or t.size == 0:
        return
    finite = t[np.isfinite(t)]
    if finite.size == 0:
        return
    age_d = float(np.max(np.abs(finite - epoch_utc_s))) / _DAY_S
    if age_d > max_age_days:
        warnings.warn(
            f"{what}: samples lie up to {age_d:.1f} days from the element epoch (limit "
            f"{max_age_days:g} days); SGP4 errors grow by km per day — use fresher elements",
            StaleElementsWarning,
            stacklevel=3,
        )


def _jd_fr(t_utc_s: FloatArray, ref: Orbit) -> tuple[FloatArray, FloatArray]:
    """POSIX seconds of UTC → (Julian date, fraction) in UTC, as SGP4 takes them.

    Split relative to the reference orbit's epoch (``jdsatepoch + whole``, ``jdsatepochF +
    fraction``), so that SGP4's time since epoch is ``t − epoch`` without the rounding of a
    1e9-second POSIX epoch (which matters for ill-conditioned elements such as Vallado's 33333).
    """
    d = (t_utc_s - ref.epoch_utc_s) / _DAY_S
    whole = np.floor(d)
    return ref.satrec.jdsatepoch + whole, ref.satrec.jdsatepochF + (d - whole)


def _to_itrs(
    r_teme: FloatArray, v_teme: FloatArray, t: FloatArray, ok: npt.NDArray[np.bool_]
) -> tuple[FloatArray, FloatArray]:
    if np.all(ok):
        return teme_to_itrs(r_teme, v_teme, t)
    r_itrs = np.full_like(r_teme, np.nan)
    v_itrs = np.full_like(v_teme, np.nan)
    if np.any(ok):
        r_itrs[ok], v_itrs[ok] = teme_to_itrs(r_teme[ok], v_teme[ok], t[ok])
    return r_itrs, v_itrs


@dataclass(frozen=True)
class Orbit:
    """One spacecraft's SGP4 mean elements (from a TLE or an OMM).

    Attributes
    ----------
    satrec : sgp4.api.Satrec
        The initialised SGP4 record (WGS72 constants, as the elements were fitted with).
    norad_id : int
        NORAD catalogue number.
    name : str
        Object name ('' when the TLE had no name line).
    epoch_utc_s : float
        Element epoch, POSIX seconds of UTC [s].
    """

    satrec: Satrec = field(compare=False)
    norad_id: int
    name: str
    epoch_utc_s: float
    #: Where the elements came from: ``("tle", line1, line2)`` or ``("omm", json_text)``; used
    #: to pickle the orbit (a ``Satrec`` cannot be pickled) and by :attr:`tle_lines`.
    source: tuple[str, ...] = field(default=(), repr=False)

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        return (_orbit_from_source, (self.source, self.name))

    def __repr__(self) -> str:
        """``Orbit('ISS (ZARYA)', NORAD 25544, epoch 2022-08-01T21:26:45Z, from a TLE)``: the
        spacecraft and the elements' epoch, not the SGP4 record's address."""
        from orbitcal.timescales import utc_s_to_iso

        (epoch,) = utc_s_to_iso([float(self.epoch_utc_s)])
        origin = {"tle": ", from a TLE", "omm": ", from an OMM"}.get(
            self.source[0] if self.source else "", ""
        )
        return f"Orbit({self.name!r}, NORAD {self.norad_id}, epoch {epoch[:19]}Z{origin})"

    @property
    def tle_lines(self) -> tuple[str, str]:
        """The two TLE lines (as read, or exported by ``sgp4.exporter`` for an OMM origin)."""
        if self.source and self.source[0] == "tle":
            return self.source[1], self.source[2]
        from sgp4.exporter import export_tle

        line1, line2 = export_tle(self.satrec)
        return line1, line2

    @property
    def line1(self) -> str:
        """TLE line 1 (see :attr:`tle_lines`)."""
        return self.tle_lines[0]

    @property
    def line2(self) -> str:
        """TLE line 2 (see :attr:`tle_lines`)."""
        return self.tle_lines[1]

    @property
    def text(self) -> str:
        """The element set as TLE text (:meth:`to_tle_text`)."""
        return self.to_tle_text()

    def to_tle_text(self) -> str:
        """Name line (if any) and the two lines, newline-terminated, as ``from_tle`` reads it."""
        lines = [self.name] if self.name else []
        return "\n".join([*lines, *self.tle_lines]) + "\n"

    @classmethod
    def from_tle(cls, text: str, *, name: str | None = None, verify_checksum: bool = True) -> Orbit:
        """Read a two-line element set, with an optional name line first.

        Parameters
        ----------
        text : str
            Two or three lines (``NAME`` or ``0 NAME``, then lines 1 and 2). Blank lines and
            trailing whitespace are ignored.
        name : str, optional
            Overrides the name line.
        verify_checksum : bool, keyword-only
            Check column 69 of both lines (default). Only for known-bad historical sets.

        Raises
        ------
        TLEError
            Naming the line and the fault: wrong count of lines, layout, length, checksum,
            catalogue numbers that differ between the lines, or elements SGP4 cannot initialise.
        """
        if not isinstance(text, str):
            raise TLEError(f"a TLE must be text, got {type(text).__name__}")
        lines = [ln.rstrip() for ln in text.strip().splitlines() if ln.strip()]
        if len(lines) == 3:
            title, line1, line2 = lines
            title = title.strip()
            if title.startswith("0 "):
                title = title[2:].strip()
        elif len(lines) == 2:
            title, (line1, line2) = "", lines
        else:
            raise TLEError(
                f"a TLE has 2 lines (or 3 with a name line first); got {len(lines)} non-blank lines"
            )
        _validate_tle_line(line1, 1, verify_checksum=verify_checksum)
        _validate_tle_line(line2, 2, verify_checksum=verify_checksum)
        _validate_tle_fields(line1, line2)
        _check_element_values(_tle_values(line1, line2), "TLE", TLEError)
        if line1[2:7] != line2[2:7]:
            raise TLEError(
                f"TLE line 1 is for catalogue number {line1[2:7]!r} but line 2 for {line2[2:7]!r}"
            )
        try:
            satrec = Satrec.twoline2rv(line1, line2, WGS72)
        except (ValueError, IndexError) as exc:  # pragma: no cover - sgp4 rarely raises
            raise TLEError(f"TLE could not be read by SGP4: {exc}") from exc
        if satrec.error:
            raise _init_error(satrec, "TLE", TLEError)
        return cls._from_satrec(satrec, name if name is not None else title, ("tle", line1, line2))

    @classmethod
    def from_omm(cls, fields: Mapping[str, Any], *, name: str | None = None) -> Orbit:
        """Read a CCSDS Orbit Mean-Elements Message (one object's fields, as ``sgp4.omm`` reads).

        Parameters
        ----------
        fields : mapping
            Keys such as ``EPOCH`` (``YYYY-MM-DDTHH:MM:SS.ffffff``, UTC), ``MEAN_MOTION``,
            ``ECCENTRICITY``, ``INCLINATION``, ``RA_OF_ASC_NODE``, ``ARG_OF_PERICENTER``,
            ``MEAN_ANOMALY``, ``NORAD_CAT_ID``, ``BSTAR``, ``MEAN_MOTION_DOT``,
            ``MEAN_MOTION_DDOT``, ``CLASSIFICATION_TYPE``, ``OBJECT_ID``, ``EPHEMERIS_TYPE``,
            ``ELEMENT_SET_NO``, ``REV_AT_EPOCH``; values strings or numbers (CelesTrak JSON).

        Raises
        ------
        OMMError
            Naming the missing or malformed field.
        """
        from sgp4 import omm

        if not isinstance(fields, Mapping):
            raise OMMError(f"an OMM must be a mapping of field names, got {type(fields).__name__}")
        texts = {str(k).upper(): ("" if v is None else str(v)) for k, v in fields.items()}
        defaults = {
            "CLASSIFICATION_TYPE": "U",
            "EPHEMERIS_TYPE": "0",
            "ELEMENT_SET_NO": "999",
            "REV_AT_EPOCH": "0",
            "MEAN_MOTION_DDOT": "0",
            "OBJECT_ID": "",
        }
        for key, value in defaults.items():
            texts.setdefault(key, value)
        for key, allowed in (("REF_FRAME", "TEME"), ("TIME_SYSTEM", "UTC")):
            if texts.get(key, allowed).strip().upper() != allowed:
                raise OMMError(f"OMM {key} is {texts[key]!r}; SGP4 elements need {allowed}")
        theory = texts.get("MEAN_ELEMENT_THEORY", "SGP4").strip().upper()
        if theory not in ("SGP4", "SGP/SGP4"):
            raise OMMError(f"OMM MEAN_ELEMENT_THEORY is {theory!r}; orbitcal propagates SGP4 only")
        epoch = texts.get("EPOCH", "").strip().rstrip("Zz")
        if epoch and "." not in epoch:
            epoch += ".0"
        if epoch:
            texts["EPOCH"] = epoch
        values: dict[str, float] = {}
        for key in (*(r[0] for r in _ELEMENT_RANGES), *(t[0] for t in _SMALL_TERMS)):
            if key not in texts:
                raise OMMError(f"OMM lacks the field {key}", field=key)
            if len(texts[key]) > 64:
                raise OMMError(f"OMM {key} is {len(texts[key])} characters long", field=key)
            try:
                values[key] = float(texts[key])
            except ValueError:
                raise OMMError(
                    f"OMM {key} is {texts[key][:40]!r}, not a number", field=key
                ) from None
        if "NORAD_CAT_ID" not in texts:
            raise OMMError("OMM lacks the field NORAD_CAT_ID", field="NORAD_CAT_ID")
        _check_integer_fields(texts, "OMM", OMMError)
        _check_element_values(values, "OMM", OMMError)
        if len(texts["CLASSIFICATION_TYPE"].strip()) > 1:
            raise OMMError(
                f"OMM CLASSIFICATION_TYPE is {texts['CLASSIFICATION_TYPE'][:40]!r}; one letter "
                "(U, C or S)",
                field="CLASSIFICATION_TYPE",
            )
        satrec = Satrec()
        try:
            omm.initialize(satrec, texts)
        except KeyError as exc:
            raise OMMError(f"OMM lacks the field {exc.args[0]}", field=str(exc.args[0])) from exc
        except (ValueError, OverflowError) as exc:
            field = "EPOCH" if "time data" in str(exc) or "does not match" in str(exc) else None
            raise OMMError(f"OMM has a malformed value: {exc}", field=field) from exc
        if satrec.error:
            raise _init_error(satrec, "OMM", OMMError)
        title = name if name is not None else texts.get("OBJECT_NAME", "")
        return cls._from_satrec(satrec, title, ("omm", json.dumps(texts, sort_keys=True)))

    @classmethod
    def _from_satrec(cls, satrec: Satrec, name: str, source: tuple[str, ...]) -> Orbit:
        epoch_utc_s = (satrec.jdsatepoch - _UNIX_EPOCH_JD) * _DAY_S + satrec.jdsatepochF * _DAY_S
        return cls(
            satrec=satrec,
            norad_id=int(satrec.satnum),
            name=name,
            epoch_utc_s=epoch_utc_s,
            source=source,
        )

    def propagate(
        self, t_utc_s: npt.ArrayLike, *, max_age_days: float | None = DEFAULT_MAX_AGE_DAYS
    ) -> Ephemeris:
        """Propagate to sample times with SGP4 (vectorised).

        Parameters
        ----------
        t_utc_s : array_like, shape (N,)
            POSIX seconds of UTC [s].
        max_age_days : float or None, keyword-only
            Warn (:class:`StaleElementsWarning`) when a sample is further than this from the
            epoch [d]; ``None`` disables the check.

        Returns
        -------
        Ephemeris
            Rows with a non-zero ``error_code`` (or a non-finite time, code −1) are NaN.
        """
        t = np.atleast_1d(np.asarray(t_utc_s, dtype=np.float64))
        if t.ndim != 1:
            raise ValueError(f"t_utc_s must have shape (N,), got {t.shape}")
        _check_age(self.epoch_utc_s, t, max_age_days, f"NORAD {self.norad_id} {self.name}".strip())
        finite = np.isfinite(t)
        jd, fr = _jd_fr(np.where(finite, t, self.epoch_utc_s), self)
        e, r, v = self.satrec.sgp4_array(jd, fr)
        error_code = np.asarray(e, dtype=np.int64)
        error_code[~finite] = -1
        ok = error_code == 0
        r = np.where(ok[:, None], r, np.nan)
        v = np.where(ok[:, None], v, np.nan)
        r_itrs, v_itrs = _to_itrs(r, v, t, ok)
        return Ephemeris(r, v, r_itrs, v_itrs, error_code, t)


def _orbit_from_source(source: tuple[str, ...], name: str) -> Orbit:
    """Rebuild an :class:`Orbit` from its ``source`` (unpickling)."""
    if source and source[0] == "tle":
        return Orbit.from_tle(f"{source[1]}\n{source[2]}", name=name, verify_checksum=False)
    if source and source[0] == "omm":
        return Orbit.from_omm(json.loads(source[1]), name=name)
    raise OrbitError("this Orbit has no recorded source (TLE or OMM) and cannot be rebuilt")


def read_tle_sets(text: str, *, verify_checksum: bool = True) -> list[Orbit]:
    """Every element set of a TLE file (2-line or 3-line entries, in file order).

    Each set is read by :meth:`Orbit.from_tle` (layout, checksums, physical ranges); a bad set
    raises :class:`TLEError` naming its place in the file.

    Raises
    ------
    TLEError
        No set found, or a set is malformed (the message says which: "set 3 (line 7): ...").
    """
    if not isinstance(text, str):
        raise TLEError(f"a TLE file must be text, got {type(text).__name__}")
    lines = [(k + 1, ln.rstrip()) for k, ln in enumerate(text.splitlines()) if ln.strip()]
    out: list[Orbit] = []
    i = 0
    name = ""
    while i < len(lines):
        number, ln = lines[i]
        if ln.startswith("1 ") and i + 1 < len(lines) and lines[i + 1][1].startswith("2 "):
            try:
                out.append(
                    Orbit.from_tle(
                        f"{ln}\n{lines[i + 1][1]}",
                        name=name.strip(),
                        verify_checksum=verify_checksum,
                    )
                )
            except TLEError as exc:
                raise TLEError(
                    f"set {len(out) + 1} (line {number}): {exc}", field=exc.field
                ) from None
            name = ""
            i += 2
        else:
            name = ln[2:] if ln.startswith("0 ") else ln
            i += 1
    if not out:
        raise TLEError("no two-line element set found (lines starting '1 ' and '2 ')")
    return out


def select_orbit(
    orbits: Sequence[Orbit] | str,
    *,
    norad_id: int | None = None,
    at_utc_s: float | tuple[float, float] | None = None,
    prefer_past: bool = False,
) -> Orbit:
    """One spacecraft's element set nearest in epoch to a time or a span.

    Parameters
    ----------
    orbits : sequence of Orbit, or str
        Element sets (or a TLE file's text, read by :func:`read_tle_sets`).
    norad_id : int or None, keyword-only
        Catalogue number; required when the sets are of more than one spacecraft.
    at_utc_s : float, (float, float) or None, keyword-only
        A time or a (first, last) span of the data, POSIX seconds of UTC [s]; None picks the
        latest epoch. For a span, the distance of an epoch is zero inside it.
    prefer_past : bool, keyword-only
        Take the latest epoch not after the (start of the) time when there is one, as an operator
        would have had at that time (the simulator); else the nearest epoch.

    Raises
    ------
    OrbitError
        Several spacecraft and no ``norad_id``, or none of that number.
    """
    sets = read_tle_sets(orbits) if isinstance(orbits, str) else list(orbits)
    if not sets:
        raise OrbitError("no element sets given")
    ids = sorted({o.norad_id for o in sets})
    if norad_id is None:
        if len(ids) > 1:
            raise OrbitError(
                f"the element sets are of {len(ids)} spacecraft ({', '.join(map(str, ids))}): "
                "name one with --norad",
                field="norad",
            )
        norad_id = ids[0]
    mine = [o for o in sets if o.norad_id == norad_id]
    if not mine:
        raise OrbitError(
            f"no element set for NORAD {norad_id} (the sets are of {', '.join(map(str, ids))})",
            field="norad",
        )
    epochs = np.array([o.epoch_utc_s for o in mine])
    if at_utc_s is None:
        return mine[int(np.argmax(epochs))]
    first, last = (at_utc_s, at_utc_s) if isinstance(at_utc_s, float | int) else at_utc_s
    if prefer_past:
        before = np.flatnonzero(epochs <= first)
        if before.size:
            return mine[int(before[np.argmax(epochs[before])])]
    distance = np.maximum(np.maximum(first - epochs, epochs - last), 0.0)
    return mine[int(np.argmin(distance))]


def _omm_records(text: str, path: str) -> list[dict[str, str]]:
    import io

    from sgp4 import omm

    stripped = text.lstrip()
    try:
        if stripped.startswith("<"):
            return list(omm.parse_xml(io.StringIO(text)))
        if stripped.startswith(("[", "{")):
            data = json.loads(text)
            records = data if isinstance(data, list) else [data]
            if not all(isinstance(r, dict) for r in records):
                raise OMMError(f"{path}: a JSON OMM file holds objects (or a list of them)")
            return records
        return list(omm.parse_csv(io.StringIO(text)))
    except OMMError:
        raise
    except Exception as exc:  # the XML/CSV/JSON parsers' own errors: a malformed file
        raise OMMError(f"{path}: not a readable OMM file ({type(exc).__name__}: {exc})") from None


def read_orbits(text: str, *, path: str = "elements") -> list[Orbit]:
    """Every element set of a TLE file or a CCSDS OMM file (XML, JSON or CSV), in file order.

    The format is recognised from the text: lines starting ``1 `` and ``2 `` are a TLE file; a
    leading ``<`` is OMM XML; ``[`` or ``{`` is OMM JSON (CelesTrak's ``FORMAT=json``); a header
    line naming ``MEAN_MOTION`` is OMM CSV. OMM records are read by :meth:`Orbit.from_omm`.

    Raises
    ------
    TLEError, OMMError
        Naming the file, the record and the field.
    """
    stripped = text.lstrip()
    first = stripped.splitlines()[0] if stripped else ""
    if stripped.startswith(("<", "[", "{")) or "MEAN_MOTION" in first.upper():
        records = _omm_records(text, path)
        if not records:
            raise OMMError(f"{path}: no OMM record found")
        orbits = []
        for k, record in enumerate(records):
            try:
                orbits.append(Orbit.from_omm(record))
            except OMMError as exc:
                raise OMMError(f"{path}: record {k + 1}: {exc}", field=exc.field) from None
        return orbits
    try:
        return read_tle_sets(text)
    except TLEError as exc:
        raise TLEError(f"{path}: {exc}", field=exc.field) from None


def check_epoch_near(
    orbit: Orbit,
    t_utc_s: npt.ArrayLike,
    *,
    max_age_days: float = DEFAULT_MAX_AGE_DAYS,
) -> float:
    """The largest distance [d] of the samples from the element epoch; raise beyond the limit.

    SGP4 elements of a LEO spacecraft are good to about a kilometre at epoch and degrade by
    kilometres per day (Vallado et al. 2006), so data further than ``max_age_days`` (default
    :data:`DEFAULT_MAX_AGE_DAYS` = 14 days) from the epoch are refused unless the caller accepts
    them (the CLI's ``--allow-stale-elements``).

    Raises
    ------
    StaleElementsError
        Naming the spacecraft, the epoch, the distance and the limit.
    """
    t = np.asarray(t_utc_s, dtype=np.float64)
    t = t[np.isfinite(t)]
    if t.size == 0:
        return 0.0
    age_d = float(np.max(np.abs(t - orbit.epoch_utc_s))) / _DAY_S
    if age_d > max_age_days:
        from orbitcal.timescales import utc_s_to_iso

        epoch = utc_s_to_iso([orbit.epoch_utc_s])[0][:19]
        raise StaleElementsError(
            f"the element set of NORAD {orbit.norad_id} (epoch {epoch}Z) is {age_d:.1f} days from "
            f"the data, more than {max_age_days:g} days: SGP4 errors grow by km per day. Give "
            "elements nearer the data (a file of many sets: the nearest is picked), positions "
            "(r_x, r_y, r_z), or --allow-stale-elements",
            field="epoch",
        )
    return age_d


def propagate_many(
    orbits: Sequence[Orbit],
    t_utc_s: npt.ArrayLike,
    *,
    max_age_days: float | None = DEFAULT_MAX_AGE_DAYS,
) -> Ephemeris:
    """Propagate many spacecraft at the same sample times in one ``SatrecArray`` call.

    Parameters
    ----------
    orbits : sequence of Orbit, length M
    t_utc_s : array_like, shape (N,)
        POSIX seconds of UTC [s].
    max_age_days : float or None, keyword-only
        As in :meth:`Orbit.propagate`, checked per spacecraft.

    Returns
    -------
    Ephemeris
        Arrays of shape (M, N, 3) and ``error_code`` (M, N); ``t_utc_s`` (N,).
    """
    t = np.atleast_1d(np.asarray(t_utc_s, dtype=np.float64))
    if t.ndim != 1:
        raise ValueError(f"t_utc_s must have shape (N,), got {t.shape}")
    m, n = len(orbits), t.size
    if m == 0:
        empty = np.empty((0, n, 3))
        return Ephemeris(empty, empty, empty, empty, np.empty((0, n), dtype=np.int64), t)
    for orbit in orbits:
        _check_age(orbit.epoch_utc_s, t, max_age_days, f"NORAD {orbit.norad_id}")
    finite = np.isfinite(t)
    jd, fr = _jd_fr(np.where(finite, t, orbits[0].epoch_utc_s), orbits[0])
    e, r, v = SatrecArray([o.satrec for o in orbits]).sgp4(jd, fr)
    error_code = np.asarray(e, dtype=np.int64)
    error_code[:, ~finite] = -1
    ok = error_code == 0
    r = np.where(ok[..., None], r, np.nan)
    v = np.where(ok[..., None], v, np.nan)
    t_all = np.broadcast_to(t, (m, n)).reshape(-1)
    r_itrs, v_itrs = _to_itrs(r.reshape(-1, 3), v.reshape(-1, 3), t_all, ok.reshape(-1))
    return Ephemeris(r, v, r_itrs.reshape(m, n, 3), v_itrs.reshape(m, n, 3), error_code, t)


def _meaning(code: int) -> str:
    if code == -1:
        return "the sample time is not a finite number"
    return SGP4_ERRORS.get(code, f"unknown SGP4 error {code}")


def require_valid(eph: Ephemeris, *, max_listed: int = 10) -> Ephemeris:
    """Return ``eph`` if SGP4 succeeded at every row; else raise :class:`PropagationError`.

    The message names the failed rows (0-based; ``(spacecraft, row)`` for many spacecraft), SGP4's
    code and its meaning, and what to do.
    """
    bad = np.argwhere(eph.error_code != 0)
    if bad.size == 0:
        return eph
    codes = eph.error_code[tuple(bad.T)]
    parts = []
    for code in np.unique(codes):
        where = bad[codes == code]
        listed = [
            str(int(w[0])) if w.size == 1 else str(tuple(int(x) for x in w))
            for w in where[:max_listed]
        ]
        more = f" and {len(where) - max_listed} more" if len(where) > max_listed else ""
        parts.append(f"error {int(code)} ({_meaning(int(code))}) at rows {', '.join(listed)}{more}")
    message = (
        f"SGP4 failed at {len(bad)} of {eph.error_code.size} samples: "
        + "; ".join(parts)
        + ". Use elements with an epoch close to the data, or positions (r_x, r_y, r_z)."
    )
    rows = bad[:, -1] if bad.shape[1] == 1 else bad
    raise PropagationError(message, rows=np.asarray(rows), codes=codes)
