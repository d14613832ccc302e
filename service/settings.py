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
    #: Failed authentications (401 answers) allowed per client address [1/s] after a burst; an
    #: address that exhausts them gets 429 on every request until its bucket refills (0: off).
    auth_fail_per_s: float = Field(default=1.0, ge=0)
    auth_fail_burst: int = Field(default=100, ge=1)
    #: Redis URL of the buckets shared by every API process (``redis://host:6379/1``); empty:
    #: buckets live in the process, right for the single-process default.
    rate_limit_redis_url: str = ""

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
    #: Promotion (``orbitcal.pipeline.decide_promotion``): a challenger must beat the served
    #: held-out RMS by more than this fraction **and** the paired test must give p < alpha.
    promote_margin: float = Field(default=0.01, ge=0.0, lt=1.0)
    promote_alpha: float = Field(default=0.01, gt=0.0, le=1.0)
    #: A retraining lock older than this is considered abandoned (crashed worker) [s].
    lock_timeout_s: float = 1800.0
    #: Quiet-time selection for retraining (orbitcal.auxdata.storm_mask): rows whose 3-hour Kp
    #: exceeds quiet_kp_max or whose hourly Dst is below quiet_dst_min_nt [nT] are left out of the
    #: fit and the comparison; None switches a criterion off (both off by default).
    quiet_kp_max: float | None = None
    quiet_dst_min_nt: float | None = None
    #: The scheduler fetches the auxiliary tables (orbitcal data update) this often [s]; 0 = off.
    aux_update_s: float = Field(default=0.0, ge=0)

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

    #: API processes serving this deployment (``uvicorn --workers``). With more than one, the
    #: rate limiter needs ``RATE_LIMIT_REDIS_URL`` (or is off), so that the limits hold in total.
    workers: int = Field(default=1, ge=1)

    #: ``yamcs-push`` after each promotion (issue 21, ``service/yamcs_hook.py``): the Yamcs base
    #: URL (empty: off), instance, processor, SpaceSystem of the loaded XTCE export, credentials.
    yamcs_push_url: str = ""
    yamcs_push_instance: str = ""
    yamcs_push_processor: str = "realtime"
    yamcs_push_space_system: str = "MAGCAL"
    yamcs_push_user: str = ""
    yamcs_push_password: SecretStr | None = None

    log_level: str = "INFO"
