"""Prometheus metrics: in-process counters plus gauges read from the database at scrape time.

``/metrics`` shows a caller only what its key may read (:meth:`Metrics.exposition`): series with
a ``spacecraft`` label for the spacecraft it may read; fleet-wide series (jobs by status, ingest
and retraining totals) only to keys that may read every spacecraft (``read:*`` or ``admin``),
the scope to give a Prometheus scraper.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import sqlalchemy as sa
from prometheus_client import CollectorRegistry, Counter, Histogram, generate_latest
from prometheus_client.core import GaugeMetricFamily
from prometheus_client.metrics_core import Metric
from prometheus_client.registry import Collector
from sqlalchemy.engine import Engine

from service.storage import Calibration, HealthPoint, Job, Spacecraft, read_tx

__all__ = ["Metrics"]


class _DatabaseCollector(Collector):
    """Queue depth, in-service held-out RMS and last retrain duration per spacecraft."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    def collect(self) -> Iterator[Any]:
        queue = GaugeMetricFamily(
            "orbitcal_jobs", "Retraining jobs by status (queued = queue depth)", labels=["status"]
        )
        rms = GaugeMetricFamily(
            "orbitcal_holdout_rms_nt",
            "Held-out RMS of the calibration in service [nT]",
            labels=["spacecraft"],
        )
        last = GaugeMetricFamily(
            "orbitcal_last_retrain_duration_seconds",
            "Duration of the last finished retraining job [s]",
            labels=["spacecraft"],
        )
        samples = GaugeMetricFamily(
            "orbitcal_samples_stored", "Samples stored", labels=["spacecraft"]
        )
        health = _HealthGauges()
        try:
            with read_tx(self.engine) as conn:
                health.read(conn)
                counts = dict(
                    conn.execute(sa.select(Job.status, sa.func.count()).group_by(Job.status)).all()
                )
                for status in ("queued", "running", "succeeded", "failed"):
                    queue.add_metric([status], float(counts.get(status, 0)))
                for sc, value in conn.execute(
                    sa.select(Spacecraft.id, Calibration.holdout_rms_nt)
                    .join(Calibration, Calibration.spacecraft_pk == Spacecraft.pk)
                    .where(Calibration.status == "in_service")
                ).all():
                    if value is not None:
                        rms.add_metric([sc], float(value))
                for sc, n in conn.execute(sa.select(Spacecraft.id, Spacecraft.sample_count)).all():
                    samples.add_metric([sc], float(n))
                latest = (
                    sa.select(Job.spacecraft_pk, sa.func.max(Job.finished_at).label("finished_at"))
                    .where(Job.finished_at.is_not(None))
                    .group_by(Job.spacecraft_pk)
                    .subquery()
                )
                for sc, started, finished in conn.execute(
                    sa.select(Spacecraft.id, Job.started_at, Job.finished_at)
                    .join(Job, Job.spacecraft_pk == Spacecraft.pk)
                    .join(
                        latest,
                        sa.and_(
                            latest.c.spacecraft_pk == Job.spacecraft_pk,
                            latest.c.finished_at == Job.finished_at,
                        ),
                    )
                ).all():
                    if started is not None and finished is not None:
                        last.add_metric([sc], float(finished - started))
        except sa.exc.SQLAlchemyError:
            return
        yield queue
        yield from health.families()
        yield rms
        yield last
        yield samples


