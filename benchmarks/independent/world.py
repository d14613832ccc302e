"""An independent world generator: shares no code, and no effect template, with ``orbitcal``.

Orbit: SGP4 (``sgp4``) from real CelesTrak element sets, TEME -> ITRS and GCRS -> ITRS through
Skyfield. Main field: IGRF-14 from ppigrf's coefficient file, synthesised by chaosmagpy with the
coefficients interpolated linearly per sample. Crust: CHAOS-7's static field (degrees 16-185).

Every one of the eleven effects of CONTRACT section 5 can be drawn (:data:`EFFECTS`), one to
three at once, with shapes the catalogue does not write (``shapes.py``): a temperature that moves
the scale factors as well as the offsets, a torquer whose field lags its command, a partial ring
current with a local-time asymmetry, Sq and the equatorial electrojet (and a solar-array stray
field) for the sun-driven field, star-tracker head switches for the attitude error, cross-axis
nonlinearity, settling offsets and a sigmoid scale change for the drift, region-1/2 auroral
sheets, a time-tag error that drifts, the truth propagated from a later element set for the orbit
error, CHAOS-7's crust. Noise (``noise.py``): white, pink, random walk, AR(1), a different kind
and level per axis, quantised, spikes, gaps. Spans of 2-24 h (log-uniform), cadences of 1-30 s.

Every world records its truth: the effects injected with the parameters drawn for each
(``World.truth["effects"]``), the noise per axis, the span, the cadence and the attitude.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
import shapes
from common import (
    REPO,
    Sensor,
    draw_sensor,
    nadir_body_to_frame,
    nec_basis,
    nec_to_itrs,
    spherical_to_itrs_km,
    tumbling_body_to_frame,
    write_table,
)
from noise import NOISE_KINDS, damage, sensor_noise
from scipy.spatial.transform import Rotation, Slerp

__all__ = [
    "EFFECTS",
    "NOISE_KINDS",
    "World",
    "draw_effects",
    "make_world",
    "nec_basis",
    "spherical_to_itrs_km",
]

TLE_FILE = REPO / "tests" / "authorities" / "swarm_iss_real_tles.tle"
CHAOS_FILE = REPO / "tests" / "authorities" / "CHAOS-7.mat"
R_EARTH_KM = 6371.2
#: The eleven effects of CONTRACT section 5 (``none`` aside).
EFFECTS = (
    "temperature",
    "magnetorquer",
    "time_offset",
    "external_field",
    "crustal_field",
    "sun_driven",
    "nonlinearity",
    "orbit_error",
    "parameter_drift",
    "field_aligned_currents",
    "attitude_error",
)
ORBIT_S = 5650.0  # about one orbit at 450-500 km [s]
SPAN_H = (2.0, 24.0)
CADENCES_S = (1.0, 2.0, 5.0, 10.0, 15.0, 20.0, 30.0)


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
    """Unit vector to the geomagnetic north pole (boreal; the dipole moment points the other
    way). Until 2026-11-28 the comment here said "points south" and the ring current was added
    along it with the wrong sign (a storm that raised the field)."""
    time_dy, coeffs = _igrf_coefficients()
    day = float(_mjd2000(np.array([t_unix_s]))[0])
    g10, g11, h11 = (np.interp(day, time_dy, coeffs[k]) for k in range(3))
    m = -np.array([g11, h11, g10])
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


def magnetic_latitude_deg(r_itrs_km: np.ndarray, north: np.ndarray) -> np.ndarray:
    """Dipole latitude [deg], positive towards ``north`` (:func:`dipole_axis_itrs`)."""
    u = r_itrs_km / np.linalg.norm(r_itrs_km, axis=1, keepdims=True)
    return np.degrees(np.arcsin(np.clip(u @ north, -1, 1)))


def dip_latitude_deg(b_itrs_nt: np.ndarray, r_itrs_km: np.ndarray) -> np.ndarray:
    """Dip latitude [deg] from the main field's inclination: atan(tan(I) / 2)."""
    nec = np.einsum("nki,ni->nk", nec_basis(r_itrs_km), b_itrs_nt)
    incl = np.arctan2(nec[:, 2], np.hypot(nec[:, 0], nec[:, 1]))
    return np.degrees(np.arctan(0.5 * np.tan(incl)))


