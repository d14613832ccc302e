"""What README.md and docs/*.md show runs: no snippet can drift from the code.

* The README's first session (every ``orbitcal`` line of it, in order, in a temporary directory
  standing in for ``/tmp``), then its notebook block and its HTTP block (curl against
  ``orbitcal serve`` on a free loopback port) on the files the session wrote.
* Every command synopsis in README and docs (``orbitcal CMD [--flag ...]``) names a command and
  flags the parser has.
* docs/ccsds.md's Python block against a live service; docs/service.md's settings table against
  ``service.settings.Settings`` (every setting, its default); docs/tutorial.md runs in
  tests/test_tutorial.py.

The two lines of the first session that take minutes (``orbitcal demo --keep-serving`` serves
until Ctrl-C; ``orbitcal bench diagnose --cases 240``) are parsed here and run by
tests/api/test_service_demo.py and ``test_reduced_blind_benchmark`` (tests/test_diagnose.py).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import socket
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))
#: Lines of the first session run elsewhere (see the module docstring), parsed only here.
LONG_LINES = ("orbitcal demo --keep-serving", "orbitcal bench diagnose")


def blocks(path: Path, lang: str) -> list[str]:
    """The fenced code blocks of ``path`` in language ``lang`` ("" for unlabelled ones)."""
    found: list[str] = []
    current: list[str] | None = None
    current_lang = ""
    for line in path.read_text().splitlines():
        if line.startswith("```"):
            if current is None:
                current, current_lang = [], line[3:].strip()
            else:
                if current_lang == lang:
                    found.append("\n".join(current) + "\n")
                current = None
        elif current is not None:
            current.append(line)
    return found


def commands(block: str) -> list[str]:
    """Shell lines of a block with continuations joined and comments dropped."""
    joined = re.sub(r"\\\n\s*", " ", block)
    out = []
    for line in joined.splitlines():
        line = line.split("  #")[0].strip()
        if line and not line.startswith("#"):
            out.append(line)
    return out


def _section(name: str) -> str:
    text = README.read_text()
    start = text.index(f"## {name}")
    end = text.find("\n## ", start + 1)
    return text[start : end if end > 0 else None]


def _first_session() -> list[str]:
    (block,) = re.findall(r"```bash\n(.*?)```", _section("A first session"), flags=re.S)
    return commands(block)


# --- synopses: every documented command and flag exists ------------------------------------------


def _synopsis_lines() -> list[tuple[str, str]]:
    found = []
    for path in [README, *DOCS]:
        if path.name == "CONTRACT.md":
            continue  # the binding copy of the shared contract, checked by tests/contract_doc.py
        for block in blocks(path, "") + blocks(path, "bash"):
            for line in commands(block):
                for part in line.split(";"):
                    part = part.strip()
                    if part.startswith("orbitcal "):
                        found.append((path.name, part))
    return found


def test_every_documented_command_and_flag_exists() -> None:
    import argparse

    from orbitcal.cli import build_parser

    parser = build_parser()
    (choices,) = [a.choices for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    lines = _synopsis_lines()
    assert len(lines) >= 20, lines
    for where, line in lines:
        for part in re.split(r"\s{3,}", line):  # "orbitcal simulate ...     orbitcal demo"
            words = part.split()
            if len(words) < 2 or words[0] != "orbitcal" or words[1].startswith("-"):
                continue
            assert words[1] in choices, (where, part)
            sub = choices[words[1]]
            nested = [a for a in sub._actions if isinstance(a, argparse._SubParsersAction)]
            if nested and len(words) > 2 and words[2] in nested[0].choices:
                sub = nested[0].choices[words[2]]  # orbitcal bench diagnose, orbitcal data status
            options = {o for a in sub._actions for o in a.option_strings}
            for flag in re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", part):
                assert flag in options, (where, part, flag)


def test_the_long_lines_of_the_first_session_parse() -> None:
    from orbitcal.cli import build_parser

    parser = build_parser()
    long_lines = [c for c in _first_session() if c.startswith(LONG_LINES)]
    assert len(long_lines) == 2
    for line in long_lines:
        args = parser.parse_args(shlex.split(line)[1:])
        assert callable(args.func)


# --- the first session, the notebook block and the HTTP block, verbatim --------------------------


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _in(tmp: Path, text: str) -> str:
    """``text`` with ``/tmp/`` standing for the test's directory."""
    return text.replace("/tmp/", f"{tmp}/")


