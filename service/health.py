"""Calibration health, continuously: every upload's new samples scored against the calibration
in service, the change rule run on that series, and a retraining on post-change data when it
fires (issue 47; the rule is :mod:`orbitcal.health`, documented in docs/design.md).

* :func:`score_new_samples` runs after an upload's commit, off the request path: the ingest route
  hands the spacecraft to the app's :class:`service.health_worker.HealthWorker` (one thread) and
  answers; the health routes wait for that spacecraft's pending scoring first, so what a client
  reads after its upload's answer includes that upload (deterministic for tests). It scores the
  samples newer than the spacecraft's last scored one once there are ``health_min_samples`` of
  them (at most the newest ``health_max_samples``), in the one RMS of CONTRACT "Definitions".
* :func:`record_holdout` starts a new version's series with its score on its own held-out block
  (the retraining job calls it after a promotion): the series is never empty under a version.
* When the rule fires, the point carries ``change_at`` (where the change began), the version is
  stale, and ``service.health_worker.request_retraining`` queues a retraining as soon as
  ``min_samples`` samples after the change are stored; :func:`change_since_utc_s` makes every
  retraining of the spacecraft start at the change (``service.jobs``). A stale version is never
  pushed to Yamcs.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from datetime import datetime
from typing import Any

import numpy as np
import sqlalchemy as sa
from sqlalchemy.engine import Connection, Engine

from orbitcal.health import ChangeRule, variance_change_index
from orbitcal.metrics import rms_nt
from service.settings import Settings
from service.storage import (
    Calibration,
    HealthPoint,
    Job,
    Spacecraft,
    count_samples,
    read_samples,
    read_tx,
    write_tx,
)

__all__ = [
    "RULE",
    "Scored",
    "change_since_utc_s",
    "health_answer",
    "is_stale",
    "record_holdout",
    "score_new_samples",
    "series",
]

log = logging.getLogger("orbitcal.service.health")

#: The service's change rule (docs/design.md, "Calibration health").
RULE = ChangeRule()

_LOCKS: dict[int, threading.Lock] = {}
_LOCKS_GUARD = threading.Lock()


def _lock(spacecraft_pk: int) -> threading.Lock:
    with _LOCKS_GUARD:
        return _LOCKS.setdefault(spacecraft_pk, threading.Lock())


@dataclass(frozen=True)
class Scored:
    """A batch scored against one calibration: RMS, noise floor, residual and sample times."""

    rms_nt: float
    noise_nt: float | None
    residual_nt: np.ndarray
    t_utc_s: np.ndarray


def _score(sc: Any, document: dict[str, Any], samples: Any, settings: Settings) -> Scored:
    """The batch's residual through the document's full calibration, against the reference
    field (the truth computation of a retraining, on these rows only)."""
    from orbitcal.diagnose.noise import noise_floor_nt
    from orbitcal.pipeline import fit_data_for_telemetry, orbit_from, residuals

    tel = samples.to_telemetry() if hasattr(samples, "to_telemetry") else samples
    truth, _name = fit_data_for_telemetry(
        tel,
        orbit=orbit_from(sc.tle, sc.omm),
        field=settings.reference_field,
        attitude_frame=sc.attitude_frame,
    )
    _b, vec, scalar = residuals(document, truth)
    r = vec if vec is not None else np.asarray(scalar)[:, None]
    noise = noise_floor_nt(r)
    return Scored(rms_nt(r), noise if np.isfinite(noise) else None, r, tel.t_utc_s)


def _served(conn: Connection, spacecraft_pk: int) -> Any:
    return conn.execute(
        sa.select(
            Calibration.version,
            Calibration.document,
            Calibration.holdout_rms_nt,
            Calibration.created_at,
        ).where(Calibration.spacecraft_pk == spacecraft_pk, Calibration.status == "in_service")
    ).first()


def _ref_rms_nt(served: Any) -> float:
    value = served.holdout_rms_nt
    if value is None:
        value = (served.document.get("metrics") or {}).get("holdout_rms_nt")
    return float(value) if value else float("nan")


def _iso_to_utc_s(text: str) -> float:
    return datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()


def _latest(conn: Connection, spacecraft_pk: int, version: int) -> Any:
    """The newest point of ``version`` (None before any)."""
    return conn.execute(
        sa.select(HealthPoint)
        .where(HealthPoint.spacecraft_pk == spacecraft_pk, HealthPoint.version == version)
        .order_by(HealthPoint.end_us.desc(), HealthPoint.pk.desc())
        .limit(1)
    ).first()


def _points(conn: Connection, spacecraft_pk: int, version: int | None = None) -> list[Any]:
    q = sa.select(HealthPoint).where(HealthPoint.spacecraft_pk == spacecraft_pk)
    if version is not None:
        q = q.where(HealthPoint.version == version)
    return list(conn.execute(q.order_by(HealthPoint.end_us, HealthPoint.pk)).all())


def record_holdout(
    engine: Engine,
    settings: Settings,
    spacecraft_pk: int,
    *,
    version: int,
    start_utc_s: float,
    end_utc_s: float,
) -> None:
    """Start the series of a just-promoted ``version`` with its score on its held-out block."""
    with _lock(spacecraft_pk), read_tx(engine) as conn:
        sc = conn.execute(sa.select(Spacecraft).where(Spacecraft.pk == spacecraft_pk)).one()
        served = _served(conn, spacecraft_pk)
        samples = read_samples(conn, spacecraft_pk, start_utc_s=start_utc_s, end_utc_s=end_utc_s)
    if served is None or served.version != version or len(samples) == 0:
        return
    try:
        scored = _score(sc, served.document, samples, settings)
    except ValueError as exc:  # e.g. a housekeeping input the rows lack
        log.warning("health: held-out block not scored", extra={"reason": str(exc)})
        return
    _insert(engine, spacecraft_pk, version, "holdout", scored, _ref_rms_nt(served), 0.0, None)


def _insert(
    engine: Engine,
    spacecraft_pk: int,
    version: int,
    kind: str,
    scored: Scored,
    ref_rms_nt: float,
    cusum: float,
    change_at_us: int | None,
    *,
    stale: bool = False,
) -> None:
    t = scored.t_utc_s
    with write_tx(engine) as conn:
        conn.execute(
            sa.insert(HealthPoint).values(
                spacecraft_pk=spacecraft_pk,
                version=version,
                kind=kind,
                start_us=round(float(t[0]) * 1e6),
                end_us=round(float(t[-1]) * 1e6),
                n=int(t.shape[0]),
                rms_nt=scored.rms_nt,
                noise_nt=scored.noise_nt,
                ref_rms_nt=ref_rms_nt if np.isfinite(ref_rms_nt) else scored.rms_nt,
                cusum=cusum,
                stale=stale,
                change_at_us=change_at_us,
                created_at=time.time(),
            )
        )


def _new_rows(conn: Connection, spacecraft_pk: int, start_utc_s: float, fresh: Any) -> Any:
    """The stored samples from ``start_utc_s`` on: the upload's rows in memory (``fresh``, all of
    them newly stored) when they are exactly those (no other unscored sample, none quarantined),
    else read back from the database (15 µs a sample: most of the cost of scoring)."""
    if fresh is not None and len(fresh):
        t_us = np.rint(np.asarray(fresh.t_utc_s) * 1e6).astype(np.int64)
        keep = t_us >= round(start_utc_s * 1e6)
        n_kept = int(np.count_nonzero(keep))
        outside = count_samples(
            conn, spacecraft_pk, start_utc_s=start_utc_s, include_quarantined=False
        )
        stored = count_samples(conn, spacecraft_pk, start_utc_s=start_utc_s)
        if outside == stored == n_kept:
            return fresh.select(keep).sort_by_time()
    return read_samples(conn, spacecraft_pk, start_utc_s=start_utc_s)


def score_new_samples(
    engine: Engine, settings: Settings, spacecraft_pk: int, *, fresh: Any = None
) -> bool:
    """Score the spacecraft's unscored new samples against the calibration in service.

    ``fresh``: the telemetry of the upload just stored when every row of it was new (it then
    need not be read back). Returns whether the calibration in service is stale afterwards.
    Nothing is scored before the first calibration or while fewer than ``health_min_samples``
    new samples wait.
    """
    with _lock(spacecraft_pk):
        with read_tx(engine) as conn:
            served = _served(conn, spacecraft_pk)
            if served is None:
                return False
            sc = conn.execute(sa.select(Spacecraft).where(Spacecraft.pk == spacecraft_pk)).one()
            last_end_us = conn.execute(
                sa.select(sa.func.max(HealthPoint.end_us)).where(
                    HealthPoint.spacecraft_pk == spacecraft_pk
                )
            ).scalar_one_or_none()
            latest = _latest(conn, spacecraft_pk, served.version)
            if last_end_us is not None:
                start = (last_end_us + 1) / 1e6
            else:  # a version stored before health existed: from the end of its data
                start = _iso_to_utc_s(served.document["data"]["end"]) + 1e-6
            samples = _new_rows(conn, spacecraft_pk, start, fresh)
        if len(samples) < settings.health_min_samples:
            return bool(latest is not None and latest.stale)
        if len(samples) > settings.health_max_samples:
            cut = len(samples) - settings.health_max_samples
            samples = samples.select(np.arange(len(samples)) >= cut)
        try:
            scored = _score(sc, served.document, samples, settings)
        except ValueError as exc:
            log.warning("health: batch not scored", extra={"reason": str(exc)})
            return bool(latest is not None and latest.stale)
        ref = _ref_rms_nt(served)
        if not np.isfinite(ref):
            ref = scored.rms_nt
        was_stale = bool(latest is not None and latest.stale)
        s = RULE.step(latest.cusum if latest is not None else 0.0, scored.rms_nt, ref)
        change_us = None
        if not was_stale and RULE.alarm(s):
            with read_tx(engine) as conn:
                mine = _points(conn, spacecraft_pk, served.version)
            change_us = _change_at_us(engine, settings, sc, served, mine, scored)
        _insert(
            engine,
            spacecraft_pk,
            served.version,
            "new",
            scored,
            ref,
            s,
            change_us,
            stale=was_stale or change_us is not None,
        )
    if change_us is not None:
        log.warning(
            "calibration stale",
            extra={"spacecraft": sc.id, "version": served.version, "rms_nt": scored.rms_nt},
        )
    return was_stale or change_us is not None


def _change_at_us(
    engine: Engine,
    settings: Settings,
    sc: Any,
    served: Any,
    mine: list[Any],
    current: Scored,
) -> int:
    """Where the change began: the run's first point (after the last ``S = 0``), refined to the
    sample by the variance split over that point and the one before it."""
    cusums = [p.cusum for p in mine]
    zeros = [i for i, c in enumerate(cusums) if c == 0.0]
    first_of_run = zeros[-1] + 1 if zeros else 0  # index into mine; len(mine): the current point
    before = mine[first_of_run - 1] if first_of_run >= 1 else None
    if first_of_run >= len(mine):  # the run starts at the current batch
        end_s = float(current.t_utc_s[-1])
    else:
        end_s = mine[first_of_run].end_us / 1e6
    start_s = (
        before.start_us / 1e6
        if before is not None
        else float(current.t_utc_s[0] if first_of_run >= len(mine) else mine[0].start_us / 1e6)
    )
    with read_tx(engine) as conn:
        samples = read_samples(conn, sc.pk, start_utc_s=start_s, end_utc_s=end_s)
    try:
        span = _score(sc, served.document, samples, settings)
    except ValueError:
        span = current
    return round(float(span.t_utc_s[variance_change_index(span.residual_nt)]) * 1e6)


def change_since_utc_s(conn: Connection, spacecraft_pk: int) -> float | None:
    """When the latest change the health check found began [s of UTC]; None if none was."""
    us = conn.execute(
        sa.select(sa.func.max(HealthPoint.change_at_us)).where(
            HealthPoint.spacecraft_pk == spacecraft_pk
        )
    ).scalar_one_or_none()
    return None if us is None else us / 1e6


def is_stale(conn: Connection, spacecraft_pk: int, version: int) -> bool:
    """Whether the health check found ``version`` stale."""
    return (
        conn.execute(
            sa.select(HealthPoint.pk)
            .where(
                HealthPoint.spacecraft_pk == spacecraft_pk,
                HealthPoint.version == version,
                HealthPoint.stale.is_(True),
            )
            .limit(1)
        ).first()
        is not None
    )


def _next_retraining(conn: Connection, settings: Settings, sc: Any, stale: bool) -> float | None:
    """When the next retraining is due [s of UTC]: a live job's creation, or the schedule's next
    slot once enough new samples are stored; None when it waits for data (a stale calibration:
    for ``min_samples`` samples after the change) or no scheduler runs."""
    from service.params import Schedule

    live = conn.execute(
        sa.select(sa.func.min(Job.created_at)).where(
            Job.spacecraft_pk == sc.pk, Job.status.in_(("queued", "running"))
        )
    ).scalar_one_or_none()
    if live is not None:
        return float(live)
    if stale:  # queued by the next upload once min_samples samples after the change are stored
        return None
    if not settings.scheduler:
        return None
    plan = Schedule.from_stored(sc.schedule, spacecraft=sc.pk)
    cadence = settings.cadence_s if plan.cadence_s is None else plan.cadence_s
    min_new = settings.min_new_samples if plan.min_new_samples is None else plan.min_new_samples
    if sc.sample_count - sc.samples_at_last_job < min_new:
        return None
    return max(time.time(), (sc.last_job_at or 0.0) + cadence)


def health_answer(conn: Connection, settings: Settings, sc: Any) -> dict[str, Any] | None:
    """The CONTRACT §3 health answer of the calibration in service, times in s of UTC (the
    route writes them as ISO-8601); None before the first calibration."""
    served = _served(conn, sc.pk)
    if served is None:
        return None
    latest = _latest(conn, sc.pk, served.version)
    alarm = conn.execute(
        sa.select(HealthPoint.change_at_us).where(
            HealthPoint.spacecraft_pk == sc.pk,
            HealthPoint.version == served.version,
            HealthPoint.change_at_us.is_not(None),
        )
    ).first()
    stale = bool(latest is not None and latest.stale)
    ref = _ref_rms_nt(served)
    return {
        "version": int(served.version),
        "in_service_since": _promoted_at(conn, sc.pk, served),
        "recent_rms_nt": float(latest.rms_nt if latest is not None else ref),
        "noise_nt": float(
            latest.noise_nt if latest is not None and latest.noise_nt is not None else ref
        ),
        "stale": stale,
        "change_at": None if alarm is None else alarm.change_at_us / 1e6,
        "next_retraining": _next_retraining(conn, settings, sc, stale),
    }


def _promoted_at(conn: Connection, spacecraft_pk: int, served: Any) -> float:
    """When ``served`` went into service: its job's end (the promotion's commit), else its
    creation."""
    finished = conn.execute(
        sa.select(Job.finished_at)
        .join(Calibration, Calibration.job_id == Job.id)
        .where(Calibration.spacecraft_pk == spacecraft_pk, Calibration.version == served.version)
    ).scalar_one_or_none()
    return float(finished if finished is not None else served.created_at)


def series(conn: Connection, spacecraft_pk: int, *, limit: int = 2000) -> list[dict[str, Any]]:
    """The health series, oldest first (the newest ``limit`` points); times in s of UTC."""
    rows = conn.execute(
        sa.select(HealthPoint)
        .where(HealthPoint.spacecraft_pk == spacecraft_pk)
        .order_by(HealthPoint.end_us.desc(), HealthPoint.pk.desc())
        .limit(limit)
    ).all()
    return [
        {
            "version": p.version,
            "kind": p.kind,
            "start": p.start_us / 1e6,
            "end": p.end_us / 1e6,
            "n": p.n,
            "rms_nt": p.rms_nt,
            "noise_nt": p.noise_nt,
            "ref_rms_nt": p.ref_rms_nt,
            "cusum": p.cusum,
            "stale": p.stale,
            "change_at": None if p.change_at_us is None else p.change_at_us / 1e6,
            "scored_at": p.created_at,
        }
        for p in reversed(rows)
    ]
