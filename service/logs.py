"""Structured (JSON lines) logging for the service; never logs keys, bodies or URLs with secrets."""

from __future__ import annotations

import json
import logging
import re
import time
from typing import Any

__all__ = ["JsonFormatter", "configure_logging", "redact_url"]

_STANDARD = set(vars(logging.LogRecord("", 0, "", 0, "", (), None))) | {"message", "asctime"}


def redact_url(url: str) -> str:
    """Database/broker URL with any password replaced by ``***``."""
    return re.sub(r"(://[^:/@]+:)[^@]*@", r"\1***@", url)


class JsonFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        out: dict[str, Any] = {
            "ts": time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(record.created))
            + f".{int(record.msecs):03d}Z",
            "level": record.levelname,
            "logger": record.name,
            "msg": record.getMessage(),
        }
        for k, v in vars(record).items():
            if k not in _STANDARD and not k.startswith("_"):
                out[k] = v
        if record.exc_info:
            out["exc"] = self.formatException(record.exc_info)
        return json.dumps(out, default=str)


def _level(level: str | int) -> int:
    return level if isinstance(level, int) else logging.getLevelName(level.upper())


class SkippedTickFilter(logging.Filter):
    """Leaves out APScheduler's "skipped: maximum number of running instances reached": a
    scheduler tick that finds the previous one still running is skipped on purpose
    (``max_instances=1, coalesce=True`` in service/scheduler.py), not a fault to warn about."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "maximum number of running instances reached" not in record.getMessage()


def configure_logging(level: str = "INFO") -> None:
    """JSON lines on stderr for the ``orbitcal`` loggers and APScheduler's (idempotent)."""
    for name in ("orbitcal", "apscheduler"):
        logger = logging.getLogger(name)
        # APScheduler says "running job ..." at INFO on every tick: its warnings only
        logger.setLevel(level if name == "orbitcal" else max(logging.WARNING, _level(level)))
        if not any(isinstance(h.formatter, JsonFormatter) for h in logger.handlers):
            handler = logging.StreamHandler()
            handler.setFormatter(JsonFormatter())
            if name == "apscheduler":
                handler.addFilter(SkippedTickFilter())
            logger.addHandler(handler)
            logger.propagate = False
