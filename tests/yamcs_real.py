"""A real Yamcs 5.12.8 for the tests (issue 45): the jars of ``fprime-yamcs-bundle`` (the ``test``
extra) run by Java 17 on a free loopback port, and a small REST client.

Java is ``$JAVA_HOME/bin/java`` or ``java`` on ``PATH`` (``.ci/run`` installs Debian's
``openjdk-17-jre-headless`` where there is none). A missing Java or bundle **fails** the test
that asks for the server; it never skips.
"""

from __future__ import annotations

import datetime
import json
import os
import shutil
import socket
import subprocess
import time
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import httpx
import pytest

#: Seconds a start may take on a loaded 2-core machine before the fixture fails.
START_TIMEOUT_S = 180.0
#: Seconds a value may take to appear after a batchSet (processing is asynchronous).
VALUE_TIMEOUT_S = 30.0


def java() -> str:
    """The ``java`` executable, or a loud failure."""
    home = os.environ.get("JAVA_HOME")
    found = str(Path(home) / "bin" / "java") if home else shutil.which("java")
    if not found or not Path(found).exists():
        pytest.fail(
            "the Yamcs tests need Java 17 (java on PATH or JAVA_HOME); .ci/run installs Debian "
            "openjdk-17-jre-headless",
            pytrace=False,
        )
    return found


def yamcs_lib() -> Path:
    try:
        import fprime_yamcs_bundle
    except ImportError:
        pytest.fail(
            "the Yamcs tests need fprime-yamcs-bundle==5.12.8.0 (pip install -e '.[test]')",
            pytrace=False,
        )
    return Path(fprime_yamcs_bundle.LIB_DIR)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class YamcsServer:
    """``java -cp LIB/* org.yamcs.YamcsServer --etc-dir etc`` in ``folder`` (the folder layout
    of the ``yamcs-instance`` export), on ``127.0.0.1:port``."""

    def __init__(self, folder: Path, *, persist: bool = False) -> None:
        self.folder = folder
        self.port = free_port()
        self.udp_port = free_port()
        self.persist = persist
        self.url = f"http://127.0.0.1:{self.port}"
        self.proc: subprocess.Popen[bytes] | None = None
        self.log = folder / "yamcs-console.log"
        self.start_s: list[float] = []

    def command(self) -> list[str]:
        return [
            java(),
            f"-Dorbitcal.yamcs.port={self.port}",
            f"-Dorbitcal.yamcs.persist={'true' if self.persist else 'false'}",
            f"-Dorbitcal.yamcs.udp={self.udp_port}",
            "-Xshare:auto",
            "-cp",
            f"{yamcs_lib()}/*",
            "org.yamcs.YamcsServer",
            "--etc-dir",
            "etc",
            "--no-color",
        ]

    def start(self, instances: Iterable[str]) -> YamcsServer:
        t0 = time.monotonic()
        with open(self.log, "ab") as log:
            self.proc = subprocess.Popen(
                self.command(), cwd=self.folder, stdout=log, stderr=subprocess.STDOUT
            )
        wanted = set(instances)
        while True:
            if self.proc.poll() is not None:
                pytest.fail(f"Yamcs exited with {self.proc.returncode}:\n{self.log_tail()}")
            try:
                got = httpx.get(f"{self.url}/api/instances", timeout=2).json()
                running = {i["name"] for i in got.get("instances", []) if i["state"] == "RUNNING"}
                if wanted <= running:
                    break
            except (httpx.HTTPError, ValueError):
                pass
            if time.monotonic() - t0 > START_TIMEOUT_S:
                self.stop()
                pytest.fail(f"Yamcs did not start in {START_TIMEOUT_S} s:\n{self.log_tail()}")
            time.sleep(0.2)
        self.start_s.append(time.monotonic() - t0)
        return self

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc = None

    def log_tail(self, n: int = 60) -> str:
        return "\n".join(self.log.read_text(errors="replace").splitlines()[-n:])

    def warnings(self) -> list[str]:
        """The WARNING/SEVERE lines of the log and the sections Yamcs skipped."""
        return [
            line
            for line in self.log.read_text(errors="replace").splitlines()
            if " WARNING " in line or " SEVERE " in line or "skipped" in line
        ]

    def processor(self, instance: str) -> Processor:
        return Processor(self.url, instance)


