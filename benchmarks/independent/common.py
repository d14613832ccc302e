"""Shared helpers of the independent harness: geometry, sensor draws, table writing, CLI runs.

Nothing here imports ``orbitcal``: the worlds are built with numpy, scipy, sgp4, Skyfield and
chaosmagpy only, and reach the diagnosis through its command line, as a user's table would.
"""

from __future__ import annotations

import gzip
import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

REPO = Path(__file__).resolve().parents[2]


def spherical_to_itrs_km(
    radius_km: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray
) -> np.ndarray:
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    return np.column_stack(
        [
            radius_km * np.cos(lat) * np.cos(lon),
            radius_km * np.cos(lat) * np.sin(lon),
            radius_km * np.sin(lat),
        ]
    )


def nec_basis(r_itrs_km: np.ndarray) -> np.ndarray:
    """Rows: unit North, East, Centre (down) vectors in ITRS at each position, shape (N, 3, 3)."""
    rho = np.linalg.norm(r_itrs_km, axis=1)
    lat = np.arcsin(r_itrs_km[:, 2] / rho)
    lon = np.arctan2(r_itrs_km[:, 1], r_itrs_km[:, 0])
    north = np.column_stack([-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)])
    east = np.column_stack([-np.sin(lon), np.cos(lon), np.zeros_like(lon)])
    centre = -r_itrs_km / rho[:, None]
    return np.stack([north, east, centre], axis=1)


def nec_to_itrs(b_nec: np.ndarray, r_itrs_km: np.ndarray) -> np.ndarray:
    return np.einsum("nki,nk->ni", nec_basis(r_itrs_km), b_nec)


@dataclass
class Sensor:
    a: np.ndarray  # raw = a @ b_true + offset
    offset_nt: np.ndarray
    noise_nt: float


def draw_sensor(
    rng: np.random.Generator,
    matrix_pct: tuple[float, float] = (0.5, 3.0),
    offset_nt: tuple[float, float] = (50.0, 500.0),
    noise_nt: tuple[float, float] = (0.5, 2.0),
) -> Sensor:
    scale = rng.uniform(*matrix_pct) / 100.0
    a = np.eye(3) + rng.normal(scale=scale, size=(3, 3))
    off = rng.uniform(*offset_nt, size=3) * rng.choice([-1.0, 1.0], size=3)
    return Sensor(a, off, float(rng.uniform(*noise_nt)))


