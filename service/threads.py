"""Worker threads that never hold the process at exit: a bounded shutdown whatever they run.

``concurrent.futures.ThreadPoolExecutor`` joins its threads when the interpreter exits, so a
retraining or a diagnosis still running when the service stops kept the process alive until it
ended (``orbitcal demo --keep-serving`` was still running 120 s after Ctrl-C on a loaded
machine). :class:`DaemonPool` runs the same work on daemon threads: its shutdown waits at most
``timeout_s``, cancels what has not started by then, and lets the process go. Work
cut off that way is the work of a process that stopped: a retraining's transaction is never
committed and its job is failed as interrupted at the next start (``recover_interrupted``).
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, TypeVar

__all__ = ["DaemonPool"]

T = TypeVar("T")
_Item = tuple[Future[Any], Callable[..., Any], tuple[Any, ...], dict[str, Any]]


class DaemonPool:
    """``workers`` daemon threads running submitted calls in order (``ThreadPoolExecutor``'s
    ``submit`` and ``Future``)."""

    def __init__(self, workers: int, name: str) -> None:
        self._queue: queue.SimpleQueue[_Item | None] = queue.SimpleQueue()
        self._closed = False
        self._abandoned = False
        self._threads = [
            threading.Thread(target=self._work, name=f"{name}-{i}", daemon=True)
            for i in range(max(1, workers))
        ]
        for thread in self._threads:
            thread.start()

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future[T]:
        if self._closed:
            raise RuntimeError("the pool is shut down")
        future: Future[T] = Future()
        self._queue.put((future, fn, args, kwargs))
        return future

    def _work(self) -> None:
        while (item := self._queue.get()) is not None:
            future, fn, args, kwargs = item
            if self._abandoned or not future.set_running_or_notify_cancel():
                future.cancel()
                continue
            try:
                future.set_result(fn(*args, **kwargs))
            except BaseException as exc:  # handed to whoever waits on the future
                future.set_exception(exc)

    def _cancel_pending(self) -> None:
        while True:
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                return
            if item is not None:
                item[0].cancel()

    def shutdown(self, timeout_s: float = 0.0, *, cancel_pending: bool = True) -> bool:
        """Refuse new work; wait up to ``timeout_s`` for what runs (and, unless
        ``cancel_pending``, for what is queued); cancel what has not started by then.

        Returns whether every thread has ended (False: work still running is left behind).
        """
        self._closed = True
        if cancel_pending:
            self._cancel_pending()
        for _ in self._threads:
            self._queue.put(None)  # behind what is queued: each thread ends after it
        deadline = time.monotonic() + timeout_s
        for thread in self._threads:
            thread.join(max(0.0, deadline - time.monotonic()))
        self._abandoned = True  # a thread still busy cancels whatever it takes next
        self._cancel_pending()
        for _ in self._threads:
            self._queue.put(None)
        return not any(thread.is_alive() for thread in self._threads)
