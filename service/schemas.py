"""Pydantic schemas of the HTTP API, per resource (``...In`` bodies, ``...Public`` answers)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from service.auth import SCOPE_RE, SPACECRAFT_ID_PATTERN
from service.params import (
    CADENCE_S_MAX,
    MIN_NEW_SAMPLES_MAX,
    SEED_MAX,
    WINDOW_S_MAX,
    WINDOW_S_MIN,
)

__all__ = [
    "ApiKeyCreated",
    "ApiKeyIn",
    "ApiKeyPublic",
    "CalibrationDocument",
    "CalibrationVersionPublic",
    "ErrorItem",
    "ErrorPublic",
    "HealthPointPublic",
    "HealthPublic",
    "IngestResult",
    "JobAccepted",
    "JobPublic",
    "OrbitIn",
    "RetrainIn",
    "RowRejection",
    "ScheduleIn",
    "SpacecraftIn",
    "SpacecraftPublic",
]

#: ``service.auth.SPACECRAFT_ID_PATTERN`` anchored (pydantic's regex engine: ``$`` is the very end).
SPACECRAFT_ID = rf"^{SPACECRAFT_ID_PATTERN}$"


class ErrorItem(BaseModel):
    field: str | None = None
    row: int | None = None
    reason: str


class ErrorPublic(BaseModel):
    detail: str
    errors: list[ErrorItem] = []


class ScheduleIn(BaseModel):
    """Per-spacecraft overrides of the retraining schedule."""

    model_config = ConfigDict(extra="forbid")
    # Finite and bounded: the schedule is stored as JSON (PostgreSQL refused Infinity: a 500) and
    # sample counts are 64-bit.
    # Bounds: service.params (a value stored now must not fail every later job).
    cadence_s: float | None = Field(
        default=None,
        gt=0,
        le=CADENCE_S_MAX,
        allow_inf_nan=False,
        description="retrain at most this often [s], at most 10 years",
    )
    min_new_samples: int | None = Field(default=None, ge=0, le=MIN_NEW_SAMPLES_MAX)
    window_s: float | None = Field(
        default=None,
        ge=WINDOW_S_MIN,
        le=WINDOW_S_MAX,
        allow_inf_nan=False,
        description="sliding window [s], 1 s to 10 years",
    )


class _OrbitFields(BaseModel):
    tle: str | None = Field(
        default=None, max_length=1000, description="two-line element set (optional name line first)"
    )
    omm: dict[str, Any] | None = Field(default=None, description="CCSDS OMM as a JSON object")

    @model_validator(mode="after")
    def _one_orbit(self) -> _OrbitFields:
        if self.tle is not None and self.omm is not None:
            raise ValueError("give either tle or omm, not both")
        return self


class SpacecraftIn(_OrbitFields):
    model_config = ConfigDict(extra="forbid")
    id: str = Field(
        pattern=SPACECRAFT_ID,
        description="spacecraft identifier: 1-64 of A-Z a-z 0-9 _ . -, starting with a letter "
        "or digit (one URL path segment as it is)",
    )
    attitude_frame: Literal["GCRS", "ITRS"] = "GCRS"
    schedule: ScheduleIn | None = None


class OrbitIn(_OrbitFields):
    model_config = ConfigDict(extra="forbid")

    @model_validator(mode="after")
    def _needs_one(self) -> OrbitIn:
        if self.tle is None and self.omm is None:
            raise ValueError("give tle or omm")
        return self


class SpacecraftPublic(BaseModel):
    id: str
    attitude_frame: str
    orbit: Literal["tle", "omm"] | None
    tle: str | None
    schedule: dict[str, Any] | None
    created_at: str
    samples: int
    calibration_version: int | None = None
    holdout_rms_nt: float | None = None


class RowRejection(BaseModel):
    row: int = Field(description="0-based data row (packet number for CCSDS)")
    reason: str


class IngestResult(BaseModel):
    accepted: int
    duplicates: int
    rejected: list[RowRejection]
    #: Present when the stored data look implausible (e.g. a median |B| no orbit has).
    warnings: list[str] | None = None


class RetrainIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    method: str | None = Field(default=None, max_length=64)
    window_s: float | None = Field(
        default=None,
        ge=WINDOW_S_MIN,
        le=WINDOW_S_MAX,
        allow_inf_nan=False,
        description="sliding window [s], 1 s to 10 years (service.params)",
    )
    seed: int | None = Field(default=None, ge=0, le=SEED_MAX)


class JobAccepted(BaseModel):
    job_id: str


class JobPublic(BaseModel):
    id: str
    job_id: str
    spacecraft: str
    kind: str
    trigger: str
    status: Literal["queued", "running", "succeeded", "failed"]
    error: str | None
    params: dict[str, Any]
    result: dict[str, Any] | None
    created_at: str
    started_at: str | None
    finished_at: str | None


class CalibrationDocument(BaseModel):
    """CONTRACT section 4 (extra keys allowed)."""

    model_config = ConfigDict(extra="allow")
    spacecraft: str
    version: int
    method: str
    created_at: str
    reference_field: str
    data: dict[str, Any]
    metrics: dict[str, Any]
    linear: dict[str, Any]
    model: dict[str, Any]


class CalibrationVersionPublic(BaseModel):
    version: int
    status: Literal["in_service", "rejected", "superseded"]
    reason: str | None
    created_at: str
    holdout_rms_nt: float | None
    job_id: str | None
    provenance: dict[str, Any]
    document: dict[str, Any]


class ApiKeyIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = Field(min_length=1, max_length=128)
    scopes: list[str] = Field(min_length=1, max_length=64)

    @field_validator("scopes")
    @classmethod
    def _valid_scopes(cls, scopes: list[str]) -> list[str]:
        for i, s in enumerate(scopes):
            if not SCOPE_RE.fullmatch(s):
                raise ValueError(
                    f"scopes[{i}] = {s!r} is not admin, ingest:<spacecraft|*> or "
                    "read:<spacecraft|*> (spacecraft ids as in POST /v1/spacecraft)"
                )
        return scopes


class ApiKeyCreated(BaseModel):
    key: str = Field(description="shown once; only its sha256 is stored")
    prefix: str
    name: str
    scopes: list[str]


class ApiKeyPublic(BaseModel):
    prefix: str
    name: str
    scopes: list[str]
    created_at: str
    revoked: bool


class HealthPublic(BaseModel):
    """CONTRACT section 3: the calibration in service against the newest data."""

    version: int
    in_service_since: str = Field(description="ISO-8601 UTC: when this version went into service")
    recent_rms_nt: float = Field(
        description="RMS [nT] over the N x 3 residual of the newest scored batch (CONTRACT "
        "Definitions); the version's held-out RMS until a batch arrives"
    )
    noise_nt: float = Field(
        description="white-noise floor [nT] of that batch's residual (second differences)"
    )
    stale: bool = Field(description="the change rule (docs/design.md) found the error grown")
    change_at: str | None = Field(description="ISO-8601 UTC: when the change began; null if none")
    next_retraining: str | None = Field(
        description="ISO-8601 UTC: when the next retraining is due; null while it waits for data"
    )


class HealthPointPublic(BaseModel):
    """One scored batch of the health series."""

    version: int
    kind: Literal["new", "holdout"]
    start: str
    end: str
    n: int
    rms_nt: float
    noise_nt: float | None
    ref_rms_nt: float = Field(description="the version's held-out RMS the rule compares with [nT]")
    cusum: float = Field(description="the change rule's CUSUM S_k [ln]; stale from ln 4 on")
    stale: bool
    change_at: str | None
    scored_at: str = Field(description="ISO-8601 UTC (wall clock): when the service scored it")