@dataclass
class World:
    t_unix_s: np.ndarray
    b_raw_nt: np.ndarray
    body_to_gcrs: Rotation
    tle_given: TleSet
    extra: dict[str, np.ndarray]
    effects: list[str]
    #: ``effects``: {name: parameters drawn}; ``dt_s`` (mean time-tag error, when drawn);
    #: ``noise``, ``span_h``, ``cadence_s``, ``attitude``, ``columns``.
    truth: dict = field(default_factory=dict)
    noise: str = "white"
    sensor: Sensor | None = None
    #: The element set the truth was propagated from (the user is given ``tle_given``).
    tle_truth: TleSet | None = None

    def write(self, table: Path, tle: Path) -> None:
        write_table(table, self.t_unix_s, self.b_raw_nt, self.body_to_gcrs, None, self.extra)
        tle.write_text(self.tle_given.text())


def draw_effects(rng: np.random.Generator, most: int = 3) -> list[str]:
    """One to ``most`` distinct effects, each of the eleven equally likely."""
    k = int(rng.integers(1, most + 1))
    return sorted(str(e) for e in rng.choice(EFFECTS, size=k, replace=False))


def draw_span_and_cadence(rng: np.random.Generator) -> tuple[float, float]:
    """Span [h], log-uniform over 2-24 h, and a cadence [s] among 1-30 s."""
    span_h = float(np.exp(rng.uniform(np.log(SPAN_H[0]), np.log(SPAN_H[1]))))
    return span_h, float(rng.choice(CADENCES_S))


def _time_tag(rng: np.random.Generator, t: np.ndarray, truth: dict) -> np.ndarray:
    """A time-tag error that drifts: dt(t) = dt0 + rate (t - t0) [s]."""
    dt0 = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.2, 1.0))
    rate = float(rng.uniform(-0.2, 0.2)) / max(t[-1] - t[0], 1.0)  # <= 0.2 s over the span
    dt = dt0 + rate * (t - t[0])
    truth["effects"]["time_offset"] = {"dt0_s": dt0, "drift_s_over_span": rate * (t[-1] - t[0])}
    truth["dt_s"] = float(dt.mean())
    return dt


