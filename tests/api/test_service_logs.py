"""Service log lines are JSON, APScheduler's included; a skipped scheduler tick is no warning."""

from __future__ import annotations

import io
import json
import logging

from service.logs import JsonFormatter, configure_logging


def _stream_of(name: str) -> tuple[logging.StreamHandler, io.StringIO]:  # type: ignore[type-arg]
    handler = next(
        h
        for h in logging.getLogger(name).handlers
        if isinstance(h, logging.StreamHandler) and isinstance(h.formatter, JsonFormatter)
    )
    buf = io.StringIO()
    return handler, buf


def test_apscheduler_lines_are_json_and_skipped_ticks_are_left_out() -> None:
    configure_logging("INFO")
    handler, buf = _stream_of("apscheduler")
    previous = handler.setStream(buf)
    try:
        log = logging.getLogger("apscheduler.executors.default")
        log.warning(
            'Execution of job "FleetScheduler.tick (trigger: interval[0:00:00.500000], next run '
            'at: 2026-11-25 23:00:00 UTC)" skipped: maximum number of running instances '
            "reached (1)"
        )
        log.info('Running job "FleetScheduler.tick" (scheduled at 2026-11-25 23:00:00)')
        log.error("Job raised an exception")
    finally:
        handler.setStream(previous)  # type: ignore[arg-type]
    lines = buf.getvalue().splitlines()
    assert len(lines) == 1, lines  # not the skipped tick, not the per-tick INFO line
    record = json.loads(lines[0])
    assert record["logger"] == "apscheduler.executors.default"
    assert record["level"] == "ERROR" and record["msg"] == "Job raised an exception"
    assert logging.getLogger("apscheduler").propagate is False  # no plain-text copy on stderr
