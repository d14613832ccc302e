"""Service settings, read from the environment with the prefix ``ORBITCAL_``."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["Settings", "default_database_url"]


def default_database_url() -> str:
    """SQLite file in the current directory: the embedded default of ``orbitcal serve``."""
    return f"sqlite:///{Path('orbitcal.sqlite').resolve()}"


class Settings(BaseSettings):
    """Everything the service reads from its environment (``ORBITCAL_<NAME>``)."""

    model_config = SettingsConfigDict(env_prefix="ORBITCAL_", extra="ignore")

    database_url: str = Field(default_factory=default_database_url)
    #: SQLite ``synchronous`` pragma; FULL makes every acknowledged commit survive power loss.
    sqlite_synchronous: Literal["NORMAL", "FULL"] = "FULL"

    #: Authentication is on unless disabled; disabling is refused unless bound to loopback.
    auth: bool = True
    admin_key: SecretStr | None = None
    #: Address the server is bound to (set by ``orbitcal serve``), used for the loopback check.
    bind_host: str = "127.0.0.1"

    #: Per-key rate limit [requests/s] and burst (``service.ratelimit``); 0 turns it off. On by
    #: default with room for a busy ground station (uploads come in batches of 10^3–10^5 rows).
    rate_limit_per_s: float = Field(default=200.0, ge=0)
    rate_limit_burst: int = Field(default=1000, ge=1)

    #: Largest request body accepted [bytes]; larger ones get 413.
    max_body_bytes: int = 64 * 1024 * 1024

    #: Retraining defaults.
    method: str = "linear"
    reference_field: str = "IGRF-14"
    holdout_fraction: float = 0.2
    window_s: float = 86400.0  # sliding window of the most recent data [s]
    min_samples: int = 200  # a fit needs at least this many samples in the window
    min_new_samples: int = 500  # scheduled retraining waits for this many new samples
    cadence_s: float = 3600.0  # per-spacecraft scheduled retraining cadence [s]
    scheduler_tick_s: float = 10.0  # how often the scheduler looks for due spacecraft [s]
    #: Promotion margin: a challenger must beat the served RMS by this fraction (0 = strictly less).
    promote_margin: float = 0.0
    #: A retraining lock older than this is considered abandoned (crashed worker) [s].
    lock_timeout_s: float = 1800.0

    #: "inline": jobs run in a thread pool inside the API; "celery": jobs go to Celery workers.
    job_backend: Literal["inline", "celery"] = "inline"
    #: Whether this process runs the scheduler (exactly one per deployment).
    scheduler: bool = True
    broker_url: str = "redis://127.0.0.1:6379/0"
    #: Celery queue the jobs go to (one per deployment sharing a broker).
    queue: str = "orbitcal"
    #: Worker threads for the inline job backend.
    inline_workers: int = 1

    #: API-key lookups are cached this long (revocations take effect within it) [s].
    key_cache_s: float = 5.0
    #: ``GET .../calibration`` answers are cached this long per spacecraft [s].
    read_cache_s: float = 1.0

    log_level: str = "INFO"
