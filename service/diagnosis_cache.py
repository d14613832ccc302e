"""The service's diagnoses: the latest report per spacecraft and the one computation running.

A diagnosis takes minutes on a day of data, so the route does not compute it in the request: a
one-thread pool runs one computation at a time per ``(spacecraft, prior)``, and each report is
kept with the key of everything it depends on (``routes.calibrations.answer_key``) until that
changes. Reports are :class:`orbitcal.diagnose.Report` objects: read-only, answered with
:meth:`~orbitcal.diagnose.Report.to_json`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Hashable
from concurrent.futures import Future
from typing import TYPE_CHECKING

from service.threads import DaemonPool

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.diagnose.result import Report

__all__ = ["DiagnosisCache", "DiagnosisKey"]

#: ``(spacecraft id, prior)``: a diagnosis with and one without the calibration in service as prior.
DiagnosisKey = tuple[str, bool]


class DiagnosisCache:
    """The latest report per :data:`DiagnosisKey` with the answer key it was computed for, and
    the computation running for each (at most one)."""

    def __init__(self) -> None:
        self._reports: dict[DiagnosisKey, tuple[Hashable, Report]] = {}
        self._running: dict[DiagnosisKey, Future[Report]] = {}
        self._lock = threading.Lock()
        self._pool: DaemonPool | None = None

    def start(self) -> None:
        """Open the one-thread pool the computations run in (the app's lifespan calls it)."""
        self._pool = DaemonPool(1, "orbitcal-diagnosis")  # never holds the process at exit

    def shutdown(self) -> None:
        """Stop the pool; queued computations are cancelled, a running one is not waited for."""
        if self._pool is not None:
            self._pool.shutdown(timeout_s=0.0)
            self._pool = None

    def latest(self, key: DiagnosisKey) -> tuple[Hashable, Report] | None:
        """The latest report of ``key`` with its answer key, or None."""
        return self._reports.get(key)

    def store(self, key: DiagnosisKey, answer_key: Hashable, report: Report) -> None:
        """Keep ``report`` as the latest of ``key``, computed for ``answer_key``."""
        self._reports[key] = (answer_key, report)

    def forget(self, key: DiagnosisKey) -> None:
        """Drop the latest report of ``key`` (a running computation still stores its own)."""
        self._reports.pop(key, None)

    def computing(self, key: DiagnosisKey) -> bool:
        """Whether a computation of ``key`` is queued or running."""
        fut = self._running.get(key)
        return fut is not None and not fut.done()

    def future(self, key: DiagnosisKey, compute: Callable[[], Report]) -> Future[Report]:
        """The running computation of ``key``, or ``compute`` submitted as a new one."""
        if self._pool is None:
            raise RuntimeError("DiagnosisCache.start() was not called (the app's lifespan)")
        with self._lock:
            fut = self._running.get(key)
            if fut is None or fut.done():
                fut = self._pool.submit(compute)
                self._running[key] = fut
            return fut