def make_world(
    rng: np.random.Generator,
    effects: list[str],
    *,
    noise: str = "white",
    small_unmodelled: bool = False,
    span_h: float | None = None,
    cadence_s: float | None = None,
    exclude: frozenset[str] = frozenset(),
) -> World:
    """One world: ``effects`` injected at drawn strengths, ``noise`` of the given kind.

    ``span_h`` / ``cadence_s``: drawn (:func:`draw_span_and_cadence`) unless given.
    ``exclude``: effects drawn (every random number as without it, so the same seed gives the
    same world otherwise) but not applied: the world without them, for the observability oracle
    (``oracle.py``). The attitude the table gives, the user's element set and the thermistor and
    torquer columns stay those of the whole world.
    """
    unknown = sorted(set(effects) - set(EFFECTS))
    if unknown or noise not in NOISE_KINDS:
        raise ValueError(f"unknown effects {unknown} or noise kind {noise!r}")

    def on(name: str) -> bool:
        return name in effects and name not in exclude

    drawn_span, drawn_cadence = draw_span_and_cadence(rng)
    span_h = drawn_span if span_h is None else span_h
    cadence_s = drawn_cadence if cadence_s is None else cadence_s
    pairs = tle_pairs()
    if "field_aligned_currents" in effects:
        pairs = [p for p in pairs if p[0].norad != 25544]  # polar orbits only
    older, newer = pairs[int(rng.integers(len(pairs)))]
    given = older if "orbit_error" in effects else newer
    start = newer.epoch_unix_s + rng.uniform(0.1, 0.6) * 86400.0
    t = start + np.arange(0.0, span_h * 3600.0, cadence_s)
    n = t.size
    truth: dict = {"effects": {}, "span_h": span_h, "cadence_s": cadence_s}
    if "orbit_error" in effects:
        truth["effects"]["orbit_error"] = {
            "element_set_age_days": (newer.epoch_unix_s - older.epoch_unix_s) / 86400.0
        }
    dt_true = _time_tag(rng, t, truth) if "time_offset" in effects else np.zeros(n)
    t_true = t + (dt_true if on("time_offset") else 0.0)
    r_whole = propagate_itrs_km(newer, t + dt_true)  # the attitude's and the Sun's geometry
    r_true = propagate_itrs_km(newer, t_true)
    b_itrs = igrf14_itrs_nt(t_true, r_true)
    north = dipole_axis_itrs(float(t[0]))
    mlat = magnetic_latitude_deg(r_true, north)
    g2i = gcrs_to_itrs_matrices(t_true)
    sun_gcrs = sun_direction_gcrs(t_true)
    sun_itrs = np.einsum("nij,nj->ni", g2i, sun_gcrs)
    mlt = shapes.magnetic_local_time_h(r_true, north, sun_itrs)
    b_itrs = b_itrs + _geophysical(
        rng, effects, on, small_unmodelled, t, r_true, b_itrs, north, mlat, mlt, sun_itrs, truth
    )
    # Attitude and the body frame.
    r_gcrs = np.einsum("nji,nj->ni", gcrs_to_itrs_matrices(t), r_whole)
    if rng.random() < 0.5:
        truth["attitude"] = "tumbling"
        body_to_gcrs = tumbling_body_to_frame(t, rng, float(rng.choice([0.3, 1.0, 2.0])))
    else:
        truth["attitude"] = "nadir"
        body_to_gcrs = nadir_body_to_frame(r_gcrs, t, rng)
    truth_att = whole_att = body_to_gcrs
    if "attitude_error" in effects:
        rv, truth["effects"]["attitude_error"] = shapes.star_tracker_steps(rng, t, ORBIT_S)
        whole_att = body_to_gcrs * Rotation.from_rotvec(rv)
        truth_att = whole_att if on("attitude_error") else body_to_gcrs
    if on("time_offset"):
        # the whole sample belongs to t + dt: the position (above), the Earth's rotation and
        # the body's attitude
        truth_att = Slerp(t, truth_att)(np.clip(t_true, t[0], t[-1]))
    b_body = truth_att.inv().apply(np.einsum("nji,nj->ni", g2i, b_itrs))
    sunlit_frac = sunlit(r_gcrs, sun_direction_gcrs(t))
    # the Sun on the body as the spacecraft really turns (the same with ``exclude``)
    sun_body = whole_att.inv().apply(sun_direction_gcrs(t))
    sensor = draw_sensor(rng, matrix_pct=(0.5, 2.0), offset_nt=(20.0, 300.0), noise_nt=(1.0, 3.0))
    b_sensor = b_body @ sensor.a.T
    raw = b_sensor + sensor.offset_nt
    extra: dict[str, np.ndarray] = {}
    raw = raw + _instrumental(rng, effects, on, t, b_sensor, sunlit_frac, sun_body, extra, truth)
    noise_nt, truth["noise"] = sensor_noise(rng, t, noise, sensor.noise_nt)
    raw, keep = damage(rng, raw + noise_nt, noise, sensor.noise_nt)
    truth["columns"] = sorted(extra)
    return World(
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


Arr = np.ndarray


def _geophysical(
    rng: np.random.Generator,
    effects: list[str],
    on: Callable[[str], bool],
    small: bool,
    t: Arr,
    r_itrs: Arr,
    b_main_itrs: Arr,
    north: Arr,
    mlat: Arr,
    mlt: Arr,
    sun_itrs: Arr,
    truth: dict,
) -> Arr:
    """The fields of the Earth's environment the effects add [nT] (N, 3), in ITRS."""
    added = np.zeros_like(r_itrs)
    if "external_field" in effects:
        size, truth["effects"]["external_field"] = shapes.partial_ring_current(rng, t, mlt)
        if on("external_field"):
            # a fifth more from the currents the storm induces in the Earth
            added += 1.2 * size[:, None] * north[None, :]
    if "field_aligned_currents" in effects or small:
        amp = rng.uniform(80.0, 250.0) if "field_aligned_currents" in effects else rng.uniform(3, 8)
        east, fac_truth = shapes.auroral_currents(rng, t, mlat, mlt, float(amp))
        if "field_aligned_currents" in effects:
            truth["effects"]["field_aligned_currents"] = fac_truth
        if on("field_aligned_currents") or "field_aligned_currents" not in effects:
            zero = np.zeros(len(t))
            added += nec_to_itrs(np.column_stack([zero, east, zero]), r_itrs)
    if "sun_driven" in effects:
        dip = dip_latitude_deg(b_main_itrs, r_itrs)
        sq, truth["effects"]["sun_driven"] = shapes.sq_and_electrojet(
            rng, r_itrs, sun_itrs, dip, nec_basis(r_itrs)
        )
        if on("sun_driven"):
            added += sq
    if "crustal_field" in effects or small:
        scale = rng.uniform(1.0, 2.0) if "crustal_field" in effects else 1.0
        nmin = 16 if "crustal_field" in effects else 100
        if "crustal_field" in effects:
            truth["effects"]["crustal_field"] = {"chaos7_scale": float(scale), "degrees": "16-185"}
        if on("crustal_field") or "crustal_field" not in effects:
            stride = max(1, round(20.0 / float(t[1] - t[0])))  # every ~20 s, interpolated
            added += scale * crust_itrs_nt(r_itrs, nmin=nmin, stride=stride)
    return added


def _instrumental(
    rng: np.random.Generator,
    effects: list[str],
    on: Callable[[str], bool],
    t: Arr,
    b_sensor: Arr,
    sunlit_frac: Arr,
    sun_body: Arr,
    extra: dict[str, Arr],
    truth: dict,
) -> Arr:
    """What the spacecraft and the sensor add [nT] (N, 3); fills the table's extra columns."""
    added = np.zeros_like(b_sensor)
    eff = truth["effects"]
    # a thermistor and torquer commands are in half the worlds without the effect too
    has_temp = "temperature" in effects or rng.random() < 0.5
    has_mtq = "magnetorquer" in effects or rng.random() < 0.5
    if has_temp:
        field_nt, extra["temperature"], temp_truth = shapes.thermal_sensor(
            rng, t, sunlit_frac, sun_body, b_sensor
        )
        if "temperature" in effects:
            eff["temperature"] = temp_truth
        if on("temperature"):
            added += field_nt
    if has_mtq:
        cmd, control_t, control_u, cmd_truth = shapes.torquer_commands(rng, t, b_sensor)
        field_nt, lag_truth = shapes.lagged_torquer(rng, t, control_t, control_u)
        if "magnetorquer" in effects:
            eff["magnetorquer"] = {**cmd_truth, **lag_truth}
        if on("magnetorquer"):
            added += field_nt
        for k, a in enumerate("xyz"):
            extra[f"mtq_{a}"] = np.round(cmd[:, k], 3)
    if "sun_driven" in effects:
        array_nt, array_truth = shapes.solar_array_field(rng, sun_body, sunlit_frac)
        with_array = bool(rng.random() < 0.5)
        eff["sun_driven"].update(array_truth, solar_array=with_array)
        if on("sun_driven") and with_array:
            added += array_nt
    if "nonlinearity" in effects:
        field_nt, eff["nonlinearity"] = shapes.cross_nonlinearity(rng, b_sensor)
        if on("nonlinearity"):
            added += field_nt
    if "parameter_drift" in effects:
        field_nt, eff["parameter_drift"] = shapes.settling_drift(rng, t, b_sensor)
        if on("parameter_drift"):
            added += field_nt
    return added
