"""A synthetic month of GRACE-FO Level-1B files: ingest, calibrate (``linear-hk``), diagnose a day.

The files are written in the RL04 ASCII layout **from the real files' own YAML headers**
(``tests/authorities/gracefo/``: MAG1B, GNV1B, SCA1B of GRACE C, 2023-06-01) with records from a
simulated world: SGP4 orbit of a real polar LEO element set (Swarm C, 2022-08-01, from
``tests/authorities/swarm_iss_real_tles.tle``), nadir attitude, IGRF-14 in the satellite frame, a
sensor with scale/misalignment, the platform offset measured on the real files
([-530, 16, 250] nT), six torquer currents (piecewise constant, mA) coupled into the sensor, and
5 nT noise. 31 days × 172,800 MAG1B records (2 Hz), 86,400 GNV1B and SCA1B records (1 Hz) a day,
written to a temporary directory (nothing is committed).

Measured, each in its own process (wall and CPU time, peak RSS, by ``/usr/bin/time``):

1. reading the same files with a plain ``numpy.loadtxt`` loop (the peer: numbers only, no join);
2. ``orbitcal.ingest.ingest_gracefo(DIR, out=month.parquet)``;
3. ``orbitcal calibrate month.parquet --method linear-hk``;
4. ``orbitcal ingest gracefo`` of one day and ``orbitcal diagnose`` on it.

Usage: ``python benchmarks/ingest_gracefo_month.py [--days 31] [--workdir /tmp/x] [--out
benchmarks/results/ingest_gracefo_month.md]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from orbitcal.ingest.gracefo import gps_j2000_to_utc_s  # noqa: E402
from orbitcal.ingest.l1b_ascii import END_OF_HEADER  # noqa: E402

AUTH = ROOT / "tests" / "authorities"
OFFSET_NT = np.array([-530.0, 16.0, 250.0])
NOISE_NT = 5.0
#: MAG1B's torquer-current columns, in the order of the injected coupling's columns.
MAG_CURRENTS = ("torque1A", "torque2A", "torque3A", "torque1B", "torque2B", "torque3B")


def _header(product: str, date: str, n: int, start_s: float, stop_s: float) -> str:
    text = (AUTH / "gracefo" / f"{product}_2023-06-01_C_04.txt").read_text()
    head = text[: text.index(END_OF_HEADER)] + END_OF_HEADER + "\n"
    head = re.sub(r"num_records: \d+", f"num_records: {n}", head)
    head = head.replace("2023-06-01", date)
    head = re.sub(r"start_time_epoch_secs: [\d.]+", f"start_time_epoch_secs: {start_s:.6f}", head)
    return re.sub(r"stop_time_epoch_secs: [\d.]+", f"stop_time_epoch_secs: {stop_s:.6f}", head)


def _write(path: Path, header: str, columns: dict[str, object]) -> None:
    table = pa.table(columns)
    with path.open("wb") as fh:
        fh.write(header.encode("ascii"))
        pa_csv.write_csv(
            table,
            fh,
            write_options=pa_csv.WriteOptions(
                include_header=False, delimiter=" ", quoting_style="none"
            ),
        )


def _world(rng: np.random.Generator) -> dict[str, np.ndarray]:
    a = np.eye(3) + rng.normal(0, 1e-3, (3, 3))
    k = rng.normal(0, 0.3, (3, 6))  # nT per mA
    return {"A": a, "K": k}


def write_month(workdir: Path, days: int, seed: int = 22) -> dict[str, object]:
    """Write ``days`` days of MAG1B/GNV1B/SCA1B; returns the injected sensor."""
    from orbitcal.orbit import read_orbits
    from orbitcal.simulate.attitude_profiles import attitude_profile
    from orbitcal.simulate.state import kinematics
    from orbitcal.truth import truth_body_nt

    tles = read_orbits((AUTH / "swarm_iss_real_tles.tle").read_text())
    tle = next(o for o in tles if o.norad_id == 39453)
    rng = np.random.default_rng(seed)
    sensor = _world(rng)
    nadir = attitude_profile("nadir")
    epoch_day = np.datetime64("2022-07-20")
    j2000_noon = np.datetime64("2000-01-01T12:00:00")
    for d in range(days):
        date = str(epoch_day + np.timedelta64(d, "D"))
        day0 = float((np.datetime64(date + "T00:00:00") - j2000_noon) / np.timedelta64(1, "s"))
        t1 = day0 + np.arange(86_400, dtype=np.float64)
        tm = day0 + 0.083329 + 0.5 * np.arange(172_800, dtype=np.float64)
        k1 = kinematics(tle, nadir, gps_j2000_to_utc_s(t1))
        km = kinematics(tle, nadir, gps_j2000_to_utc_s(tm))
        v_itrs_m_s = np.gradient(k1.r_itrs_km, t1, axis=0) * 1000.0
        b_true = truth_body_nt(
            km.t_utc_s, km.r_itrs_km, km.q_wxyz, attitude_frame="GCRS", field="IGRF-14"
        )
        steps = rng.normal(0.0, 40.0, (172_800 // 16 + 1, 6))
        currents = np.repeat(steps, 16, axis=0)[:172_800]
        currents[:, [1, 3]] = 0.0  # two coils idle, as in the real file
        b_raw = (
            b_true @ sensor["A"].T
            + OFFSET_NT
            + currents @ sensor["K"].T
            + rng.normal(0, NOISE_NT, b_true.shape)
        )
        n1, nm = t1.size, tm.size
        intg = np.floor(tm).astype(np.int64)
        frac_us = np.round((tm - intg) * 1e6).astype(np.int64)
        mag = {
            "time_intg": intg,
            "time_frac": frac_us,
            "GRACEFO_id": ["C"] * nm,
            "time_ref": ["G"] * nm,
            "MfvX_RAW": b_raw[:, 0] / 1000.0,
            "MfvY_RAW": b_raw[:, 1] / 1000.0,
            "MfvZ_RAW": b_raw[:, 2] / 1000.0,
        }
        for j, name in enumerate(MAG_CURRENTS):
            mag[name] = currents[:, j]
        mag |= {
            "MF_BCalX": np.zeros(nm),
            "MF_BCalY": np.full(nm, 65000.0),
            "MF_BCalZ": np.full(nm, -65000.0),
            "torque_cal": np.full(nm, -137.4900054931641),
            "qualflg": ["00000000"] * nm,
        }
        first = float(intg[0]) + frac_us[0] * 1e-6
        _write(
            workdir / f"MAG1B_{date}_C_04.txt",
            _header("MAG1B", date, nm, first, float(tm[-1])),
            mag,
        )
        r_m = k1.r_itrs_km * 1000.0
        gnv: dict[str, object] = {"gps_time": t1.astype(np.int64), "GRACEFO_id": ["C"] * n1}
        gnv["coord_ref"] = ["E"] * n1
        for j, ax in enumerate("xyz"):
            gnv[f"{ax}pos"] = r_m[:, j]
        for ax in "xyz":
            gnv[f"{ax}pos_err"] = np.full(n1, 0.0006)
        for j, ax in enumerate("xyz"):
            gnv[f"{ax}vel"] = v_itrs_m_s[:, j]
        for ax in "xyz":
            gnv[f"{ax}vel_err"] = np.full(n1, 1.4e-6)
        gnv["qualflg"] = ["00000000"] * n1
        _write(workdir / f"GNV1B_{date}_C_04.txt", _header("GNV1B", date, n1, t1[0], t1[-1]), gnv)
        q = k1.q_wxyz  # SCA1B's convention is the contract's (scalar first, inertial -> SRF)
        sca: dict[str, object] = {
            "gps_time": t1.astype(np.int64),
            "GRACEFO_id": ["C"] * n1,
            "sca_id": np.full(n1, 23, dtype=np.int64),
            "quatangle": q[:, 0],
            "quaticoeff": q[:, 1],
            "quatjcoeff": q[:, 2],
            "quatkcoeff": q[:, 3],
            "qual_rss": np.full(n1, 8.77e-7),
            "qualflg": ["00000000"] * n1,
        }
        _write(workdir / f"SCA1B_{date}_C_04.txt", _header("SCA1B", date, n1, t1[0], t1[-1]), sca)
    return {
        "offset_nt": OFFSET_NT.tolist(),
        "K_nt_per_ma": sensor["K"].tolist(),
        "A": sensor["A"].tolist(),
    }


def _run(cmd: list[str], *, env: dict[str, str] | None = None) -> tuple[float, float, float, str]:
    """Wall [s], CPU user+system [s], peak RSS [MB] and output of a command.

    Measured by ``/usr/bin/time`` around the command, so that the peak is the command's own and
    not the high-water mark this (larger) parent process leaves in a forked child.
    """
    with tempfile.NamedTemporaryFile("r", suffix=".time") as tf:
        proc = subprocess.run(
            ["/usr/bin/time", "-f", "%e %U %S %M", "-o", tf.name, *cmd],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            env=env,
            text=True,
            check=False,
        )
        if proc.returncode != 0:
            raise RuntimeError(
                f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stdout[-3000:]}"
            )
        wall, user, system, peak_kb = Path(tf.name).read_text().split()[-4:]
    return float(wall), float(user) + float(system), float(peak_kb) / 1024.0, proc.stdout


LOADTXT = """
import sys, numpy as np
from pathlib import Path
from orbitcal.ingest.l1b_ascii import L1BFile
n = 0
for p in sorted(Path(sys.argv[1]).glob('*1B_*.txt')):
    f = L1BFile.open(p)
    cols = [v.column for v in f.variables if v.name not in ('GRACEFO_id', 'time_ref', 'coord_ref')]
    a = np.loadtxt(p, skiprows=f.header_lines, usecols=cols, comments=None)
    n += a.shape[0]
