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
    #: Failed authentications (401 answers) allowed per client address [1/s] after a burst; once
    #: an address has exhausted them, its failed authentications are answered 429 instead of 401
    #: until the bucket refills (0: off). A valid key is never refused by this limit.
    auth_fail_per_s: float = Field(default=1.0, ge=0)
    auth_fail_burst: int = Field(default=100, ge=1)
    #: Redis URL of the buckets shared by every API process (``redis://host:6379/1``); empty:
    #: buckets live in the process, right for the single-process default.
    rate_limit_redis_url: str = ""

    #: Largest request body accepted [bytes]; larger ones get 413.
    max_body_bytes: int = 64 * 1024 * 1024

    #: The HTTP server's own limits (``service.http``; docs/reliability.md). The request line and
    #: headers together may hold at most ``max_header_bytes`` and ``max_header_count`` fields
    #: (431 beyond, read no further); they must arrive within ``header_timeout_s`` of the
    #: connection opening (or of the request's first byte on a kept-alive connection), and a
    #: body may pause at most ``body_idle_timeout_s`` between two pieces and take at most
    #: ``body_timeout_s`` in all (408, nothing stored). On SIGTERM, uploads still arriving get
    #: half of ``shutdown_timeout_s`` to finish, requests being processed the whole of it; then
    #: the process stops. More than ``max_connections`` open connections get 503.
    max_header_bytes: int = Field(default=64 * 1024, ge=1024, le=16 * 1024 * 1024)
    max_header_count: int = Field(default=100, ge=8, le=10_000)
    header_timeout_s: float = Field(default=10.0, gt=0, le=3600)
    body_idle_timeout_s: float = Field(default=30.0, gt=0, le=3600)
    body_timeout_s: float = Field(default=600.0, gt=0, le=86400)
    shutdown_timeout_s: float = Field(default=10.0, gt=0, le=3600)
    max_connections: int = Field(default=1000, ge=1)
    #: The HTTP/1.1 implementation under those limits (``service.http``): ``httptools`` (the C
    #: parser, the default: half of h11's server CPU per request,
    #: ``benchmarks/results/load_reads.md``) or ``h11`` (pure Python). Both enforce every limit
    #: above the same way.
    http_protocol: Literal["httptools", "h11"] = "httptools"
    #: Proxies whose ``X-Forwarded-For``/``X-Forwarded-Proto`` are believed (comma-separated
    #: addresses or networks, ``*`` for any; uvicorn's ``--forwarded-allow-ips`` semantics). The
    #: client address the rate limiter sees is then the one the proxy reports. Empty (the
    #: default): no proxy is trusted and the headers are ignored.
    forwarded_allow_ips: str = ""
    #: Largest size of a SQLite database [bytes] (``PRAGMA max_page_count``); 0: unlimited. A
    #: write beyond it answers 503 "disk full" like a full file system.
    sqlite_max_bytes: int = Field(default=0, ge=0)

    #: Retraining defaults.
    method: str = "linear"
    reference_field: str = "IGRF-14"
    #: The share held out for ``holdout_rms_nt``: one default on every surface (CLI, library,
    #: service), ``orbitcal.calibrate.holdout.HOLDOUT_FRACTION``.
    holdout_fraction: float = 0.25
    window_s: float = 86400.0  # sliding window of the most recent data [s]
    min_samples: int = 200  # a fit needs at least this many samples in the window
    #: Calibration health (service/health.py): new samples are scored in batches of at least
    #: this many; at most the newest ``health_max_samples`` of a batch are scored.
    health_min_samples: int = Field(default=60, ge=8)  # the noise floor needs a few samples
    health_max_samples: int = Field(default=20000, ge=8)
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
