"""The service's state: one typed object per app, instead of untyped attributes set here and there.

``app.state`` is a :class:`ServiceState` (a Starlette ``State``, so ``request.app.state.engine``
keeps working for code that reads it that way); :func:`service_state` gives it typed. Two kinds
of field:

* made with the app (:meth:`ServiceState.new`): settings, the admin key's hash, the rate-limit
  store and the in-process caches with their locks;
* opened by the lifespan (:meth:`ServiceState.open`): the database engine, the metrics registry,
  the job runner, the scheduler, the diagnoses' pool and whether this process leads the
  deployment. Reading one before the lifespan ran is a programming error (``AttributeError``).
"""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING, Any

from starlette.datastructures import State
from starlette.requests import Request

from service.diagnosis_cache import DiagnosisCache

if TYPE_CHECKING:
    from sqlalchemy.engine import Engine

    from service.health_worker import HealthWorker
    from service.jobs import JobRunner
    from service.metrics import Metrics
    from service.ratelimit import Buckets
    from service.scheduler import FleetScheduler
    from service.settings import Settings

__all__ = ["ServiceState", "service_state"]


class ServiceState(State):
    """Everything one app holds between requests (see the module's docstring)."""

    # made with the app
    settings: Settings
    admin_key_hash: str | None
    rate_limit_store: Buckets
    #: key hash -> (service.auth.Principal, or None for unknown/revoked; monotonic expiry); typed
    #: loosely so that this module imports nothing of auth (which reads the state: no cycle)
    key_cache: dict[str, tuple[Any, float]]
    key_lock: asyncio.Lock
    #: spacecraft id -> the served calibration's bytes (``routes.calibrations``)
    calibration_cache: dict[str, Any]
    calibration_locks: dict[str, asyncio.Lock]
    #: the latest diagnosis per (spacecraft id, prior) and the one computation running
    diagnoses: DiagnosisCache

    # opened by the lifespan
    engine: Engine
    metrics: Metrics
    runner: JobRunner
    scheduler: FleetScheduler
    leader: bool
    #: scores each upload's new samples against the calibration in service (service.health)
    health: HealthWorker

    @classmethod
    def new(
        cls, settings: Settings, *, admin_key_hash: str | None, rate_limit_store: Buckets
    ) -> ServiceState:
        state = cls()
        state.settings = settings
        state.admin_key_hash = admin_key_hash
        state.rate_limit_store = rate_limit_store
        state.key_cache = {}
        state.key_lock = asyncio.Lock()
        state.calibration_cache = {}
        state.calibration_locks = {}
        state.diagnoses = DiagnosisCache()
        return state

    def open(
        self,
        *,
        engine: Engine,
        metrics: Metrics,
        runner: JobRunner,
        scheduler: FleetScheduler,
        leader: bool,
        health: HealthWorker,
    ) -> None:
        """Record what the lifespan opened (and start the diagnoses' one-thread pool)."""
        self.health = health
        self.engine = engine
        self.metrics = metrics
        self.runner = runner
        self.scheduler = scheduler
        self.leader = leader
        self.diagnoses.start()


def service_state(request: Request) -> ServiceState:
    """The typed state of the app serving ``request``."""
    state = request.app.state
    assert isinstance(state, ServiceState), "the app was not built by service.app.create_app"
    return state