def _t(iso: str) -> datetime.datetime:
    return datetime.datetime.fromisoformat(iso)


def _eng(pv: dict[str, Any]) -> Any:
    eng = pv.get("engValue") or {}
    for key in ("doubleValue", "uint32Value", "sint64Value", "stringValue", "floatValue"):
        if key in eng:
            return eng[key]
    return None


def value_json(v: float | int | str) -> dict[str, Any]:
    if isinstance(v, str):
        return {"type": "STRING", "stringValue": v}
    if isinstance(v, int):
        return {"type": "UINT32", "uint32Value": v}
    return {"type": "DOUBLE", "doubleValue": float(v)}


class Processor:
    """The realtime processor of one instance, over Yamcs's REST API."""

    def __init__(self, url: str, instance: str) -> None:
        self.url, self.instance = url, instance
        self.base = f"{url}/api/processors/{instance}/realtime"
        self.client = httpx.Client(timeout=30)

    def set(self, values: Mapping[str, float | int | str]) -> httpx.Response:
        """``parameters:batchSet`` of qualified names; returns the answer (raises on none)."""
        body = {"request": [{"id": {"name": n}, "value": value_json(v)} for n, v in values.items()]}
        return self.client.post(f"{self.base}/parameters:batchSet", json=body)

    def get(self, names: Iterable[str]) -> dict[str, dict[str, Any]]:
        """``parameters:batchGet`` from the cache: name → parameter value (absent: none yet)."""
        ids = [{"name": n} for n in names]
        answer = self.client.post(
            f"{self.base}/parameters:batchGet", json={"id": ids, "fromCache": True}
        )
        answer.raise_for_status()
        return {pv["id"]["name"]: pv for pv in answer.json().get("value", [])}

    def values(self, names: Iterable[str]) -> dict[str, Any]:
        return {n: _eng(pv) for n, pv in self.get(names).items()}

    def wait_for(
        self, expected: dict[str, float], also: list[str], outputs: Sequence[str] = ()
    ) -> dict[str, dict[str, Any]]:
        """Poll until every name of ``expected`` holds its value and every name of ``outputs``
        has a value acquired at or after it; return those and ``also``."""
        t0 = time.monotonic()
        first = next(iter(expected))
        while True:
            got = self.get([*expected, *also, *outputs])
            if all(_eng(got.get(n, {})) == v for n, v in expected.items()) and all(
                o in got and _t(got[o]["acquisitionTime"]) >= _t(got[first]["acquisitionTime"])
                for o in outputs
            ):
                return got
            if time.monotonic() - t0 > VALUE_TIMEOUT_S:
                raise AssertionError(f"Yamcs never showed {expected}: {json.dumps(got)[:2000]}")
            time.sleep(0.02)

    def algorithm_status(self, qualified: str) -> dict[str, Any]:
        answer = self.client.get(f"{self.base}/algorithms{qualified}/status")
        answer.raise_for_status()
        out: dict[str, Any] = answer.json()
        return out

    def events(self) -> list[dict[str, Any]]:
        """Events of the instance (the ``EventRecorder`` archive), oldest first."""
        answer = self.client.get(
            f"{self.url}/api/archive/{self.instance}/events", params={"limit": 1000}
        )
        answer.raise_for_status()
        return list(reversed(answer.json().get("events", [])))


def eng(pv: dict[str, Any] | None) -> Any:
    """The engineering value of a parameter value (``None``: absent)."""
    return None if pv is None else _eng(pv)


# --- the suite's server: every export route in one instance, from docs/yamcs.md's worked example --

