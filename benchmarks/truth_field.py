"""Benchmark: the reference field in the body frame along track, against ppigrf and chaosmagpy.

Run:  python benchmarks/truth_field.py [--sizes 10000 100000 1000000] [--out PATH]
      python benchmarks/truth_field.py --kernel-only [--kernel-n 1000000] [--repeat 5]

``--kernel-only``: the compiled kernel against the practical limit of the machine, at
``--kernel-n`` samples (IGRF-14, per-sample times): orbitcal's kernel on one thread and parallel
over samples on every core, and plain C loops (``benchmarks/kernels/field_loop.c``, compiled with
gcc -O3 -march=native and the floating-point licences of the kernel's fastmath at benchmark time,
called through ctypes, one thread per core each with a share of the samples): ``synth_lanes``, the
kernel's own algorithm, and ``synth_rows``, the kernel's previous algorithm (Legendre rows stored
per sample). The variants run in turn, ``--repeat`` rounds, each round starting one variant later;
medians are quoted, with the process CPU time over the wall time (cores actually used) and points
per CPU second, and every result is checked against the serial
kernel (max |difference| in nT). The limit is the fastest C loop on every core.
Table: ``benchmarks/results/truth_field_kernel.md``.

Workloads (every sample at its own time, 1 s apart, on a real Swarm A TLE propagated with SGP4):
N = 10^4, 10^5, 10^6 samples of one spacecraft, and 100 spacecraft × 8,640 samples (10 s cadence,
one day each; the 56 real TLE sets of tests/authorities cycled, later copies shifted by 12 h).

Compared side by side on the same samples, field model IGRF-14:
- orbitcal, field only (``get_field("IGRF-14").b_nec_nt``) and the whole body-frame pipeline
  (``orbitcal.truth.truth_body_nt``: spherical coordinates, field, NEC→ITRS→GCRS, quaternion);
- (a) a per-sample ppigrf loop (``ppigrf.igrf_gc`` with one date and one point per call; it
  re-reads its .shc file each call). Timed on a subset of ``--ppigrf-points`` samples and
  extrapolated per point;
- (b) chaosmagpy: per-sample coefficients (``BaseModel.synth_coeffs`` of the same IGRF14.shc)
  and ``model_utils.synth_values``, in chunks of 20,000 samples (one call at 10^6 would need GBs).
Ratios compare field synthesis with field synthesis; the body-frame ratio adds orbitcal's own
rotation time to the baselines' field time (they have no frames of their own).

Peak memory: ``tracemalloc`` (numpy reports its buffers to it) around one orbitcal body-frame run,
beyond the inputs, divided by N. Timings: best of ``--repeat`` runs with ``time.perf_counter``.
The results table, with the machine, goes to ``benchmarks/results/truth_field.md``.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import ctypes
import datetime as dt
import io
import os
import platform
import shutil
import subprocess
import tempfile
import time
import tracemalloc
import warnings
from collections.abc import Callable
from pathlib import Path

import chaosmagpy
import numba
import numpy as np
import ppigrf
from scipy.spatial.transform import Rotation

from orbitcal.field import _kernel, get_field
from orbitcal.field._base import utc_s_to_mjd2000
from orbitcal.field.igrf import igrf_shc_path
from orbitcal.frames import itrs_to_spherical
from orbitcal.orbit import Orbit
from orbitcal.truth import truth_body_nt

REPO = Path(__file__).resolve().parents[1]
TLE_FILE = REPO / "tests" / "authorities" / "swarm_iss_real_tles.tle"
CHAOSMAGPY_CHUNK = 20_000


def _machine() -> dict[str, str]:
    cpu = "unknown"
    with contextlib.suppress(OSError), open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    nproc = subprocess.run(["nproc"], capture_output=True, text=True, check=False).stdout.strip()
    return {
        "date (UTC)": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M"),
        "nproc": nproc,
        "CPU": cpu,
        "load average at start": " ".join(f"{x:.2f}" for x in os.getloadavg()),
        "python": platform.python_version(),
        "numpy / numba / chaosmagpy / ppigrf": (
            f"{np.__version__} / {numba.__version__} / {chaosmagpy.__version__} / 2.1.0"
        ),
    }


def _tle_sets() -> list[str]:
    lines = [ln.rstrip() for ln in TLE_FILE.read_text().splitlines() if ln.strip()]
    return ["\n".join(lines[i : i + 3]) for i in range(0, len(lines), 3)]


def _best(fn: Callable[[], object], repeat: int) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return float(best)


def _quaternions(n: int, seed: int) -> np.ndarray:
    q = Rotation.random(n, random_state=np.random.default_rng(seed)).as_quat()
    return np.column_stack([q[:, 3], q[:, :3]])


def _samples(orbit: Orbit, start_s: float, n: int, step_s: float) -> tuple[np.ndarray, np.ndarray]:
    t = start_s + np.arange(n) * step_s
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # stale-elements warning beyond 14 days
        eph = orbit.propagate(t)
    return t, eph.require_valid().r_itrs_km


def _chaosmagpy_field(model: chaosmagpy.chaos.BaseModel, t: np.ndarray, r: np.ndarray) -> None:
    radius, colat, lon = itrs_to_spherical(r)
    mjd = utc_s_to_mjd2000(t)
    for a in range(0, t.size, CHAOSMAGPY_CHUNK):
        b = a + CHAOSMAGPY_CHUNK
        coeffs = model.synth_coeffs(mjd[a:b])
        chaosmagpy.model_utils.synth_values(coeffs, radius[a:b], colat[a:b], lon[a:b])


def _ppigrf_loop(t: np.ndarray, r: np.ndarray) -> None:
    radius, colat, lon = itrs_to_spherical(r)
    for i in range(t.size):
        when = dt.datetime(1970, 1, 1) + dt.timedelta(seconds=float(t[i]))
        with contextlib.redirect_stdout(io.StringIO()):
            ppigrf.igrf_gc(radius[i], colat[i], lon[i], when)


def _peak_bytes(fn: Callable[[], object]) -> int:
    tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak - base


def _compile_c_loop(workdir: Path) -> tuple[ctypes.CDLL, str]:
    gcc = shutil.which("gcc")
    if gcc is None:
        raise SystemExit("gcc is needed for the C loop limit")
    so = workdir / "field_loop.so"
    # the licences numba's fastmath={"reassoc", "contract", "nsz", "arcp"} gives the kernel
    flags = [
        "-O3", "-march=native", "-fno-math-errno", "-fno-trapping-math", "-fno-signed-zeros",
        "-fassociative-math", "-freciprocal-math", "-ffp-contract=fast", "-fPIC", "-shared",
    ]  # fmt: skip
    src = REPO / "benchmarks" / "kernels" / "field_loop.c"
    subprocess.run([gcc, *flags, "-o", str(so), str(src), "-lm"], check=True)
    version = subprocess.run([gcc, "--version"], capture_output=True, text=True, check=False)
    lib = ctypes.CDLL(str(so))
    dp = ctypes.POINTER(ctypes.c_double)
    lp = ctypes.POINTER(ctypes.c_long)
    i = ctypes.c_int
    long_ = ctypes.c_long
    lib.synth_rows.argtypes = [dp, i, i, i, lp, dp, dp, dp, dp, i, i, long_, long_, dp]
    lib.synth_rows.restype = None
    lib.synth_lanes.argtypes = [dp, i, i, lp, dp, dp, dp, dp, i, i, dp, dp, long_, long_, dp]
    lib.synth_lanes.restype = None
    return lib, f"{version.stdout.splitlines()[0]} {' '.join(flags)}"


def kernel_limit(n: int, repeat: int, out: Path) -> None:
    """The compiled kernel, serial and parallel, against a plain C loop (see module doc)."""
    machine = _machine()
    field = get_field("IGRF-14")
    tles = _tle_sets()
    swarm = Orbit.from_tle(next(s for s in tles if s.startswith("SWARM A")))
    t, r = _samples(swarm, swarm.epoch_utc_s, n, 1.0)
    radius, colat_deg, lon_deg = itrs_to_spherical(r)
    mjd = field.check_range(t)
    idx, dt_days = field._piece_and_offset(mjd)
    pp = np.ascontiguousarray(field._pp_blocks)
    piece = np.ascontiguousarray(idx, dtype=np.int64)
    colat, lon = np.radians(colat_deg), np.radians(lon_deg)
    nmin, nmax = field.nmin, field.nmax
    cores = _kernel.max_threads()

    def numba_run(threads: int) -> np.ndarray:
        return _kernel.synth_pp_nec_nt(
            pp, piece, dt_days, radius, colat, lon, nmin=nmin, nmax=nmax, threads=threads
        )

    ppm = _kernel.order_major(pp, nmax)
    ab, d_c = (np.ascontiguousarray(a) for a in _kernel._constants(nmax))
    dp = ctypes.POINTER(ctypes.c_double)
    lp = ctypes.POINTER(ctypes.c_long)

    with tempfile.TemporaryDirectory() as tmp:
        lib, compiler = _compile_c_loop(Path(tmp))

        def c_part(fn: str, a: int, b: int, res: np.ndarray) -> None:
            # ctypes releases the GIL during the call: threads run the loop side by side
            common = (
                piece.ctypes.data_as(lp), dt_days.ctypes.data_as(dp), radius.ctypes.data_as(dp),
                colat.ctypes.data_as(dp), lon.ctypes.data_as(dp), nmin, nmax,
            )  # fmt: skip
            if fn == "lanes":
                lib.synth_lanes(
                    ppm.ctypes.data_as(dp), ppm.shape[2], ppm.shape[1], *common,
                    ab.ctypes.data_as(dp), d_c.ctypes.data_as(dp), a, b, res.ctypes.data_as(dp),
                )  # fmt: skip
            else:
                lib.synth_rows(
                    pp.ctypes.data_as(dp), pp.shape[0], pp.shape[1], pp.shape[2], *common, a, b,
                    res.ctypes.data_as(dp),
                )  # fmt: skip

        def c_run(fn: str, threads: int) -> np.ndarray:
            res = np.zeros((n, 3))
            # shares on multiples of the lane width, like the kernel's chunks
            cut = [(k * (n // _kernel.LANES) // threads) * _kernel.LANES for k in range(threads)]
            bounds = list(zip(cut, [*cut[1:], n], strict=True))
            if threads == 1:
                c_part(fn, 0, n, res)
            else:
                with concurrent.futures.ThreadPoolExecutor(threads) as pool:
                    list(pool.map(lambda ab_: c_part(fn, *ab_, res), bounds))
            return res

        runs: dict[str, Callable[[], np.ndarray]] = {
            "orbitcal kernel, 1 thread": lambda: numba_run(1),
            f"orbitcal kernel, parallel ({cores} threads)": lambda: numba_run(cores),
            "C loop, same algorithm, 1 thread": lambda: c_run("lanes", 1),
            f"C loop, same algorithm, {cores} threads": lambda: c_run("lanes", cores),
            "C loop, previous algorithm (rows), 1 thread": lambda: c_run("rows", 1),
            f"C loop, previous algorithm (rows), {cores} threads": lambda: c_run("rows", cores),
        }
        reference = numba_run(1)  # also the warm-up (compiles or loads the cached kernels)
        numba_run(cores)
        times: dict[str, list[float]] = {k: [] for k in runs}
        cpu: dict[str, list[float]] = {k: [] for k in runs}
        diffs: dict[str, float] = dict.fromkeys(runs, 0.0)
        names = list(runs)
        for r in range(repeat):
            # each round starts one variant later: no variant always follows the same one
            for name in names[r % len(names) :] + names[: r % len(names)]:
                fn = runs[name]
                c0 = time.process_time()
                t0 = time.perf_counter()
                res = fn()
                times[name].append(time.perf_counter() - t0)
                cpu[name].append(time.process_time() - c0)
                diffs[name] = max(diffs[name], float(np.max(np.abs(res - reference))))
    machine["load average at end"] = " ".join(f"{x:.2f}" for x in os.getloadavg())
    machine["C compiler"] = compiler
    machine["parallel kernel"] = (
        f"{cores} Python threads taking chunks of samples in turn; the compiled kernel releases "
        "the GIL"
    )
    pps = {k: n / float(np.median(v)) for k, v in times.items()}
    cores_used = {k: float(np.median(np.array(cpu[k]) / np.array(v))) for k, v in times.items()}
    per_cpu_s = {k: n / float(np.median(v)) for k, v in cpu.items()}
    limit_name = max(
        (k for k in runs if k.startswith("C loop") and "1 thread" not in k), key=pps.get
    )
    limit = pps[limit_name]
    per_thread = pps["orbitcal kernel, 1 thread"] / pps["C loop, same algorithm, 1 thread"]
    per_thread_cpu = (
        per_cpu_s["orbitcal kernel, 1 thread"] / per_cpu_s["C loop, same algorithm, 1 thread"]
    )
    parallel = pps[f"orbitcal kernel, parallel ({cores} threads)"] / limit
    lines = [
        "# Reference-field kernel against the machine's limit (`benchmarks/truth_field.py "
        "--kernel-only`)",
        "",
        f"IGRF-14 at {n:,} samples of a Swarm A orbit (1 s apart, each at its own time); "
        f"the variants run in turn (each round starting one variant later), {repeat} rounds, "
        "medians quoted. Command: "
        f"`python benchmarks/truth_field.py --kernel-only --kernel-n {n} --repeat {repeat}` "
        "(about 15 s on this machine under load).",
        "",
        "## Machine",
        "",
        *(f"- {k}: {v}" for k, v in machine.items()),
        "",
        f"Limit: the fastest C loop on every core ({limit_name}).",
        "",
        "| variant | points/s (median) | min–max [s] | cores used (CPU s / wall s) "
        "| points per CPU s | fraction of the limit | max \\|Δ\\| vs serial kernel [nT] |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, v in times.items():
        lines.append(
            f"| {name} | {pps[name]:.3g} | {min(v):.3f}–{max(v):.3f} | {cores_used[name]:.2f} "
            f"| {per_cpu_s[name]:.3g} | {pps[name] / limit:.2f} | {diffs[name]:.1e} |"
        )
    lines += [
        "",
        f"Per thread the orbitcal kernel runs at {per_thread:.2f} of the C loop of the same "
        f"algorithm in wall time ({per_thread_cpu:.2f} in points per CPU second, which the "
        f"scheduler's share of a busy core does not change); in parallel on {cores} threads at "
        f"{parallel:.2f} of the limit.",
        "",
        "Algorithm (kernel and `synth_lanes`): for each order m the Schmidt recursion in degree "
        "keeps its two previous terms in registers and each term is summed at once; 32 samples "
        "of one model piece at a time in SIMD lanes; Gauss coefficients by Horner in time at "
        "each sample's own time, read in the order the loops use them; IGRF being linear in "
        "time within a piece, one loop over lanes per (n, m) term does recursion, coefficients "
        "and sums, with (a/r)^(n+2) carried by the Legendre functions. `synth_rows` is the "
        "previous kernel's algorithm (per sample: all coefficients into a buffer, Legendre rows "
        "stored and read back, scalar), kept to show what the change is worth in C as well.",
        "Parallel runs split the samples into shares (the kernel: 8 chunks per thread, taken "
        "in turn by its worker threads); "
        "on a machine shared with other jobs the second core is only partly ours, which the load "
        "average and the cores-used column show. Points per CPU second compare code "
        "independently of that share; a parallel run's CPU seconds include the threading "
        "layer's waiting.",
        "",
    ]
    out.write_text("\n".join(lines))
    print("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--ppigrf-points", type=int, default=200)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--fleet", type=int, nargs=2, default=[100, 8640], metavar=("M", "N"))
    parser.add_argument(
        "--out", type=Path, default=REPO / "benchmarks" / "results" / "truth_field.md"
    )
    parser.add_argument("--kernel-only", action="store_true")
    parser.add_argument("--kernel-n", type=int, default=1_000_000)
    args = parser.parse_args()
    if args.kernel_only:
        kernel_limit(
            args.kernel_n, args.repeat, REPO / "benchmarks" / "results" / "truth_field_kernel.md"
        )
        return

    machine = _machine()
    field = get_field("IGRF-14")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cmp_model = chaosmagpy.chaos.BaseModel.from_shc(str(igrf_shc_path("IGRF-14")))
    tles = _tle_sets()
    swarm = Orbit.from_tle(next(s for s in tles if s.startswith("SWARM A")))

    # warm-up: loads coefficients, compiles or loads the cached kernel, builds the frame grid
    t_w, r_w = _samples(swarm, swarm.epoch_utc_s, 100, 1.0)
    truth_body_nt(t_w, r_w, _quaternions(100, 0))

    rows = []
    for n in args.sizes:
        t, r = _samples(swarm, swarm.epoch_utc_s, n, 1.0)
        q = _quaternions(n, 1)
        radius, colat, lon = itrs_to_spherical(r)
        repeat = args.repeat if n <= 100_000 else 1
        t_field = _best(lambda: field.b_nec_nt(t, radius, colat, lon), repeat)  # noqa: B023
        t_body = _best(lambda: truth_body_nt(t, r, q), repeat)  # noqa: B023
        t_cmp = _best(lambda: _chaosmagpy_field(cmp_model, t, r), 1 if n > 10_000 else repeat)  # noqa: B023
        m = min(args.ppigrf_points, n)
        t_ppigrf = _best(lambda: _ppigrf_loop(t[:m], r[:m]), 1) * n / m  # noqa: B023
        peak = _peak_bytes(lambda: truth_body_nt(t, r, q))  # noqa: B023
        rows.append(
            {
                "workload": f"1 spacecraft × {n:,}",
                "n": n,
                "field_pps": n / t_field,
                "body_pps": n / t_body,
                "chaosmagpy_pps": n / t_cmp,
                "ppigrf_pps": n / t_ppigrf,
                "ratio_cmp": t_cmp / t_field,
                "ratio_ppigrf": t_ppigrf / t_field,
                "ratio_cmp_body": (t_cmp + t_body - t_field) / t_body,
                "ratio_ppigrf_body": (t_ppigrf + t_body - t_field) / t_body,
                "bytes_per_sample": peak / n,
            }
        )
        print(rows[-1], flush=True)

    # fleet: M spacecraft × N samples at 10 s, each spacecraft its own TLE and times
    n_sc, n_per = args.fleet
    fleet = []
    for i in range(n_sc):
        orbit = Orbit.from_tle(tles[i % len(tles)])
        start = orbit.epoch_utc_s + (i // len(tles)) * 43_200.0
        t, r = _samples(orbit, start, n_per, 10.0)
        fleet.append((t, r, _quaternions(n_per, 100 + i)))
    n_tot = n_sc * n_per

    def fleet_field() -> None:
        for t, r, _ in fleet:
            field.b_nec_nt(t, *itrs_to_spherical(r))

    def fleet_body() -> None:
        for t, r, q in fleet:
            truth_body_nt(t, r, q)

    def fleet_cmp() -> None:
        for t, r, _ in fleet:
            _chaosmagpy_field(cmp_model, t, r)

    t_field = _best(fleet_field, 1)
    t_body = _best(fleet_body, 1)
    t_cmp = _best(fleet_cmp, 1)
    m = min(args.ppigrf_points, n_per)
    t_ppigrf = _best(lambda: _ppigrf_loop(fleet[0][0][:m], fleet[0][1][:m]), 1) * n_tot / m
    peak = _peak_bytes(lambda: truth_body_nt(fleet[0][0], fleet[0][1], fleet[0][2]))
    rows.append(
        {
            "workload": f"{n_sc} spacecraft × {n_per:,}",
            "n": n_tot,
            "field_pps": n_tot / t_field,
            "body_pps": n_tot / t_body,
            "chaosmagpy_pps": n_tot / t_cmp,
            "ppigrf_pps": n_tot / t_ppigrf,
            "ratio_cmp": t_cmp / t_field,
            "ratio_ppigrf": t_ppigrf / t_field,
            "ratio_cmp_body": (t_cmp + t_body - t_field) / t_body,
            "ratio_ppigrf_body": (t_ppigrf + t_body - t_field) / t_body,
            "bytes_per_sample": peak / n_per,
        }
    )
    print(rows[-1], flush=True)
    machine["load average at end"] = " ".join(f"{x:.2f}" for x in os.getloadavg())
    _write(args.out, machine, rows, args.ppigrf_points)


def _write(path: Path, machine: dict[str, str], rows: list[dict[str, object]], m: int) -> None:
    lines = [
        "# Truth field benchmark (`benchmarks/truth_field.py`)",
        "",
        "Reference field IGRF-14 at every sample's own time and position; body frame = field, "
        "NEC→ITRS→GCRS (IAU 2006/2000A) and the contract quaternion.",
        "",
        "## Machine",
        "",
        *(f"- {k}: {v}" for k, v in machine.items()),
        "",
        "The machine is shared by several developers: the load average shows how busy it was; "
        "ratios measured in the same run are more telling than absolute rates.",
        "",
        "## Results (points per second; ratios = baseline time / orbitcal time)",
        "",
        "| workload | orbitcal field | orbitcal body frame | chaosmagpy field | ppigrf loop field "
        "| × chaosmagpy (field) | × ppigrf (field) | × chaosmagpy (body) | × ppigrf (body) "
        "| peak memory / sample |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['workload']} | {r['field_pps']:.3g} | {r['body_pps']:.3g} "
            f"| {r['chaosmagpy_pps']:.3g} | {r['ppigrf_pps']:.3g} | {r['ratio_cmp']:.1f} "
            f"| {r['ratio_ppigrf']:.0f} | {r['ratio_cmp_body']:.1f} | {r['ratio_ppigrf_body']:.0f} "
            f"| {r['bytes_per_sample']:.0f} B |"
        )
    lines += [
        "",
        "Notes:",
        f"- ppigrf: a per-sample loop timed on the first {m} samples of each workload and "
        "extrapolated linearly per point (each call costs the same: it re-reads the .shc file). "
        "Given all N dates at once ppigrf would build an N × N grid instead.",
        "- chaosmagpy: per-sample coefficients + `synth_values`, in chunks of "
        f"{CHAOSMAGPY_CHUNK:,}.",
        "- body-frame ratios: baseline field time + orbitcal's rotation time, over orbitcal's "
        "body-frame time.",
        "- peak memory: tracemalloc peak during one body-frame run beyond its inputs, per sample "
        "(for the fleet: per spacecraft run of 8,640 samples).",
        "- orbitcal's field uses the compiled kernel (numba; on every core from "
        f"{2 * _kernel.MIN_SAMPLES_PER_THREAD:,} samples, see truth_field_kernel.md); the first "
        "call in a fresh environment compiles it (a few seconds, cached on disk afterwards) and is "
        "excluded as warm-up.",
        "",
    ]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