def tumbling_body_to_frame(
    t_s: np.ndarray, rng: np.random.Generator, rate_deg_s: float
) -> Rotation:
    """A steady spin about a random axis from a random start, plus a slow nutation."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    tau = t_s - t_s[0]
    spin = Rotation.from_rotvec(np.outer(np.radians(rate_deg_s) * tau, axis))
    wob_axis = np.cross(axis, rng.normal(size=3))
    wob_axis /= np.linalg.norm(wob_axis)
    wob = Rotation.from_rotvec(
        np.outer(np.radians(8.0) * np.sin(2 * np.pi * tau / rng.uniform(300, 900)), wob_axis)
    )
    return Rotation.random(random_state=int(rng.integers(1 << 31))) * spin * wob


def nadir_body_to_frame(r_km: np.ndarray, t_s: np.ndarray, rng: np.random.Generator) -> Rotation:
    """Body z to nadir, x along the velocity (LVLH), a fixed mounting rotation of a few deg."""
    v = np.gradient(r_km, t_s, axis=0)
    z = -r_km / np.linalg.norm(r_km, axis=1, keepdims=True)
    y = np.cross(z, v)
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    x = np.cross(y, z)
    m = np.stack([x, y, z], axis=2)  # columns: body axes in the frame
    mount = Rotation.from_rotvec(np.radians(rng.uniform(-5, 5, size=3)))
    return Rotation.from_matrix(m) * mount


def write_table(
    path: Path,
    t_unix_s: np.ndarray,
    b_raw_nt: np.ndarray,
    body_to_frame: Rotation,
    r_itrs_km: np.ndarray | None = None,
    extra: dict[str, np.ndarray] | None = None,
) -> None:
    """CONTRACT section-1 CSV: ``v_body = Rotation.from_quat(q_xyzw).inv().apply(v_frame)``."""
    q = body_to_frame.as_quat()  # x, y, z, w
    cols: dict[str, np.ndarray] = {
        "time": t_unix_s,
        "b_x": b_raw_nt[:, 0],
        "b_y": b_raw_nt[:, 1],
        "b_z": b_raw_nt[:, 2],
        "q_w": q[:, 3],
        "q_x": q[:, 0],
        "q_y": q[:, 1],
        "q_z": q[:, 2],
    }
    if r_itrs_km is not None:
        cols.update(r_x=r_itrs_km[:, 0], r_y=r_itrs_km[:, 1], r_z=r_itrs_km[:, 2])
    cols.update(extra or {})
    names = list(cols)
    data = np.column_stack([cols[n] for n in names])
    # 17 significant digits: Unix seconds (~1.7e9) at "%.10g" would lose the fraction of a
    # second, a time-tag error of up to 0.5 s in every world (seen as false time_offset /
    # orbit_error in null worlds before this was found).
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.17g")


ENGINE_CLI = Path(__file__).resolve().parent / "engine_cli.py"


def check_engines(engines: list[str]) -> str:
    """Fail with a clear message unless every one of ``engines`` can run; returns how the
    engine is chosen (``"option"``, or ``"default"`` when ``DiagnosisOptions`` has no ``engine``
    field and only the rules engine was asked for). Asked in a child process: nothing here
    imports ``orbitcal``."""
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); from engine_cli import engine_support, "
        "missing_engine_message as m; ok = engine_support(); "
        "bad = [e for e in sys.argv[2:] if not ok and e != 'rules']; "
        "print('option' if ok else 'default'); sys.exit(m(bad[0]) if bad else 0)"
    )
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.run(
        [sys.executable, "-c", code, str(ENGINE_CLI.parent), *engines],
        capture_output=True,
        text=True,
        env=env,
        cwd=REPO,
    )
    if proc.returncode != 0:
        raise SystemExit((proc.stderr or proc.stdout).strip().splitlines()[-1])
    return proc.stdout.strip()


def run_cli(
    table: Path,
    out: Path,
    *,
    tle: Path | None = None,
    frame: str = "GCRS",
    engine: str | None = None,
) -> dict:
    """``orbitcal diagnose TABLE [--tle TLE] --attitude-frame FRAME --out OUT`` with defaults;
    with ``engine``, through ``engine_cli.py`` (``DiagnosisOptions(engine=ENGINE)``)."""
    entry = ["-m", "orbitcal"] if engine is None else [str(ENGINE_CLI), engine]
    cmd = [
        sys.executable,
        *entry,
        "diagnose",
        str(table),
        "--out",
        str(out),
        "--attitude-frame",
        frame,
    ]
    if tle is not None:
        cmd += ["--tle", str(tle)]
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=REPO)
    if proc.returncode != 0:
        return {"error": (proc.stderr or proc.stdout).strip().splitlines()[-1:]}
    return json.loads(out.read_text())


def git_head(paths: tuple[str, ...] = ("orbitcal",)) -> str:
    """The short commit, ``+dirty`` when ``paths`` have uncommitted changes."""
    out = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=REPO
    )
    dirty = subprocess.run(
        ["git", "status", "--porcelain", *paths], capture_output=True, text=True, cwd=REPO
    )
    return out.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")


def write_json(path: Path, doc: dict) -> None:
    text = json.dumps(doc, indent=1, default=float)
    if path.suffix == ".gz":
        path.write_bytes(gzip.compress(text.encode(), mtime=0))
    else:
        path.write_text(text)


def read_json(path: Path) -> dict:
    data = path.read_bytes()
    return json.loads(gzip.decompress(data) if path.suffix == ".gz" else data)  # type: ignore[no-any-return]