@pytest.mark.slow  # minutes: simulate, calibrate (lmbp-hk), diagnose, reproduce, serve, retrain
@pytest.mark.timeout(2400)
def test_readme_first_session_notebook_and_http_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("ORBITCAL_")}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    bindir = Path(sys.executable).parent
    env["PATH"] = f"{bindir}{os.pathsep}{env['PATH']}"
    ran = []
    for line in _first_session():
        if line.startswith(LONG_LINES):
            continue
        proc = subprocess.run(
            _in(tmp_path, line), shell=True, cwd=ROOT, env=env, capture_output=True, text=True,
            timeout=600,
        )  # fmt: skip
        assert proc.returncode == 0, (line, proc.stdout[-2000:], proc.stderr[-2000:])
        ran.append((line, proc.stdout))
    assert len(ran) == 8
    # the exports and the ingest lines wrote what they say
    assert "http://www.omg.org/spec/XTCE/20180204" in (tmp_path / "mag.xml").read_text()
    import pandas as pd

    table = pd.read_csv(tmp_path / "gracefo.csv")
    assert len(table) == 100 and {"time", "b_x", "q_w", "r_x"} <= set(table.columns)
    # the comments' claims: a 0.5 s time-tag error, named by the diagnosis
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["verdict"] == "time_offset"
    dt = next(e for e in report["effects"] if e["name"] == "time_offset")["params"]["dt_s"]
    assert dt == pytest.approx(-0.5, abs=0.05)
    diagnose_out = next(out for line, out in ran if line.startswith("orbitcal diagnose"))
    assert f"HTML page to {tmp_path}/report.html" in diagnose_out  # diagnose --html says where
    assert (tmp_path / "report.html").read_text().startswith("<!doctype html>")

    # the notebook block, on the files the session wrote
    (code,) = blocks(README, "python")
    namespace: dict[str, Any] = {"__name__": "readme"}
    monkeypatch.chdir(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        exec(compile(_in(tmp_path, code), "README.md[notebook]", "exec"), namespace)
    assert namespace["report"]["verdict"] == "time_offset"
    assert namespace["run"].document["method"] == "linear"

    # the HTTP block: orbitcal serve, register, upload, retrain, fetch
    (http,) = re.findall(r"```bash\n(.*?)```", _section("Over HTTP"), flags=re.S)
    port = _free_port()
    script = _in(tmp_path, http).replace("8765", str(port))
    proc = subprocess.run(
        ["bash", "-euo", "pipefail", "-c", script], cwd=tmp_path, env=env, capture_output=True,
        text=True, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, (proc.stdout[-2000:], proc.stderr[-3000:])
    assert '"accepted":2160' in proc.stdout.replace(" ", ""), proc.stdout
    doc = json.loads((tmp_path / "iss-cal.json").read_text())
    assert doc["spacecraft"] == "iss" and doc["version"] == 1
    assert doc["metrics"]["holdout_rms_nt"] > 0


# --- docs/ccsds.md and docs/service.md ------------------------------------------------------------


def test_ccsds_doc_block_uploads_packets(tmp_path: Path) -> None:
    import numpy as np

    sys.path.insert(0, str(ROOT / "tests" / "api"))
    from service_helpers import ADMIN_KEY, live_server, sqlite_settings
    from service_worlds import SWARM_A_TLE, T0_UTC_S

    (code,) = blocks(ROOT / "docs" / "ccsds.md", "python")
    n = 30
    rng = np.random.default_rng(0)
    q = rng.normal(size=(n, 4))
    with live_server(sqlite_settings(tmp_path)) as server, server.client() as c:
        assert c.post("/v1/spacecraft", json={"id": "sat-1", "tle": SWARM_A_TLE}).is_success
        namespace: dict[str, Any] = {
            "__name__": "ccsds_doc",
            "httpx": __import__("httpx"),
            "url": server.url,
            "key": ADMIN_KEY,
            "t_utc_s": T0_UTC_S + 10.0 * np.arange(n),
            "b_raw_nt": rng.normal(scale=2e4, size=(n, 3)),
            "q_wxyz": q / np.linalg.norm(q, axis=1, keepdims=True),
            "temp": 20.0 + rng.normal(size=n),
        }
        exec(compile(code, "docs/ccsds.md", "exec"), namespace)
        assert c.get("/v1/spacecraft/sat-1").json()["samples"] == n


def _settings_table() -> dict[str, str]:
    text = (ROOT / "docs" / "service.md").read_text()
    rows: dict[str, str] = {}
    for line in text.splitlines():
        m = re.match(r"^\| (`[A-Z_]+`(?:, `[A-Z_]+`)*) \| ([^|]*) \|", line)
        if m:
            names = re.findall(r"`([A-Z_]+)`", m.group(1))
            values = [v.strip().strip("`") for v in m.group(2).split(", ")]
            if len(values) != len(names):
                values = [m.group(2).strip().strip("`")] * len(names)
            rows.update(zip(names, values, strict=True))
    return rows


def _same(documented: str, default: Any) -> bool:
    if default is None:
        return documented in ("off", "–", "none")
    if isinstance(default, bool):
        return documented == str(default).lower()
    if isinstance(default, int | float):
        units = {"KiB": 2**10, "MiB": 2**20}
        m = re.fullmatch(r"([\d.]+)(?: (\w+))?", documented)
        if m is None:
            return False
        return float(m.group(1)) * units.get(m.group(2) or "", 1) == float(default)
    return documented == str(default) or (default == "" and documented == "empty")


def test_service_settings_table_lists_every_setting_with_its_default() -> None:
    from service.settings import Settings

    table = _settings_table()
    for name, field in Settings.model_fields.items():
        env = name.upper()
        assert env in table, f"docs/service.md does not list ORBITCAL_{env}"
        if field.default_factory is not None:
            continue  # computed (DATABASE_URL: a file in the working directory)
        default = field.default
        if hasattr(default, "get_secret_value"):
            default = default.get_secret_value()
        assert _same(table[env], default), (env, table[env], default)


# --- docs/yamcs.md: the operator's recipe against a real Yamcs 5.12.8 (issue 45) ---------------


def _yamcs_calibrations(tmp: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """``/tmp/cal.json`` (lmbp-hk on the shared world), ``/tmp/cal-v2.json`` (its next version)."""
    sys.path.insert(0, str(ROOT / "tests"))
    from export_worlds import fitted
    from shared_worlds import swarm_a_temperature_world

    doc = fitted(swarm_a_temperature_world(), "lmbp-hk").document
    doc2 = json.loads(json.dumps(doc))
    doc2["version"] = 2
    doc2["model"]["weights"]["b2"] = [v + 0.01 for v in doc2["model"]["weights"]["b2"]]
    (tmp / "cal.json").write_text(json.dumps(doc))
    (tmp / "cal-v2.json").write_text(json.dumps(doc2))
    return doc, doc2


def _run_until(script: str, env: dict[str, str], done: Any, what: str) -> str:
    """Run a bash block until ``done(stdout)`` (Yamcs processes a set asynchronously: an
    operator reads again), at most 60 s."""
    import time

    t0 = time.monotonic()
    while True:
        proc = subprocess.run(
            ["bash", "-euo", "pipefail", "-c", script], env=env, capture_output=True, text=True,
            timeout=300,
        )  # fmt: skip
        assert proc.returncode == 0, (what, proc.stdout[-2000:], proc.stderr[-2000:])
        if done(proc.stdout):
            return proc.stdout
        assert time.monotonic() - t0 < 60, (what, proc.stdout[-3000:])
        time.sleep(0.2)


def _batch_values(text: str) -> dict[str, Any]:
    """name → engineering value of the batchGet answers in ``text`` (last answer wins)."""
    out: dict[str, Any] = {}
    decoder = json.JSONDecoder()
    i = 0
    while (i := text.find("{", i)) >= 0:
        try:
            obj, end = decoder.raw_decode(text, i)
        except ValueError:
            i += 1
            continue
        for pv in obj.get("value", []) if isinstance(obj, dict) else []:
            eng = pv.get("engValue", {})
            out[pv["id"]["name"]] = next(v for k, v in eng.items() if k != "type")
        i = end
    return out


@pytest.mark.yamcs
@pytest.mark.slow  # two starts of Yamcs, an export and a push: ~40 s on this machine
def test_yamcs_doc_runs(tmp_path: Path) -> None:
    import numpy as np

    sys.path.insert(0, str(ROOT / "tests"))
    from yamcs_real import YamcsServer, free_port

    from orbitcal.export import evaluate_document

    doc, doc2 = _yamcs_calibrations(tmp_path)
    text = (ROOT / "docs" / "yamcs.md").read_text()
    port, udp = free_port(), free_port()
    bash = [
        _in(tmp_path, b).replace("8090", str(port)).replace("10015", str(udp))
        for b in blocks(ROOT / "docs" / "yamcs.md", "bash")
    ]
    assert len(bash) == 7, len(bash)
    env = {k: v for k, v in os.environ.items() if not k.startswith("ORBITCAL_")}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env['PATH']}"
    raw2, hk = [21001.5, -4001.25, 30501.0], [[21.5, 2.0, -1.5, 0.5, 3.0]]
    want = evaluate_document(doc, np.array([raw2]), np.array(hk))[0]
    want2 = evaluate_document(doc2, np.array([[21002.5, -4001.25, 30501.0]]), np.array(hk))[0]
    cal = ["/MAGCAL/MAG_X_CAL", "/MAGCAL/MAG_Y_CAL", "/MAGCAL/MAG_Z_CAL"]

    def start(line: str, instance: str) -> Any:
        """The documented start line, run in the background with the test's port."""
        assert line.endswith("&") and "org.yamcs.YamcsServer --etc-dir etc" in line
        folder = Path(line.split("&&")[0].removeprefix("cd ").strip())
        server = YamcsServer(folder)
        server.port, server.udp_port, server.url = port, udp, f"http://127.0.0.1:{port}"
        command = line.rstrip("&").replace(
            "java ", f"java -Dorbitcal.yamcs.port={port} -Dorbitcal.yamcs.udp={udp} ", 1
        )
        server.command = lambda: ["bash", "-c", f"exec {command.split('&&', 1)[1].strip()}"]  # type: ignore[method-assign]
        return server.start([instance])

    # 1. a ready instance
    export_line, start_line = commands(bash[0])
    out = subprocess.run(
        export_line, shell=True, env=env, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stderr
    server = start(start_line, "magcal")
    try:
        status = _run_until(bash[1], env, lambda s: "errorCount" in s, "raw before housekeeping")
        answer = json.loads(status[status.rindex("{\n") :])  # the status, after the set's "{}"
        assert answer.get("errorCount", 0) == 0 and int(answer.get("runCount", 0)) == 0, answer
        got = _run_until(
            bash[2], env, lambda s: _batch_values(s).get("/MAGCAL/MAG_X_CAL") is not None
            and abs(_batch_values(s)["/MAGCAL/MAG_X_CAL"] - want[0]) < 1e-9, "replayed row",
        )  # fmt: skip
        values = _batch_values(got)
        assert np.max(np.abs(np.array([values[c] for c in cal]) - want)) < 1e-9
        assert values["/MAGCAL/MAGCAL_VERSION"] == 1
        # 2. a push of version 2
        pushed = _run_until(bash[3], env, lambda s: True, "push")
        n = re.search(r"set (\d+) parameters on http://127\.0\.0\.1:\d+ \(magcal/realtime\); "
                      r"previous version 1", pushed)  # fmt: skip
        assert n is not None, pushed
        assert f"set {n.group(1)} parameters on http://127.0.0.1:8090" in text
        after = _run_until(
            bash[4], env, lambda s: "computing with coefficients of version 2" in s
            and _batch_values(s).get("/MAGCAL/MAGCAL_VERSION") == 2
            and abs(_batch_values(s)["/MAGCAL/MAG_X_CAL"] - want2[0]) < 1e-9, "after the push",
        )  # fmt: skip
        values = _batch_values(after)
        assert np.max(np.abs(np.array([values[c] for c in cal]) - want2)) < 1e-9
        assert "holds version 1, which every restart serves again" in after
    finally:
        server.stop()

    # 3. the mission route: export, the mission MDB and the instance file, packets over UDP
    (mission_export,) = commands(bash[5])
    out = subprocess.run(
        mission_export, shell=True, env=env, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stderr
    mission = tmp_path / "mission"
    (mission / "mdb" / "MYSAT.xml").write_text(blocks(ROOT / "docs" / "yamcs.md", "xml")[0])
    (yaml_block,) = blocks(ROOT / "docs" / "yamcs.md", "yaml")
    (mission / "etc" / "yamcs.mysat.yaml").write_text(yaml_block.replace("10015", str(udp)))
    server = start(start_line.replace(str(tmp_path / "magcal-yamcs"), str(mission)), "mysat")
    try:
        (code,) = blocks(ROOT / "docs" / "yamcs.md", "python")
        exec(compile(code.replace("10015", str(udp)), "docs/yamcs.md[udp]", "exec"), {})
        got = _run_until(
            bash[6], env, lambda s: _batch_values(s).get("/MYSAT/MAG_X") == raw2[0]
            and _batch_values(s).get("/MAGCAL/MAG_X_CAL") is not None, "mission packets",
        )  # fmt: skip
        values = _batch_values(got)
        assert np.max(np.abs(np.array([values[c] for c in cal]) - want)) < 1e-9
    finally:
        server.stop()
