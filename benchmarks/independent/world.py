"""An independent world generator: shares no code with ``orbitcal``.

Orbit: SGP4 (``sgp4``) from real CelesTrak element sets, TEME -> ITRS and GCRS -> ITRS through
Skyfield. Main field: IGRF-14 from ppigrf's coefficient file, synthesised by chaosmagpy with the
coefficients interpolated linearly per sample. Crust: CHAOS-7's static field (degrees 16-185).
Effects have their own shapes, from the physics rather than from the diagnosis's templates:

* ``temperature``: a sensor temperature from a first-order thermal model driven by the eclipse
  (cylindrical shadow, Skyfield Sun), with its own time constant; the offsets drift along it,
  with a small quadratic term; the table's ``temperature`` is that of a nearby thermistor
  (lagged a little, quantised to 0.1 degC).
* ``magnetorquer``: B-dot-like commands (sign of the field rate, saturating, duty-cycled off
  half of each 20 s period) coupled into the sensor by a random 3x3 matrix.
* ``time_offset``: the sensor samples the field at ``t + dt``.
* ``external_field``: a ring current along the dipole axis from a Dst series of Burton's equation
  (an injection for the main phase, then recovery), uniform over the orbit, with a 20 % induced
  part.
* ``field_aligned_currents``: sheets of current at the auroral ovals (|mlat| 62-72 deg), a
  tanh-shaped step of the east component (perpendicular to B), different strength per crossing.
* ``attitude_error``: small rotations (twice-per-orbit thermal flex plus a random walk).
* ``orbit_error``: the truth is propagated from a later element set of the same satellite; the
  user is given the older one.
* ``crustal_field``: CHAOS-7 static field, degrees 16-185 (none below 21 in CHAOS-7), scaled.

Noise kinds: ``white``, ``pink`` (1/f), ``random_walk``, ``quantised``, ``spikes``, ``gaps``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
from common import (
    REPO,
    Sensor,
    draw_sensor,
    nadir_body_to_frame,
    nec_to_itrs,
    tumbling_body_to_frame,
    write_table,
)
from scipy.spatial.transform import Rotation

TLE_FILE = REPO / "tests" / "authorities" / "swarm_iss_real_tles.tle"
CHAOS_FILE = REPO / "tests" / "authorities" / "CHAOS-7.mat"
R_EARTH_KM = 6371.2
EFFECTS = (
    "temperature",
    "magnetorquer",
    "time_offset",
    "external_field",
    "field_aligned_currents",
    "attitude_error",
    "orbit_error",
    "crustal_field",
)
NOISE_KINDS = ("white", "pink", "random_walk", "quantised", "spikes", "gaps")


@dataclass
class TleSet:
    name: str
    line1: str
    line2: str

    @property
    def norad(self) -> int:
        return int(self.line1[2:7])

    @property
    def epoch_unix_s(self) -> float:
        yy = int(self.line1[18:20])
        doy = float(self.line1[20:32])
        year = 2000 + yy if yy < 57 else 1900 + yy
        return (
            float(np.datetime64(f"{year}-01-01T00:00:00", "s").astype(float))
            + (doy - 1.0) * 86400.0
        )

    def text(self) -> str:
        return f"{self.name}\n{self.line1}\n{self.line2}\n"


def read_tles() -> list[TleSet]:
    lines = [ln.rstrip() for ln in TLE_FILE.read_text().splitlines() if ln.strip()]
    out = []
    for k in range(0, len(lines) - 2, 3):
        out.append(TleSet(lines[k].strip(), lines[k + 1], lines[k + 2]))
    return out


def tle_pairs(min_days: float = 2.0, max_days: float = 9.0) -> list[tuple[TleSet, TleSet]]:
    """(older, newer) sets of one satellite, ``min_days``-``max_days`` apart."""
    sets = read_tles()
    pairs = []
    for a in sets:
        for b in sets:
            if (
                a.norad == b.norad
                and min_days <= (b.epoch_unix_s - a.epoch_unix_s) / 86400.0 <= max_days
            ):
                pairs.append((a, b))
    return pairs


def _skyfield_time(t_unix_s: np.ndarray):
    from skyfield.api import load

    ts = load.timescale(builtin=True)
    # Whole days and seconds of the day: ``ts.utc(1970, 1, 1, 0, 0, t_unix_s)`` would count the
    # leap seconds since 1970 into the seconds (27 s off in 2022).
    day = np.floor(np.asarray(t_unix_s, dtype=float) / 86400.0)
    return ts.utc(1970, 1, 1 + day.astype(int), 0, 0, t_unix_s - day * 86400.0)


def propagate_itrs_km(tle: TleSet, t_unix_s: np.ndarray) -> np.ndarray:
    from sgp4.api import Satrec
    from skyfield.sgp4lib import TEME_to_ITRF

    sat = Satrec.twoline2rv(tle.line1, tle.line2)
    jd = t_unix_s / 86400.0 + 2440587.5
    jd_i = np.floor(jd)
    err, r, v = sat.sgp4_array(jd_i, jd - jd_i)
    if np.any(err):
        raise RuntimeError(f"SGP4 error codes {set(err.tolist())} for {tle.name}")
    t = _skyfield_time(t_unix_s)
    r_itrs, _ = TEME_to_ITRF(t.ut1, r.T, v.T * 86400.0, 0.0, 0.0)
    return np.asarray(r_itrs.T)


def gcrs_to_itrs_matrices(t_unix_s: np.ndarray) -> np.ndarray:
    from skyfield.framelib import itrs

    m = itrs.rotation_at(_skyfield_time(t_unix_s))  # (3, 3, N): v_itrs = m @ v_gcrs
    return np.moveaxis(np.asarray(m), -1, 0)


def sun_direction_gcrs(t_unix_s: np.ndarray) -> np.ndarray:
    """Low-precision solar direction (Astronomical Almanac, ~0.01 deg), unit vectors (N, 3)."""
    n = t_unix_s / 86400.0 + 2440587.5 - 2451545.0
    mean_lon = np.radians((280.460 + 0.9856474 * n) % 360.0)
    g = np.radians((357.528 + 0.9856003 * n) % 360.0)
    lam = mean_lon + np.radians(1.915) * np.sin(g) + np.radians(0.020) * np.sin(2 * g)
    eps = np.radians(23.439 - 4e-7 * n)
    return np.column_stack([np.cos(lam), np.cos(eps) * np.sin(lam), np.sin(eps) * np.sin(lam)])


def sunlit(r_gcrs_km: np.ndarray, sun_dir: np.ndarray) -> np.ndarray:
    """Cylindrical shadow with a 20 s-wide penumbral ramp, in [0, 1]."""
    along = np.sum(r_gcrs_km * sun_dir, axis=1)
    perp = np.linalg.norm(r_gcrs_km - along[:, None] * sun_dir, axis=1)
    depth = perp - 6378.0  # > 0 outside the cylinder
    lit = np.clip(0.5 + depth / 150.0, 0.0, 1.0)
    return np.where(along > 0, 1.0, lit)


@lru_cache(maxsize=1)
def _igrf_coefficients() -> tuple[np.ndarray, np.ndarray]:
    import ppigrf
    from chaosmagpy.data_utils import load_shcfile

    time_dy, coeffs, _ = load_shcfile(str(Path(ppigrf.__file__).parent / "IGRF14.shc"))
    return np.asarray(time_dy, dtype=float), np.asarray(coeffs, dtype=float)


def _mjd2000(t_unix_s: np.ndarray) -> np.ndarray:
    """Days since 2000-01-01 00:00 UTC (chaosmagpy's time of the coefficient files)."""
    return (np.asarray(t_unix_s, dtype=float) - 946684800.0) / 86400.0


def _spherical(r_itrs_km: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rho = np.linalg.norm(r_itrs_km, axis=1)
    theta = np.degrees(np.arccos(r_itrs_km[:, 2] / rho))
    phi = np.degrees(np.arctan2(r_itrs_km[:, 1], r_itrs_km[:, 0]))
    return rho, theta, phi


def _synth_nec(coeffs: np.ndarray, r_itrs_km: np.ndarray, nmax: int, nmin: int = 1) -> np.ndarray:
    from chaosmagpy.model_utils import synth_values

    rho, theta, phi = _spherical(r_itrs_km)
    br, bt, bp = synth_values(coeffs, rho, theta, phi, nmax=nmax, nmin=nmin)
    return np.column_stack([-bt, bp, -br])


def igrf14_itrs_nt(t_unix_s: np.ndarray, r_itrs_km: np.ndarray) -> np.ndarray:
    time_dy, coeffs = _igrf_coefficients()
    day = _mjd2000(t_unix_s)
    per_sample = np.stack(
        [np.interp(day, time_dy, coeffs[k]) for k in range(coeffs.shape[0])], axis=1
    )
    return nec_to_itrs(_synth_nec(per_sample, r_itrs_km, 13), r_itrs_km)


def dipole_axis_itrs(t_unix_s: float) -> np.ndarray:
    time_dy, coeffs = _igrf_coefficients()
    day = float(_mjd2000(np.array([t_unix_s]))[0])
    g10, g11, h11 = (np.interp(day, time_dy, coeffs[k]) for k in range(3))
    m = -np.array([g11, h11, g10])  # direction of the dipole moment (points south)
    return m / np.linalg.norm(m)


@lru_cache(maxsize=1)
def _crust_coefficients() -> np.ndarray:
    import chaosmagpy as cp

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = cp.load_CHAOS_matfile(str(CHAOS_FILE))
    return np.asarray(model.model_static.coeffs).reshape(-1)


def crust_itrs_nt(
    r_itrs_km: np.ndarray, nmin: int = 16, nmax: int = 185, stride: int = 10
) -> np.ndarray:
    """CHAOS-7 static field, degrees ``nmin`` to ``nmax`` (its coefficients below degree 21 are
    zero); evaluated every ``stride`` samples and interpolated linearly.

    chaosmagpy's ``synth_values`` reads its coefficient array as starting at degree ``nmin``:
    the array is cut there. (Until 2026-11-26 the whole array went in with ``nmin=16``, which
    shifted every coefficient by 255 places: the "crust" of the worlds was a scrambled
    Earth-fixed field that no crustal model could explain; runs before that date scored crustal
    worlds against it.)"""
    coeffs = _crust_coefficients()
    first, n_coef = (nmin - 1) * (nmin + 1), nmax * (nmax + 2)
    idx = np.arange(0, len(r_itrs_km), stride)
    if idx[-1] != len(r_itrs_km) - 1:
        idx = np.append(idx, len(r_itrs_km) - 1)
    nec = _synth_nec(coeffs[first:n_coef], r_itrs_km[idx], nmax, nmin)
    full = np.column_stack([np.interp(np.arange(len(r_itrs_km)), idx, nec[:, k]) for k in range(3)])
    return nec_to_itrs(full, r_itrs_km)


def magnetic_latitude_deg(r_itrs_km: np.ndarray, axis: np.ndarray) -> np.ndarray:
    u = r_itrs_km / np.linalg.norm(r_itrs_km, axis=1, keepdims=True)
    return np.degrees(np.arcsin(np.clip(-u @ axis, -1, 1)))


def colored_noise(rng: np.random.Generator, n: int, kind: str, sigma: float) -> np.ndarray:
    """(n, 3) noise of RMS ~sigma per component."""
    if kind == "pink":
        white = rng.normal(size=(n, 3))
        spec = np.fft.rfft(white, axis=0)
        f = np.fft.rfftfreq(n)
        f[0] = f[1]
        x = np.fft.irfft(spec / np.sqrt(f)[:, None], n=n, axis=0)
        return sigma * x / x.std(axis=0)
    if kind == "random_walk":
        walk = np.cumsum(rng.normal(size=(n, 3)), axis=0)
        walk -= walk.mean(axis=0)
        return 0.5 * sigma * rng.normal(size=(n, 3)) + sigma * walk / walk.std(axis=0)
    return sigma * rng.normal(size=(n, 3))


@dataclass
class World:
    t_unix_s: np.ndarray
    b_raw_nt: np.ndarray
    body_to_gcrs: Rotation
    tle_given: TleSet
    extra: dict[str, np.ndarray]
    effects: list[str]
    truth: dict[str, float] = field(default_factory=dict)
    noise: str = "white"
    sensor: Sensor | None = None
    #: The element set the truth was propagated from (the user is given ``tle_given``).
    tle_truth: TleSet | None = None

    def write(self, table: Path, tle: Path) -> None:
        write_table(table, self.t_unix_s, self.b_raw_nt, self.body_to_gcrs, None, self.extra)
        tle.write_text(self.tle_given.text())


def make_world(
    rng: np.random.Generator,
    effects: list[str],
    *,
    noise: str = "white",
    small_unmodelled: bool = False,
    orbits: float = 4.0,
    cadence_s: float = 10.0,
    exclude: frozenset[str] = frozenset(),
) -> World:
    """One world: ``effects`` injected at drawn strengths, ``noise`` of the given kind.

    ``exclude``: effects drawn (every random number as without it, so the same seed gives the
    same world otherwise) but not applied: the world without them, for the observability oracle
    (``oracle.py``). The attitude the table gives, the user's element set and the thermistor and
    torquer columns stay those of the whole world.
    """

    def on(name: str) -> bool:
        return name in effects and name not in exclude

    pairs = tle_pairs()
    if "field_aligned_currents" in effects:
        pairs = [p for p in pairs if p[0].norad != 25544]  # polar orbits only
    older, newer = pairs[int(rng.integers(len(pairs)))]
    given = older if "orbit_error" in effects else newer
    start = newer.epoch_unix_s + rng.uniform(0.1, 0.6) * 86400.0
    duration = orbits * 5650.0
    t = start + np.arange(0.0, duration, cadence_s)
    n = t.size
    truth: dict[str, float] = {}
    dt_true = 0.0
    if "time_offset" in effects:
        dt_true = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.2, 1.0))
        truth["dt_s"] = dt_true
    dt_used = dt_true if on("time_offset") else 0.0
    r_whole = propagate_itrs_km(newer, t + dt_true)  # the attitude's and the Sun's geometry
    r_true = r_whole if dt_used == dt_true else propagate_itrs_km(newer, t + dt_used)
    b_itrs = igrf14_itrs_nt(t + dt_used, r_true)
    axis = dipole_axis_itrs(float(t[0]))
    mlat = magnetic_latitude_deg(r_true, axis)
    g2i = gcrs_to_itrs_matrices(t)
    if "external_field" in effects:
        tau_h = (t - t[0]) / 3600.0
        peak = rng.uniform(-150.0, -40.0)
        onset = rng.uniform(0.0, 3.0)
        tau_rec = rng.uniform(4, 12)
        # Burton et al. (1975): dDst/dt = Q - Dst / tau, with a constant injection Q for the
        # ``onset`` hours of the main phase (chosen so that Dst reaches ``peak``), none after.
        # (Until 2026-11-26 the main phase rose linearly to 0.3 x the peak and the remaining
        # 0.7 x came in one sample: a step of 30-105 nT in 10 s that no ring current makes.)
        main = 1.0 - np.exp(-np.minimum(tau_h, onset) / tau_rec)
        dst = np.where(
            tau_h < onset,
            peak * main / max(1.0 - np.exp(-onset / tau_rec), 1e-9),
            peak * np.exp(-(tau_h - onset) / tau_rec),
        )
        # The ring current's field at the Earth is along the dipole moment (southward) when
        # Dst < 0; 1.2: a fifth more from the currents it induces in the Earth.
        if on("external_field"):
            b_itrs = b_itrs + (-1.2 * dst)[:, None] * axis[None, :]
        truth["dst_peak_nt"] = float(peak)
        truth["storm_onset_h"] = float(onset)
    if "field_aligned_currents" in effects or small_unmodelled:
        amp = (
            rng.uniform(80.0, 250.0)
            if "field_aligned_currents" in effects
            else rng.uniform(3.0, 8.0)
        )
        am = np.abs(mlat)
        edge_lo, edge_hi = rng.uniform(60, 64), rng.uniform(69, 73)
        crossing = np.cumsum(np.r_[0, np.diff((am > 55).astype(int)) == 1])
        strength = amp * rng.uniform(0.5, 1.5, size=crossing.max() + 2)[crossing]
        sheet = 0.5 * (np.tanh((am - edge_lo) / 1.0) - np.tanh((am - edge_hi) / 1.5))
        east = np.column_stack([np.zeros(n), strength * sheet * np.sign(mlat), np.zeros(n)])
        if on("field_aligned_currents") or ("field_aligned_currents" not in effects):
            b_itrs = b_itrs + nec_to_itrs(east, r_true)
    if "crustal_field" in effects or small_unmodelled:
        scale = rng.uniform(1.0, 2.0) if "crustal_field" in effects else 1.0
        nmin = 16 if "crustal_field" in effects else 100
        if on("crustal_field") or ("crustal_field" not in effects):
            b_itrs = b_itrs + scale * crust_itrs_nt(r_true, nmin=nmin)
    # Attitude and the body frame.
    r_gcrs = np.einsum("nji,nj->ni", g2i, r_whole)
    if rng.random() < 0.5:
        attitude = "tumbling"
        body_to_gcrs = tumbling_body_to_frame(t, rng, float(rng.choice([0.3, 1.0, 2.0])))
    else:
        attitude = "nadir"
        body_to_gcrs = nadir_body_to_frame(r_gcrs, t, rng)
    truth_att = body_to_gcrs
    if "attitude_error" in effects:
        period = 5650.0
        amp = np.radians(rng.uniform(0.03, 0.1))
        flex = amp * np.sin(4 * np.pi * (t - t[0]) / period + rng.uniform(0, 6.3))
        walk = np.cumsum(rng.normal(size=(n, 3)), axis=0)
        walk = 0.5 * amp * walk / np.abs(walk).max()
        rv = walk + np.outer(flex, rng.normal(size=3) / np.sqrt(3))
        if on("attitude_error"):
            truth_att = body_to_gcrs * Rotation.from_rotvec(rv)
        truth["attitude_error_deg"] = float(np.degrees(amp))
    if dt_used != 0.0:
        # A time-tag error of the magnetometer: the whole sample belongs to t + dt -- the
        # position (above), the Earth's rotation and the body's attitude.
        from scipy.spatial.transform import Slerp

        t_true = np.clip(t + dt_true, t[0], t[-1])
        truth_att = Slerp(t, truth_att)(t_true)
        g2i = gcrs_to_itrs_matrices(t + dt_true)
    b_gcrs = np.einsum("nji,nj->ni", g2i, b_itrs)
    b_body = truth_att.inv().apply(b_gcrs)
    sensor = draw_sensor(rng, matrix_pct=(0.5, 2.0), offset_nt=(20.0, 300.0), noise_nt=(1.0, 3.0))
    raw = b_body @ sensor.a.T + sensor.offset_nt
    extra: dict[str, np.ndarray] = {}
    ill = sunlit(r_gcrs, sun_direction_gcrs(t))
    if "temperature" in effects:
        tc = rng.uniform(900.0, 2500.0)
        temp = np.empty(n)
        temp[0] = 10.0 + 15.0 * ill[0]
        for k in range(1, n):
            drive = -5.0 + 25.0 * ill[k]
            temp[k] = temp[k - 1] + (drive - temp[k - 1]) * (1 - np.exp(-cadence_s / tc))
        coef = rng.uniform(0.8, 3.0, size=3) * rng.choice([-1, 1], size=3)
        dtemp = temp - temp.mean()
        if on("temperature"):
            raw = raw + np.outer(dtemp, coef) + 0.01 * np.outer(dtemp**2, coef)
        lag = np.r_[np.full(3, temp[0]), temp[:-3]]
        extra["temperature"] = np.round(lag + rng.normal(scale=0.05, size=n), 1)
        truth["temperature_coef_nt_per_c_max"] = float(np.abs(coef).max())
    if "magnetorquer" in effects:
        mmax = rng.uniform(5.0, 20.0)
        db = np.gradient(b_body, t, axis=0)
        cmd = -mmax * np.tanh(db / (np.abs(db).mean(axis=0) + 1e-9))
        duty = ((t - t[0]) % 20.0) < 10.0
        cmd = cmd * duty[:, None] * (rng.random(n) > 0.1)[:, None]
        coupling = rng.normal(scale=rng.uniform(3.0, 10.0), size=(3, 3))
        if on("magnetorquer"):
            raw = raw + cmd @ coupling.T
        for k, a in enumerate("xyz"):
            extra[f"mtq_{a}"] = np.round(cmd[:, k], 3)
    sigma = sensor.noise_nt
    kind = "white" if noise in ("quantised", "spikes", "gaps") else noise
    raw = raw + colored_noise(rng, n, kind, sigma)
    if noise == "quantised":
        raw = np.round(raw / (2.0 * sigma)) * (2.0 * sigma)
    if noise == "spikes":
        hit = rng.random(n) < 0.005
        raw[hit] += rng.normal(scale=300.0, size=(int(hit.sum()), 3))
    keep = np.ones(n, dtype=bool)
    if noise == "gaps":
        for _ in range(int(rng.integers(3, 7))):
            a = int(rng.integers(0, n - 60))
            keep[a : a + int(rng.integers(10, 60))] = False
    w = World(
        t_unix_s=t[keep],
        b_raw_nt=raw[keep],
        body_to_gcrs=body_to_gcrs[np.flatnonzero(keep)],
        tle_given=given,
        extra={k: v[keep] for k, v in extra.items()},
        effects=list(effects),
        truth=truth,
        noise=noise,
        sensor=sensor,
        tle_truth=newer,
    )
    w.truth["attitude"] = attitude  # type: ignore[assignment]
    return w
