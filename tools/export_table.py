"""Regenerate ``docs/export/results.md``: every export of a ``linear-hk`` and an ``lmbp-hk``
calibration, evaluated by its consumer on held-out samples, beside ``orbitcal apply`` (issue 21).

Runs the commands it prints (``orbitcal simulate``, ``truth``, ``calibrate``, ``apply``,
``export``) in a scratch directory, then drives each consumer as the tool does
(``tests/export_consumers.py``: node with Yamcs's binding, the MathAlgorithm postfix, openc3's
``PacketConfig`` and ``PolynomialConversion``, ``cc``; ``yamcs-push`` against the loopback
stand-in of ``tests/yamcs_standin.py``). Needs node, cc, xmlschema and openc3 (see
``docs/export/README.md``).

    python tools/export_table.py [--workdir DIR] [--out docs/export/results.md]
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the consumer drivers the tests use

TLE = "orbitcal/data/swarm_iss_real_tles.tle"
SIMULATE = [
    "simulate", "--tle", TLE, "--norad", "39452", "--start", "2023-11-19T14:00:00Z",
    "--duration-s", "20000", "--cadence-s", "10", "--attitude", "tumbling",
    "--effect", "temperature", "--effect", "magnetorquer", "--seed", "7",
    "--format", "parquet", "--out", "world",
]  # fmt: skip
METHODS = ("linear-hk", "lmbp-hk")


def _orbitcal(args: list[str], cwd: Path, log: list[str]) -> str:
    log.append("orbitcal " + shlex.join(args))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-m", "orbitcal", *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return out.stdout


def _rms(b: np.ndarray, ref: np.ndarray) -> float:
    return float(np.sqrt(np.mean((b - ref) ** 2)))


def run(work: Path) -> tuple[list[dict[str, Any]], list[str], dict[str, Any]]:
    import pandas as pd
    from export_consumers import (
        run_c_header,
        run_cosmos,
        run_math_algorithms,
        run_polynomial,
        run_yamcs_javascript,
        validate_xtce,
        xtce_values,
    )
    from yamcs_standin import FakeYamcs, mdb_of

    from orbitcal.calibrate.holdout import later_block_split
    from orbitcal.export import (
        ExportOptions,
        YamcsTarget,
        calibration_form,
        evaluate_document,
        export,
        hk_columns,
    )
    from orbitcal.telemetry import read_telemetry

    log: list[str] = []
    (work / "orbitcal" / "data").mkdir(parents=True, exist_ok=True)
    (work / TLE).write_text((ROOT / TLE).read_text())
    _orbitcal(SIMULATE, work, log)
    tel_path, tle_path = "world/telemetry.parquet", "world/spacecraft.tle"
    _orbitcal(["truth", tel_path, "--tle", tle_path, "--out", "truth.csv"], work, log)
    tel = read_telemetry(work / tel_path, time_scale="UTC").telemetry.sort_by_time()
    truth = pd.read_csv(work / "truth.csv")[["b_x", "b_y", "b_z"]].to_numpy()
    rows_out: list[dict[str, Any]] = []
    extra: dict[str, Any] = {"n": len(tel)}
    for method in METHODS:
        cal = f"{method}.json"
        _orbitcal(
            ["calibrate", tel_path, "--tle", tle_path, "--method", method, "--out", cal], work, log
        )
        _orbitcal(["apply", cal, tel_path, "--out", f"{method}_apply.csv"], work, log)
        doc = json.loads((work / cal).read_text())
        frac = float(doc["metrics"]["holdout_fraction"])
        hold = np.flatnonzero(later_block_split(tel.t_utc_s, frac)[1])
        b_apply = pd.read_csv(work / f"{method}_apply.csv")[["b_x", "b_y", "b_z"]].to_numpy()
        ref, app = truth[hold], b_apply[hold]
        form = calibration_form(doc)
        x_all = hk_columns(form, tel)
        raw, x = tel.b_raw_nt[hold], None if x_all is None else x_all[hold]
        loss_args = ["--telemetry", tel_path, "--tle", tle_path]
        paths = {
            "xtce": f"{method}_xtce.xml",
            "cosmos": f"{method}_cosmos.zip",
            "c-header": f"{method}_magcal.h",
            "polynomial": f"{method}_poly.json",
        }
        for fmt, path in paths.items():
            _orbitcal(["export", cal, "--format", fmt, "--out", path, *loss_args], work, log)
        xml = (work / paths["xtce"]).read_bytes()
        errors = validate_xtce(xml)
        root = ET.fromstring(xml)
        hk_params = [c.upper() for c in form.hk_names]
        values = xtce_values(root, ("MAG_X_RAW", "MAG_Y_RAW", "MAG_Z_RAW"), raw, hk_params, x)
        results: list[tuple[str, str, np.ndarray]] = [
            ("orbitcal apply (CLI)", "whole model", app),
            ("numpy reference evaluator", "whole model", evaluate_document(doc, raw, x)),
            (
                "XTCE JavaScript CustomAlgorithm (node, Yamcs binding)",
                "whole model",
                run_yamcs_javascript(root, values, len(hold)),
            ),
            (
                "XTCE MathAlgorithm postfix (Yamcs stack order)",
                "affine part",
                run_math_algorithms(root, values)[1],
            ),
        ]
        files = export(doc, ExportOptions(format="cosmos")).files
        assert files is not None
        results.append(
            (
                "COSMOS MagCalibration (openc3 PacketConfig)",
                "whole model",
                run_cosmos(files, hk_params, raw, x)[0],
            )
        )
        ok, _, b64, b32 = run_c_header((work / paths["c-header"]).read_bytes(), raw, x)
        results.append(("C header, float64 (cc)", "affine part", b64))
        results.append(("C header, float32 (cc)", "affine part, float32", b32))
        poly = json.loads((work / paths["polynomial"]).read_text())
        results.append(
            ("polynomial (openc3 PolynomialConversion)", "diagonal only", run_polynomial(poly, raw))
        )
        for consumer, carries, b in results:
            rows_out.append(
                {
                    "method": method,
                    "consumer": consumer,
                    "carries": carries,
                    "holdout_rms_nt": _rms(b, ref),
                    "apply_holdout_rms_nt": _rms(app, ref),
                    "max_abs_diff_from_apply_nt": float(np.max(np.abs(b - app))),
                }
            )
        mdb = mdb_of(doc)
        with FakeYamcs(mdb, user="ops", password="pw") as yamcs:
            report = export(
                doc,
                ExportOptions(
                    format="yamcs-push",
                    yamcs=YamcsTarget(
                        url=yamcs.url, instance="magsat", username="ops", password="pw"
                    ),
                ),
            ).report
        assert report is not None
        extra[method] = {
            "document_holdout_rms_nt": doc["metrics"]["holdout_rms_nt"],
            "hidden_layer": (doc["model"].get("training") or {}).get("hidden_layer"),
            "schema_errors": len(errors),
            "c_table_crc_ok": bool(ok),
            "yamcs_push_n_set": report["n_set"],
            "n_holdout": len(hold),
            "xtce_bytes": len(xml),
        }
    return rows_out, log, extra


def render(rows: list[dict[str, Any]], log: list[str], extra: dict[str, Any]) -> str:
    lines = [
        "# Exports evaluated by their consumers (generated by `tools/export_table.py`)",
        "",
        "A simulated Swarm A world (real TLE, tumbling, temperature and magnetorquer effects, "
        f"{extra['n']} samples at 10 s); each calibration fitted on the earlier 75 %, every "
        "figure on the later 25 % (held out), against the reference field of `orbitcal truth`. "
        "RMS over samples and the three components [nT] (CONTRACT `_rms_nt`).",
        "",
        "| method | consumer | carries | held-out RMS [nT] | `orbitcal apply` [nT] | "
        "max \\|consumer − apply\\| [nT] |",
        "|---|---|---|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['method']} | {r['consumer']} | {r['carries']} | {r['holdout_rms_nt']:.4f} | "
            f"{r['apply_holdout_rms_nt']:.4f} | {r['max_abs_diff_from_apply_nt']:.3g} |"
        )
    lines += [
        "",
        "| method | document `holdout_rms_nt` | hidden layer (validation guard) | "
        "XTCE 1.2 schema errors | C table CRC-32 check | `yamcs-push` parameters set "
        "(loopback stand-in) |",
        "|---|---:|---|---:|---|---:|",
    ]
    for m in METHODS:
        e = extra[m]
        lines.append(
            f"| {m} | {e['document_holdout_rms_nt']:.4f} | {e['hidden_layer'] or '–'} | "
            f"{e['schema_errors']} | {'ok' if e['c_table_crc_ok'] else 'FAILED'} | "
            f"{e['yamcs_push_n_set']} |"
        )
    lines += ["", "Commands run (in a scratch directory):", "", "```"]
    lines += log
    lines += ["```", ""]
    return "\n".join(lines)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--workdir", type=Path)
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "export" / "results.md")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.workdir or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        rows, log, extra = run(work)
    args.out.write_text(render(rows, log, extra))
    (args.out.with_suffix(".json")).write_text(json.dumps({"rows": rows, **extra}, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
