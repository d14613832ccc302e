"""A prior on the 12 calibration parameters: the calibration already in service.

A diagnosis usually fits the 12 parameters jointly with each candidate effect. On a short span that
is ill-posed for effects nearly parallel to the main field: at low latitude a ring-current field
points along (minus) the horizontal main field, so a 0.5 % scale factor absorbs a -166 nT storm
field and the joint fit cannot tell the two apart in 30 minutes. Operators do not diagnose from
nothing, though: the calibration in service was fitted on earlier (quiet) data. Given here as a
Gaussian prior, ``A ~ N(A0, sigma_a^2)`` and ``o ~ N(o0, sigma_o^2)`` per element, it keeps the 12
parameters where that calibration put them unless the data insist, and the effect takes what is
left.

The widths say how far the sensor may have moved since that calibration; the defaults (30 ppm of
the matrix, 1 nT of the offsets, i.e. about 1.5 nT at 50,000 nT) suit a fluxgate calibrated within
days. Split-fit tests ignore the prior: they ask what the 12 parameters absorb when left free.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.errors import BadInputError

__all__ = [
    "DEFAULT_SIGMA_MATRIX",
    "DEFAULT_SIGMA_OFFSET_NT",
    "CalibrationPrior",
    "prior_from_document",
]


#: Default prior standard deviation of each element of ``A`` [-] (30 ppm).
DEFAULT_SIGMA_MATRIX = 3.0e-5
#: Default prior standard deviation of each offset [nT].
DEFAULT_SIGMA_OFFSET_NT = 1.0


@dataclass(frozen=True)
class CalibrationPrior:
    """Gaussian prior on the forward calibration ``b_raw = a @ b_true + o``.

    Attributes
    ----------
    a : ndarray, shape (3, 3)
        Prior mean of the matrix [-].
    o_nt : ndarray, shape (3,)
        Prior mean of the offsets [nT].
    sigma_a : float
        Standard deviation of each matrix element [-].
    sigma_o_nt : float
        Standard deviation of each offset [nT].
    source : str
        Where it came from (e.g. ``"calibration document v3 (linear)"``).
    version : int, optional
        The version of the calibration document it came from, named in the report's
        ``baseline.calibration_prior`` when ``names_version`` (the service's diagnosis does).
    names_version : bool
        Whether :meth:`summary` names ``version``.
    """

    a: FloatArray
    o_nt: FloatArray
    sigma_a: float = DEFAULT_SIGMA_MATRIX
    sigma_o_nt: float = DEFAULT_SIGMA_OFFSET_NT
    source: str = "given"
    version: int | None = None
    names_version: bool = False

    def __post_init__(self) -> None:
        if np.shape(self.a) != (3, 3) or np.shape(self.o_nt) != (3,):
            raise BadInputError("a calibration prior needs a 3x3 matrix and 3 offsets")
        if not (np.all(np.isfinite(self.a)) and np.all(np.isfinite(self.o_nt))):
            raise BadInputError("a calibration prior must be finite")
        if not (self.sigma_a > 0.0 and self.sigma_o_nt > 0.0):
            raise BadInputError(
                "prior standard deviations must be positive (--prior-sigma-matrix, "
                "--prior-sigma-offset)",
                field="sigma",
            )

    def summary(self) -> dict[str, Any]:
        """JSON-ready description for reports."""
        out: dict[str, Any] = {
            "source": self.source,
            "sigma_matrix": self.sigma_a,
            "sigma_offset_nt": self.sigma_o_nt,
        }
        if self.names_version:
            out["version"] = self.version
        return out


def prior_from_document(
    doc: dict[str, Any],
    *,
    sigma_a: float = DEFAULT_SIGMA_MATRIX,
    sigma_o_nt: float = DEFAULT_SIGMA_OFFSET_NT,
    names_version: bool = False,
) -> CalibrationPrior:
    """The prior of a CONTRACT section-4 calibration document.

    The document's ``linear`` part (``b_cal = M @ (b_raw - o)``, exact for linear methods and the
    best linear approximation otherwise) gives the forward model ``b_raw = M^-1 b_true + o``.
    With ``names_version`` the report names the document's version.

    Raises
    ------
    BadInputError
        No ``linear`` part, or a singular ``M``.
    """
    lin = doc.get("linear")
    if not isinstance(lin, dict) or "M" not in lin or "o" not in lin:
        raise BadInputError(
            "calibration document lacks linear.M and linear.o: give a section-4 document",
            field="linear",
        )
    try:
        m = np.asarray(lin["M"], dtype=np.float64)
        o = np.asarray(lin["o"], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise BadInputError(
            f"calibration document: linear.M and linear.o must be numbers ({exc})", field="linear"
        ) from exc
    if m.shape != (3, 3) or o.shape != (3,):
        raise BadInputError(
            "calibration document: linear.M must be 3x3 and linear.o have 3 values",
            field="linear",
        )
    if abs(float(np.linalg.det(m))) < 1e-12:
        raise BadInputError("calibration document: linear.M is singular", field="linear.M")
    version = doc.get("version")
    method = doc.get("method", "?")
    label = f"calibration document v{version} ({method})" if version is not None else str(method)
    return CalibrationPrior(
        a=np.asarray(np.linalg.inv(m), dtype=np.float64),
        o_nt=o,
        sigma_a=sigma_a,
        sigma_o_nt=sigma_o_nt,
        source=label,
        version=version,
        names_version=names_version,
    )