DOC = Path(__file__).resolve().parents[1] / "docs" / "yamcs.md"
METHODS = ("linear", "linear-hk", "lmbp", "lmbp-hk")
#: The housekeeping columns of the shared world and the mission MDB's names for them.
MISSION_HK = {
    "temperature": "/MYSAT/MAG_TEMP",
    "mtq_x": "/MYSAT/MTQ_X",
    "mtq_y": "/MYSAT/MTQ_Y",
    "mtq_z": "/MYSAT/MTQ_Z",
    "hk_sa_current_a": "/MYSAT/SA_CURRENT",
}
CUSTOM_HK = {
    "temperature": "TMAG",
    "mtq_x": "MTQ1",
    "mtq_y": "MTQ2",
    "mtq_z": "MTQ3",
    "hk_sa_current_a": "SAI",
}


def doc_block(lang: str) -> str:
    """The one fenced block of docs/yamcs.md in ``lang``."""
    import re

    (block,) = re.findall(rf"```{lang}\n(.*?)```", DOC.read_text(), flags=re.S)
    return block


def system_name(method: str, names: str) -> str:
    return f"C_{method.replace('-', '_').upper()}_{names[0].upper()}"


def export_options(method: str, names: str, hk_columns: tuple[str, ...]) -> Any:
    """ExportOptions of one (method, names) cell: ``default``, ``custom`` (local inputs) or
    ``qualified`` (the mission MDB's parameters), or ``telemetered`` (default names)."""
    from orbitcal.export import ExportOptions

    sys_ = system_name(method, names)
    if names == "custom":
        return ExportOptions(
            format="xtce",
            space_system=sys_,
            raw_names=("BX", "BY", "BZ"),
            cal_names=("CX", "CY", "CZ"),
            hk_names={c: CUSTOM_HK[c] for c in hk_columns},
        )
    if names == "qualified":
        return ExportOptions(
            format="xtce",
            space_system=sys_,
            raw_names=("/MYSAT/MAG_X", "/MYSAT/MAG_Y", "/MYSAT/MAG_Z"),
            hk_names={c: MISSION_HK[c] for c in hk_columns},
            yamcs_inputs="qualified",
        )
    inputs = "telemetered" if names == "telemetered" else "local"
    return ExportOptions(format="xtce", space_system=sys_, yamcs_inputs=inputs)


def write_suite_folder(
    folder: Path,
    documents: dict[str, dict[str, Any]],
    cells: list[tuple[str, str]],
    instance: str = "suite",
) -> dict[str, str]:
    """A Yamcs folder: one ``yamcs-instance`` export's server and processor files, the instance
    file of docs/yamcs.md's mission example listing the mission MDB and one calibration MDB per
    cell; returns cell → MDB file name."""
    from orbitcal.export import ExportOptions, calibration_form, export

    base = export(
        documents[METHODS[0]], ExportOptions(format="yamcs-instance", yamcs_instance=instance)
    )
    assert base.files is not None
    for name in ("etc/yamcs.yaml", "etc/processor.yaml"):
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_bytes(base.files[name])
    (folder / "mdb").mkdir(exist_ok=True)
    (folder / "mdb" / "MYSAT.xml").write_text(doc_block("xml"))
    files = {}
    for method, names in cells:
        doc = documents[method]
        opts = export_options(method, names, calibration_form(doc).hk_names)
        xml = export(doc, opts).content
        assert xml is not None
        files[f"{method}/{names}"] = f"mdb/{opts.space_system}.xml"
        (folder / files[f"{method}/{names}"]).write_bytes(xml)
    mdb = "\n".join(f"  - type: xtce\n    spec: {f}" for f in ["mdb/MYSAT.xml", *files.values()])
    yaml = doc_block("yaml").replace("port: 10015", "port: ${orbitcal.yamcs.udp:10015}")
    head, _, tail = yaml.partition("mdb:\n")
    _, _, tail = tail.partition("streamConfig:")
    (folder / "etc" / f"yamcs.{instance}.yaml").write_text(
        f"{head}mdb:\n{mdb}\nstreamConfig:{tail}"
    )
    text = (folder / "etc" / "yamcs.yaml").read_text().replace("  - magcal", f"  - {instance}")
    (folder / "etc" / "yamcs.yaml").write_text(text)
    return files
