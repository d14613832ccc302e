"""A warm parent that imports the service once and forks real server/worker processes on demand.

Importing the service costs ~6 s on this machine (torch alone ~3 s), so restarting
``orbitcal serve`` twenty times would spend minutes in imports. This script imports everything
once, then reads one JSON spec per line on stdin and forks a child per spec; it answers the
child's pid on stdout. The children are ordinary processes running the real code paths
(``orbitcal.cli.main(["serve", ...])``, ``create_app`` under uvicorn, ``run_retrain``); tests kill
them with real signals. Children are reaped automatically (``SIGCHLD`` ignored).

Spec keys: ``kind`` (``cli`` | ``app`` | ``retrain``), ``log`` (file for the child's stdout and
stderr), ``env`` (extra environment), and per kind ``argv``; ``settings``, ``port``,
``fit_delay_s``; ``settings``, ``job_id``, ``fit_delay_s``; any kind: ``patch_fit_delay_s``
(replaces ``orbitcal.pipeline.fit_document`` by a slow one in the child).
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from typing import Any

import uvicorn

import orbitcal.cli
import service.app
import service.jobs
from orbitcal import pipeline
from service.settings import Settings
from service.storage import make_engine

_REAL_FIT = pipeline.fit_document


def _slow_fit(delay_s: float) -> Any:
    def fit(*args: Any, **kwargs: Any) -> dict[str, Any]:
        time.sleep(delay_s)  # the window in which the test kills the process
        return _REAL_FIT(*args, **kwargs)

    return fit


def _child(spec: dict[str, Any]) -> int:
    os.environ.update(spec.get("env", {}))
    kind = spec["kind"]
    if spec.get("patch_fit_delay_s"):  # e.g. for `orbitcal worker`, whose fit is not injectable
        pipeline.fit_document = _slow_fit(float(spec["patch_fit_delay_s"]))
    if kind == "cli":
        return orbitcal.cli.main(spec["argv"])
    settings = Settings(**spec.get("settings", {}))
    fit = _slow_fit(float(spec["fit_delay_s"])) if spec.get("fit_delay_s") else None
    if kind == "app":
        app = service.app.create_app(settings, fit=fit)
        uvicorn.run(app, host="127.0.0.1", port=int(spec["port"]), log_level="warning")
        return 0
    if kind == "retrain":
        engine = make_engine(settings.database_url)
        status = service.jobs.run_retrain(engine, settings, spec["job_id"], fit=fit)
        print(json.dumps({"status": status}), flush=True)
        return 0
    raise ValueError(f"unknown kind {kind!r}")


def main() -> None:
    orbitcal.cli.build_parser()  # imports every sub-command module once, here
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)
    print("ready", flush=True)
    for line in sys.stdin:
        if not line.strip():
            continue
        spec = json.loads(line)
        pid = os.fork()
        if pid == 0:
            signal.signal(signal.SIGCHLD, signal.SIG_DFL)
            fd = os.open(spec["log"], os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
            os.dup2(fd, 1)
            os.dup2(fd, 2)
            code = 1
            try:
                code = _child(spec)
            except BaseException as exc:  # report and exit; never return into the loop
                print(f"child failed: {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(code)
        print(pid, flush=True)


if __name__ == "__main__":
    main()
