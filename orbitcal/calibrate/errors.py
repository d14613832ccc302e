"""Typed errors of the calibrators, split by what the caller can do about them.

All derive from :class:`CalibrationError` (an :class:`orbitcal.errors.OrbitcalError`), so the CLI
turns them into a one-line reason and a non-zero exit status (CONTRACT section 2).
"""

from __future__ import annotations

from orbitcal.errors import BadInputError, NotEnoughDataError, OrbitcalError

__all__ = [
    "CalibrationError",
    "DocumentError",
    "MissingAttitudeError",
    "PoorCoverageError",
    "TooFewSamplesError",
    "UndeterminedFitError",
    "UnknownMethodError",
]


class CalibrationError(OrbitcalError):
    """Base class: the input cannot be calibrated as asked."""


class TooFewSamplesError(CalibrationError, NotEnoughDataError):
    """Fewer valid samples than the method needs; collect more data."""

    def __init__(self, method: str, n_samples: int, n_required: int) -> None:
        self.method = method
        self.n_samples = n_samples
        self.n_required = n_required
        super().__init__(
            f"{method} needs at least {n_required} valid samples, got {n_samples}; "
            "collect more telemetry before calibrating"
        )


class MissingAttitudeError(CalibrationError, BadInputError):
    """A vector method was asked for but the telemetry carries no attitude quaternions."""

    def __init__(self, method: str) -> None:
        self.method = method
        super().__init__(
            f"{method} is a vector method and needs attitude (q_w, q_x, q_y, q_z) for every "
            "sample; "
            "supply attitude or use an attitude-free method (twostep, flann, online)"
        )


class PoorCoverageError(CalibrationError, NotEnoughDataError):
    """The data leave a direction unobservable; the normal matrix is ill-conditioned."""

    def __init__(self, method: str, condition_number: float, limit: float) -> None:
        self.method = method
        self.condition_number = condition_number
        self.limit = limit
        super().__init__(
            f"{method}: poor attitude/field coverage leaves an axis unobservable "
            f"(condition number {condition_number:.3g} > {limit:.3g}); "
            "use data with more varied field directions in the sensor frame"
        )


class UndeterminedFitError(CalibrationError, NotEnoughDataError):
    """The fit is well-conditioned numerically but the data do not determine the matrix: its
    standard errors exceed what a calibration can be trusted with."""

    def __init__(self, method: str, gain_sd: float, limit: float, n: int) -> None:
        self.method = method
        self.gain_sd = gain_sd
        self.limit = limit
        super().__init__(
            f"{method}: the {n} samples determine the calibration matrix only to "
            f"±{gain_sd:.3g} (1 sigma) per element, more than {limit:g}: the field barely "
            "changed direction in the sensor frame; use a longer span (hours, several orbits) "
            "or more varied attitudes"
        )


class UnknownMethodError(CalibrationError, BadInputError):
    """No calibrator is registered under that name."""

    def __init__(self, name: str, known: list[str]) -> None:
        self.name = name
        self.known = known
        super().__init__(f"unknown calibration method {name!r}; known: {', '.join(known)}")


class DocumentError(CalibrationError, BadInputError):
    """A calibration document (CONTRACT section 4) is malformed or of an unknown method."""