class _HealthGauges:
    """The calibration-health gauges per spacecraft (service.health): the newest scored batch of
    the version in service."""

    def __init__(self) -> None:
        def gauge(name: str, doc: str) -> GaugeMetricFamily:
            return GaugeMetricFamily(name, doc, labels=["spacecraft"])

        self.recent = gauge(
            "orbitcal_health_recent_rms_nt",
            "RMS of the calibration in service on the newest scored batch [nT]",
        )
        self.noise = gauge(
            "orbitcal_health_noise_nt", "White-noise floor of the newest scored batch [nT]"
        )
        self.cusum = gauge(
            "orbitcal_health_cusum", "The change rule's CUSUM (stale from ln 4 = 1.386 on)"
        )
        self.stale = gauge(
            "orbitcal_health_stale", "1 when the calibration in service is stale, else 0"
        )

    def read(self, conn: Any) -> None:
        newest = (
            sa.select(HealthPoint.spacecraft_pk, sa.func.max(HealthPoint.pk).label("pk"))
            .join(
                Calibration,
                sa.and_(
                    Calibration.spacecraft_pk == HealthPoint.spacecraft_pk,
                    Calibration.version == HealthPoint.version,
                    Calibration.status == "in_service",
                ),
            )
            .group_by(HealthPoint.spacecraft_pk)
            .subquery()
        )
        rows = conn.execute(
            sa.select(
                Spacecraft.id,
                HealthPoint.rms_nt,
                HealthPoint.noise_nt,
                HealthPoint.cusum,
                HealthPoint.stale,
            )
            .join(HealthPoint, HealthPoint.spacecraft_pk == Spacecraft.pk)
            .join(newest, newest.c.pk == HealthPoint.pk)
        ).all()
        for sc, rms, noise, cusum, stale in rows:
            self.recent.add_metric([sc], float(rms))
            if noise is not None:
                self.noise.add_metric([sc], float(noise))
            self.cusum.add_metric([sc], float(cusum))
            self.stale.add_metric([sc], 1.0 if stale else 0.0)

    def families(self) -> Iterator[GaugeMetricFamily]:
        yield from (self.recent, self.noise, self.cusum, self.stale)


class Metrics:
    """One registry per app (no global state)."""

    def __init__(self, engine: Engine) -> None:
        self.registry = CollectorRegistry()
        self.ingest_samples = Counter(
            "orbitcal_ingest_samples",
            "Samples accepted (new) by ingest; rate() gives the ingest rate",
            ["format"],
            registry=self.registry,
        )
        self.ingest_duplicates = Counter(
            "orbitcal_ingest_duplicates",
            "Samples already stored (unchanged)",
            ["format"],
            registry=self.registry,
        )
        self.ingest_rejected = Counter(
            "orbitcal_ingest_rejected_rows",
            "Rows rejected by validation",
            ["format"],
            registry=self.registry,
        )
        self.ingest_seconds = Histogram(
            "orbitcal_ingest_request_seconds",
            "Time to parse, validate and commit one upload",
            ["format"],
            registry=self.registry,
        )
        self.retrain_seconds = Histogram(
            "orbitcal_retrain_duration_seconds",
            "Retraining job duration in this process",
            ["outcome"],
            buckets=(0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 120, 300),
            registry=self.registry,
        )
        self.registry.register(_DatabaseCollector(engine))

    def exposition(self, *, may_read: Callable[[str], bool], fleet: bool) -> bytes:
        """The Prometheus text of what a caller may see.

        ``may_read(spacecraft)`` says whether a series labelled with that spacecraft is shown;
        ``fleet`` whether the series without a spacecraft label (totals over the fleet) are.
        """
        return generate_latest(_Scoped(self.registry, may_read, fleet))  # type: ignore[arg-type]


class _Scoped:
    """A registry's families with the samples a caller may see (duck-typed for generate_latest)."""

    def __init__(
        self, registry: CollectorRegistry, may_read: Callable[[str], bool], fleet: bool
    ) -> None:
        self.registry = registry
        self.may_read = may_read
        self.fleet = fleet

    def collect(self) -> Iterator[Metric]:
        for family in self.registry.collect():
            kept = [
                s
                for s in family.samples
                if (
                    self.may_read(s.labels["spacecraft"])
                    if "spacecraft" in s.labels
                    else self.fleet
                )
            ]
            if not kept:
                continue
            out = Metric(family.name, family.documentation, family.type, family.unit)
            out.samples = kept
            yield out
