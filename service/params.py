"""Values stored now and used later: a retraining job's parameters and a spacecraft's schedule.

Both are validated, bounded and normalised **at the door** (the request that stores them answers
422 naming the field) and resolved **once**: a job stores the complete :class:`RetrainParams`
(method, field, window, hold-out share, minimum samples, seed) taken from the request, the
spacecraft's schedule and the settings, in that order; whoever runs the job (a thread, a Celery
worker, after a restart) reads exactly that object back and asks nothing else.

Bounds (documented in docs/service.md; every value is finite):

=====================  ===================================  ======================================
field                  bounds                               why
=====================  ===================================  ======================================
``window_s``           1 s … 10 years (315,576,000 s)       the window's start in µs fits 64 bits
``cadence_s``          > 0 … 10 years                       a schedule that never runs is "off"
``min_new_samples``    0 … 10¹²                             a sample count
``holdout_fraction``   > 0 … 0.9                            leaves rows to fit and to compare
``min_samples``        1 … 10⁹                              a sample count
``seed``               0 … 2⁶³ − 1                          numpy's seed
``method``             a name of ``orbitcal.calibrate.METHODS``
``field``              ``+``-joined names of ``orbitcal.field.FIELD_NAMES``
=====================  ===================================  ======================================
"""

from __future__ import annotations

import logging
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from orbitcal.errors import BadInputError
from service.settings import Settings

__all__ = [
    "CADENCE_S_MAX",
    "HOLDOUT_FRACTION_MAX",
    "MIN_NEW_SAMPLES_MAX",
    "MIN_SAMPLES_MAX",
    "SEED_MAX",
    "WINDOW_S_MAX",
    "WINDOW_S_MIN",
    "RetrainParams",
    "Schedule",
    "StoredParamsError",
    "check_field_name",
    "check_method",
]

log = logging.getLogger("orbitcal.service.params")

#: Ten Julian years [s]: the longest window or cadence (a window's start in µs of UTC stays
#: far inside 64 bits; ``window_s = 1e13`` overflowed the storage query).
WINDOW_S_MAX = 10 * 365.25 * 86400.0
#: The shortest window [s].
WINDOW_S_MIN = 1.0
#: The longest scheduled-retraining cadence [s].
CADENCE_S_MAX = WINDOW_S_MAX
#: The largest "new samples before a scheduled retraining" [-].
MIN_NEW_SAMPLES_MAX = 10**12
#: The largest minimum sample count of a fit [-].
MIN_SAMPLES_MAX = 10**9
#: The largest hold-out share [-] (the rest is fitted).
HOLDOUT_FRACTION_MAX = 0.9
#: Seeds are 63-bit non-negative integers.
SEED_MAX = 2**63 - 1


def check_method(method: str) -> str:
    """``method`` if a calibrator is registered under it, else ``ValueError`` naming the known."""
    from orbitcal.calibrate import METHODS

    if method not in METHODS:
        raise ValueError(f"unknown calibration method {method!r}; known: {', '.join(METHODS)}")
    return method


def check_field_name(name: str) -> str:
    """``name`` if each ``+``-joined term is a field model, else ``ValueError``."""
    from orbitcal.field import FIELD_NAMES

    terms = [t.strip() for t in name.split("+")]
    unknown = [t for t in terms if t not in FIELD_NAMES]
    if unknown:
        raise ValueError(
            f"unknown field model {unknown[0]!r}; available: {', '.join(FIELD_NAMES)} "
            "(terms joined with '+')"
        )
    return name


#: Stored schedules already warned about: (spacecraft, fields).
_WARNED: set[tuple[str, tuple[str, ...]]] = set()


