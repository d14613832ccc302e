"""A full disk reached through a real limit is named as such (issue 44 item 11).

The limits are real: the process's ``RLIMIT_FSIZE`` (``ulimit -f``, which makes ``write`` fail
with EFBIG; SQLite reports it as a bare I/O error) in a child process, for the service and for
the command line. The service answers 507 Insufficient Storage naming the limit (never
"database connection lost"), stores nothing of the refused upload and keeps serving; the CLI
exits with one line naming the limit. ``PRAGMA max_page_count`` (a disk full as SQLite sees it)
is ``test_probes_edge.py::test_a_full_disk_is_507_saying_so_and_the_log_says_so``.
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
from pathlib import Path

from reliability_helpers import REPO

_SERVICE = r"""
import json, os, resource, sqlite3, sys
sys.path[:0] = [{repo!r}, {repo!r} + "/tests/reliability", {repo!r} + "/tests"]
from fastapi.testclient import TestClient
from pydantic import SecretStr
from reliability_helpers import SWARM_A_TLE, T0_UTC_S, csv_batch
from service.app import create_app
from service.settings import Settings
db = {db!r}
settings = Settings(database_url=f"sqlite:///{{db}}", admin_key=SecretStr("k"),
                    rate_limit_per_s=0, scheduler=False)
H = {{"X-API-Key": "k"}}
with TestClient(create_app(settings)) as http:
    http.post("/v1/spacecraft", json={{"id": "s1", "tle": SWARM_A_TLE}}, headers=H)
    resource.setrlimit(resource.RLIMIT_FSIZE, (os.path.getsize(db) + 2**20, resource.RLIM_INFINITY))
    statuses = []
    for i in range(60):
        r = http.post("/v1/spacecraft/s1/telemetry", content=csv_batch(T0_UTC_S + i * 10_000, 2000),
                      headers={{**H, "content-type": "text/csv"}})
        statuses.append(r.status_code)
        if r.status_code != 200:
            break
    full = r
    read = http.get("/v1/spacecraft/s1", headers=H).status_code
    resource.setrlimit(resource.RLIMIT_FSIZE, (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
    stored = sqlite3.connect(db).execute("SELECT count(*) FROM samples").fetchone()[0]
    print(json.dumps({{"statuses": statuses, "status": full.status_code, "body": full.json(),
                      "read": read, "stored": stored}}))
"""


def test_a_file_size_limit_under_the_service_is_507_naming_it(tmp_path: Path) -> None:
    script = _SERVICE.format(repo=str(REPO), db=str(tmp_path / "fs.sqlite"))
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=600, cwd=tmp_path
    )
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
    assert lines, out.stderr[-3000:]
    a = json.loads(lines[-1])
    assert a["status"] == 507, a
    assert a["statuses"][:-1] and set(a["statuses"][:-1]) == {200}, a  # the limit was reached
    detail = a["body"]["detail"]
    assert "file-size limit" in detail and "nothing was stored" in detail, detail
    assert a["stored"] == 2000 * (len(a["statuses"]) - 1), a  # the refused upload left nothing
    assert a["read"] == 200
    assert '"resource": "file size limit"' in out.stderr, out.stderr[-2000:]
    assert "connection lost" not in out.stderr + json.dumps(a)


def _limit_output_files() -> None:
    resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, resource.RLIM_INFINITY))


def test_a_file_size_limit_under_the_cli_is_one_line_naming_it(tmp_path: Path) -> None:
    argv = [
        sys.executable, "-m", "orbitcal", "simulate",
        "--tle", str(REPO / "orbitcal" / "data" / "swarm_iss_real_tles.tle"), "--norad", "39452",
        "--allow-stale-elements", "--start", "2022-08-01T00:00:00Z", "--duration-s", "20000",
        "--cadence-s", "1", "--sensor", "ideal", "--out", str(tmp_path / "sim"),
    ]  # fmt: skip
    proc = subprocess.run(
        argv,
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
        preexec_fn=_limit_output_files,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
    )
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr[-2000:]
    assert lines[0].startswith("orbitcal simulate: cannot write"), lines
    assert "file-size limit (ulimit -f)" in lines[0], lines