print(n)
"""

INGEST = """
import sys
from orbitcal.ingest import GraceFOOptions, ingest_gracefo
every = float(sys.argv[3]) if len(sys.argv) > 3 else None
r = ingest_gracefo(sys.argv[1], out=sys.argv[2], options=GraceFOOptions(every_s=every))
print(f"{r.summary.rows:,} rows kept")
"""


def _coupling_line(report: dict[str, object], injected: dict[str, object]) -> str:
    """The diagnosis's torquer-current couplings against the injected ones [nT per A]."""
    effects = report.get("effects") or []
    assert isinstance(effects, list)
    mtq = next((e for e in effects if e["name"] == "magnetorquer" and e["significant"]), None)
    if mtq is None:
        return "The diagnosis named no magnetorquer coupling."
    k_nt_per_a = 1e3 * np.asarray(injected["K_nt_per_ma"])
    intervals = mtq.get("param_intervals_90") or {}
    diffs = []
    covered = 0
    for i, axis in enumerate("xyz"):
        for j, ch in enumerate(MAG_CURRENTS):
            key = f"current_coupling_{axis}_{ch.lower()}_ma_nt_per_a"
            if key in mtq["params"]:
                diffs.append(abs(mtq["params"][key] - k_nt_per_a[i, j]))
                lo, hi = intervals.get(key, (np.nan, np.nan))
                covered += bool(lo <= k_nt_per_a[i, j] <= hi)
    return (
        f"The diagnosis's magnetorquer coupling of the torquer currents ({len(diffs)} of "
        f"{k_nt_per_a.size}: idle coils left out) against the injected one: largest difference "
        f"{max(diffs):.2f} nT/A (injected |K| up to {np.abs(k_nt_per_a).max():.0f} nT/A); "
        f"{covered} of {len(diffs)} injected values inside their 90 % intervals."
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=31)
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--keep", action="store_true", help="keep the written files")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks/results/ingest_gracefo_month.md")
    args = ap.parse_args()
    work = args.workdir or Path(tempfile.mkdtemp(prefix="gracefo_month_"))
    files = work / "l1b"
    files.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    py = sys.executable
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    injected = write_month(files, args.days)
    t_write = time.perf_counter() - t0
    size_mb = sum(p.stat().st_size for p in files.iterdir()) / 1e6
    n_mag = 172_800 * args.days

    w_loadtxt, c_loadtxt, m_loadtxt, out_l = _run([py, "-c", LOADTXT, str(files)], env=env)
    month = work / "month.parquet"
    w_ingest, c_ingest, m_ingest, out_i = _run([py, "-c", INGEST, str(files), str(month)], env=env)
    month10 = work / "month_0.1hz.parquet"
    w_i10, c_i10, m_i10, out_i10 = _run([py, "-c", INGEST, str(files), str(month10), "10"], env=env)
    cal = work / "cal.json"
    w_cal, c_cal, m_cal, out_c = _run(
        [
            py,
            "-m",
            "orbitcal",
            "calibrate",
            str(month10),
            "--method",
            "linear-hk",
            "--out",
            str(cal),
        ],
        env=env,
    )
    doc = json.loads(cal.read_text())
    day_dir = work / "day1"
    day_dir.mkdir(exist_ok=True)
    day_date = "2022-07-21" if args.days >= 2 else "2022-07-20"  # the second day, or the only one
    for p in sorted(files.glob(f"*_{day_date}_C_04.txt")):
        (day_dir / p.name).symlink_to(p)
    day = work / "day.parquet"
    w_iday, c_iday, m_iday, _ = _run(
        [
            py,
            "-m",
            "orbitcal",
            "ingest",
            "gracefo",
            str(day_dir),
            "--every-s",
            "1",
            "--out",
            str(day),
        ],
        env=env,
    )
    rep = work / "report.json"
    w_diag, c_diag, m_diag, _ = _run(
        [py, "-m", "orbitcal", "diagnose", str(day), "--out", str(rep)], env=env
    )
    report = json.loads(rep.read_text())
    load1 = os.getloadavg()

    o_fit = np.asarray(doc["linear"]["o"])
    steps = [
        (
            "plain `numpy.loadtxt` loop",
            w_loadtxt,
            c_loadtxt,
            m_loadtxt,
            f"numbers of every file, no join ({out_l.strip()} records)",
        ),
        (
            "`ingest_gracefo` → Parquet, 2 Hz",
            w_ingest,
            c_ingest,
            m_ingest,
            f"{n_mag:,} MAG1B records joined, streamed ({out_i.strip()})",
        ),
        (
            "`ingest_gracefo` → Parquet, `every_s=10`",
            w_i10,
            c_i10,
            m_i10,
            f"the same files thinned to 0.1 Hz for the calibration ({out_i10.strip()})",
        ),
        ("`calibrate --method linear-hk` (0.1 Hz month)", w_cal, c_cal, m_cal, out_c.strip()),
        (
            "ingest (0.1 Hz) + calibrate",
            w_i10 + w_cal,
            c_i10 + c_cal,
            max(m_i10, m_cal),
            "target ≤ 600 s, ≤ 2048 MB",
        ),
        (
            "`ingest gracefo --every-s 1` one day",
            w_iday,
            c_iday,
            m_iday,
            f"{day_date}, 86,400 rows",
        ),
        ("`diagnose` one day", w_diag, c_diag, m_diag, f"verdict `{report.get('verdict')}`"),
    ]
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    lines = [
        "# A month of GRACE-FO Level-1B files: ingest, calibrate, diagnose",
        "",
        f"`python benchmarks/ingest_gracefo_month.py --days {args.days}` (under `nice -n 5`), "
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}.",
        f"Machine: {machine}; load average {load0[0]:.1f} at the start, {load1[0]:.1f} at the "
        "end (the cores were shared with other jobs).",
        "",
        f"Files: {args.days} days × (MAG1B 172,800 + GNV1B 86,400 + SCA1B 86,400 records) in the "
        f"RL04 ASCII layout, headers from the real GRACE C files, {size_mb:.0f} MB; written in "
        f"{t_write:.0f} s.",
        "",
        "| step | wall [s] | CPU [s] | peak RSS [MB] | what |",
        "|---|---|---|---|---|",
        *(f"| {n} | {w:.1f} | {c:.1f} | {m:.0f} | {what} |" for n, w, c, m, what in steps),
        "",
        f"Ingest (2 Hz, joined and written) vs the `loadtxt` loop on the same files: "
        f"{w_ingest / w_loadtxt:.2f}× its wall time, {c_ingest / c_loadtxt:.2f}× its CPU time; "
        f"{c_ingest / args.days:.1f} s of CPU a day.",
        "",
        f"Injected offset {injected['offset_nt']} nT; fitted `o` "
        f"{np.round(o_fit, 2).tolist()} nT; held-out RMS {doc['metrics']['holdout_rms_nt']:.2f} nT "
        f"(noise {NOISE_NT} nT per axis).",
        "",
        f"Diagnosis of {day_date} at 1 Hz: baseline `{report['baseline']['method']}` held-out RMS "
        f"{report['baseline']['holdout_rms_nt']:.2f} nT; effects (name, significant, shrink): "
        + ", ".join(
            f"{e['name']} {e['significant']} {e['shrink']:.2f}"
            for e in report.get("effects", [])[:5]
        ),
        "",
        _coupling_line(report, injected),
        "",
    ]
    args.out.write_text("\n".join(lines))
    print("\n".join(lines))
    if not args.keep and args.workdir is None:
        for p in sorted(work.rglob("*"), reverse=True):
            p.unlink() if p.is_file() or p.is_symlink() else p.rmdir()
        work.rmdir()


if __name__ == "__main__":
    main()