class Schedule(BaseModel):
    """A spacecraft's overrides of the retraining schedule, as stored (``None``: the setting)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    cadence_s: float | None = Field(default=None, gt=0, le=CADENCE_S_MAX, allow_inf_nan=False)
    min_new_samples: int | None = Field(default=None, ge=0, le=MIN_NEW_SAMPLES_MAX)
    window_s: float | None = Field(
        default=None, ge=WINDOW_S_MIN, le=WINDOW_S_MAX, allow_inf_nan=False
    )

    @classmethod
    def from_stored(cls, stored: dict[str, Any] | None, *, spacecraft: object = "") -> Schedule:
        """The stored schedule; a value stored before these bounds existed that breaks them is
        dropped (the setting applies) with a warning, never a failure of every later job."""
        stored = dict(stored or {})
        try:
            return cls.model_validate(stored)
        except ValidationError as exc:
            bad = {str(e["loc"][0]) for e in exc.errors() if e.get("loc")}
            key = (str(spacecraft), tuple(sorted(bad)))
            if key not in _WARNED:  # once per process, not on every scheduler tick
                _WARNED.add(key)
                log.warning(
                    "stored schedule out of bounds: the settings apply instead",
                    extra={"spacecraft": str(spacecraft), "fields": sorted(bad)},
                )
            kept = {k: v for k, v in stored.items() if k not in bad and k in cls.model_fields}
            return cls.model_validate(kept)


class StoredParamsError(BadInputError):
    """A job's stored parameters break the bounds (stored before they existed)."""


class RetrainParams(BaseModel):
    """Everything a retraining job fits with, resolved once and stored with the job."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    method: str = Field(max_length=64)
    field: str = Field(max_length=200)
    window_s: float = Field(ge=WINDOW_S_MIN, le=WINDOW_S_MAX, allow_inf_nan=False)
    holdout_fraction: float = Field(gt=0.0, le=HOLDOUT_FRACTION_MAX, allow_inf_nan=False)
    min_samples: int = Field(ge=1, le=MIN_SAMPLES_MAX)
    seed: int = Field(default=0, ge=0, le=SEED_MAX)

    @field_validator("method")
    @classmethod
    def _known_method(cls, method: str) -> str:
        return check_method(method)

    @field_validator("field")
    @classmethod
    def _known_field(cls, name: str) -> str:
        return check_field_name(name)

    @classmethod
    def resolve(
        cls,
        settings: Settings,
        *,
        schedule: Schedule | None = None,
        overrides: dict[str, Any] | None = None,
    ) -> RetrainParams:
        """The parameters of a new job: ``overrides`` (the request), then the spacecraft's
        ``schedule``, then the settings. The request was validated at the door; a setting out of
        bounds raises :class:`BadInputError` naming ``settings.<name>``."""
        window_s = schedule.window_s if schedule is not None else None
        values: dict[str, Any] = {
            "method": settings.method,
            "field": settings.reference_field,
            "window_s": window_s if window_s is not None else settings.window_s,
            "holdout_fraction": settings.holdout_fraction,
            "min_samples": settings.min_samples,
            "seed": 0,
            **(overrides or {}),
        }
        try:
            return cls.model_validate(values)
        except ValidationError as exc:
            raise _named(exc, "settings or schedule", BadInputError) from None

    @classmethod
    def from_stored(cls, stored: dict[str, Any], settings: Settings) -> RetrainParams:
        """A job's parameters as stored. Jobs stored before every key was resolved at creation
        (older releases) get the missing keys from the settings; values that break the bounds
        raise :class:`StoredParamsError` (the job fails saying which, nothing is fitted)."""
        values = {k: v for k, v in stored.items() if v is not None}
        values.setdefault("method", settings.method)
        values.setdefault("field", settings.reference_field)
        values.setdefault("window_s", settings.window_s)
        values.setdefault("holdout_fraction", settings.holdout_fraction)
        values.setdefault("min_samples", settings.min_samples)
        try:
            return cls.model_validate(values)
        except ValidationError as exc:
            raise _named(exc, "stored job parameters", StoredParamsError) from None

    def stored(self) -> dict[str, Any]:
        """The JSON stored with the job (``Job.params``)."""
        return self.model_dump()


def _named(exc: ValidationError, what: str, error: type[BadInputError]) -> BadInputError:
    first = exc.errors()[0]
    name = ".".join(str(p) for p in first.get("loc", ())) or None
    reasons = "; ".join(
        f"{'.'.join(str(p) for p in e.get('loc', ()))}: {e.get('msg', '')}" for e in exc.errors()
    )
    return error(f"{what} out of bounds: {reasons}", field=name)
