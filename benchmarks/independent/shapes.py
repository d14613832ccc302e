"""Effect shapes of the independent generator that the diagnosis's catalogue does not write.

Shares no code with ``orbitcal``. Each function returns the effect's contribution and the truth it
was drawn with (a dict of plain floats); none of them is the catalogue's template
(``orbitcal/diagnose/effects.py``) nor our simulator's (``orbitcal/simulate/effects.py``):

* :func:`thermal_sensor`: a sensor temperature from a first-order thermal model driven by the
  eclipse; the offsets **and the scale factors** move with it (the scale through the sensor's
  matrix, so the field it adds is proportional to the field measured), with a quadratic term;
  the thermistor the table gives sits elsewhere (its own, longer lag).
* :func:`lagged_torquer`: dipole commands held over each control period (its own clock, not the
  samples'); the field at the sensor **lags its command** through a first-order filter (coil
  inductance and eddy currents, time constant ``lag_s``), coupled by a random 3x3 matrix.
* :func:`partial_ring_current`: a storm-time field along the dipole axis whose size **depends on
  magnetic local time** (a partial ring current, deepest near dusk: SYM + ASY cos(MLT - dusk)),
  SYM from a driven Burton equation with a noisy injection, ASY decaying faster.
* :func:`sq_and_electrojet`: the dayside ionospheric Sq vortices (foci near +-30 deg latitude,
  organised by solar local time) and the equatorial electrojet, a line current at 110 km over
  the dip equator on the dayside (Biot-Savart); with a probability, a solar-array stray field
  proportional to the array's current (max(cos incidence, 0) while sunlit).
* :func:`star_tracker_steps`: the attitude solution switches between star-tracker heads, each
  with its own misalignment: steps at the switches, plus a slow Gauss-Markov wander.
* :func:`cross_nonlinearity`: cross-axis quadratic terms (b_x b_y, ...) and a soft saturation,
  not the catalogue's per-axis polynomial.
* :func:`settling_drift`: offsets settling exponentially (ageing) and a scale-factor change
  along a smooth sigmoid at a drawn time, not a linear trend or a step.
* :func:`auroral_currents`: region-1/region-2 sheet pairs of opposite sign whose boundaries move
  from crossing to crossing, sign reversed between dawn and dusk, with small-scale structure.
"""

from __future__ import annotations

import numpy as np

MU0_OVER_2PI = 2e-7  # [T m / A]
R_EARTH_KM = 6371.2


def first_order_lag(u: np.ndarray, t_s: np.ndarray, tau_s: float, y0: np.ndarray) -> np.ndarray:
    """Exact response of ``tau y' = u - y`` to ``u`` held constant from each sample to the next
    (zero-order hold): ``y[k] = a y[k-1] + (1 - a) u[k-1]``, ``a = exp(-dt / tau)``."""
    y = np.empty_like(u, dtype=float)
    y[0] = y0
    a = np.exp(-np.diff(t_s) / tau_s)
    for k in range(1, len(t_s)):
        y[k] = a[k - 1] * y[k - 1] + (1.0 - a[k - 1]) * u[k - 1]
    return y


def thermal_sensor(
    rng: np.random.Generator,
    t_s: np.ndarray,
    sunlit: np.ndarray,
    sun_body: np.ndarray,
    b_body_nt: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, dict]:
    """(field added [nT] (N, 3), thermistor reading [degC] (N,), truth).

    The drive: the Sun on a radiator of drawn normal while sunlit, and a heater cycling with a
    drawn period (so that an orbit without eclipse still moves the temperature)."""
    tau_s = float(rng.uniform(600.0, 2500.0))
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    on_radiator = np.clip(sun_body @ normal, 0.0, None)
    heater_period_s = float(rng.uniform(2400.0, 7200.0))
    heater = (((t_s - t_s[0]) / heater_period_s + rng.uniform(0, 1)) % 1.0) < 0.5
    drive = -5.0 + 25.0 * sunlit * (0.5 + 0.5 * on_radiator) + rng.uniform(4.0, 10.0) * heater
    temp = first_order_lag(drive, t_s, tau_s, np.asarray(10.0 + 15.0 * sunlit[0]))
    dtemp = temp - temp.mean()
    offset_coef = rng.uniform(0.5, 3.0, size=3) * rng.choice([-1.0, 1.0], size=3)
    # scale factor [ppm / degC]: fluxgates 10-40 ppm/degC; at 4e4 nT, 20 ppm/degC x 10 degC = 8 nT
    scale_ppm = rng.uniform(10.0, 40.0, size=3) * rng.choice([-1.0, 1.0], size=3)
    added = np.outer(dtemp, offset_coef) + 0.01 * np.outer(dtemp**2, offset_coef)
    added += b_body_nt * (1e-6 * np.outer(dtemp, scale_ppm))
    tau_thermistor_s = float(rng.uniform(100.0, 600.0))
    thermistor = first_order_lag(temp, t_s, tau_thermistor_s, np.asarray(temp[0]))
    thermistor = np.round(thermistor + rng.normal(scale=0.05, size=len(t_s)), 1)
    truth = {
        "time_constant_s": tau_s,
        "heater_period_s": heater_period_s,
        "thermistor_lag_s": tau_thermistor_s,
        "offset_coef_nt_per_c_max": float(np.abs(offset_coef).max()),
        "scale_ppm_per_c_max": float(np.abs(scale_ppm).max()),
        "temperature_span_c": float(np.ptp(temp)),
    }
    return added, thermistor, truth


def torquer_commands(
    rng: np.random.Generator, t_s: np.ndarray, b_body_nt: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """B-dot-like dipole commands [A m^2], set at the start of each control period of a drawn
    length and held over it, some periods off. Returns the command active at each sample (the
    table's ``mtq_*``), the control times and levels (K,), (K, 3), and the truth."""
    period_s = float(rng.uniform(4.0, 30.0))
    m_max = float(rng.uniform(5.0, 20.0))
    control_t = (
        t_s[0]
        - rng.uniform(0.0, period_s)
        + np.arange(0.0, t_s[-1] - t_s[0] + 2 * period_s, period_s)
    )
    db = np.gradient(b_body_nt, t_s, axis=0)
    db_at = np.column_stack([np.interp(control_t, t_s, db[:, k]) for k in range(3)])
    level = -np.sign(db_at) * rng.choice([0.25, 0.5, 0.75, 1.0], size=(len(control_t), 3))
    level *= (rng.random(len(control_t)) > 0.3)[:, None]  # some periods without torquing
    control_u = m_max * level
    active = np.searchsorted(control_t, t_s, side="right") - 1
    truth = {"control_period_s": period_s, "dipole_max_am2": m_max}
    return control_u[active], control_t, control_u, truth


def lagged_torquer(
    rng: np.random.Generator, t_s: np.ndarray, control_t: np.ndarray, control_u: np.ndarray
) -> tuple[np.ndarray, dict]:
    """Field at the sensor [nT] (N, 3): the commands (``control_u`` from each ``control_t`` to
    the next) through a first-order lag of time constant ``lag_s``, coupled by a 3x3 matrix;
    evaluated at the sample times exactly, whatever the cadence."""
    lag_s = float(rng.uniform(1.0, 15.0))
    coupling = rng.normal(scale=rng.uniform(3.0, 10.0), size=(3, 3))
    at_control = first_order_lag(control_u, control_t, lag_s, np.zeros(3))  # y at each c_j
    j = np.clip(np.searchsorted(control_t, t_s, side="right") - 1, 0, None)
    decay = np.exp(-(t_s - control_t[j]) / lag_s)[:, None]
    dipole = control_u[j] + (at_control[j] - control_u[j]) * decay
    truth = {"lag_s": lag_s, "coupling_nt_per_am2_max": float(np.abs(coupling).max())}
    return dipole @ coupling.T, truth


def magnetic_local_time_h(
    r_itrs_km: np.ndarray, north_itrs: np.ndarray, sun_itrs: np.ndarray
) -> np.ndarray:
    """Magnetic local time [h]: the angle from the Sun to the position about the geomagnetic
    north axis, both projected onto the dipole's equatorial plane (12 h: towards the Sun,
    increasing eastward)."""

    def project(v: np.ndarray) -> np.ndarray:
        p = v - (v @ north_itrs)[:, None] * north_itrs[None, :]
        return p / np.linalg.norm(p, axis=1, keepdims=True)

    p_sat, p_sun = project(r_itrs_km), project(sun_itrs)
    cos_a = np.sum(p_sat * p_sun, axis=1)
    sin_a = np.cross(p_sun, p_sat) @ north_itrs
    return (12.0 + np.degrees(np.arctan2(sin_a, cos_a)) / 15.0) % 24.0


def partial_ring_current(
    rng: np.random.Generator, t_s: np.ndarray, mlt_h: np.ndarray
) -> tuple[np.ndarray, dict]:
    """Signed size of the disturbance along the dipole moment [nT] (N,), and the truth.

    ``-(SYM + ASY cos(2 pi (MLT - dusk) / 24))``: the field is depressed most on the dusk side.
    SYM: ``dSYM/dt = Q(t) - SYM / tau`` with an injection of random strength per 10 min during
    the main phase; ASY: the part injected in the last ``tau_asy`` (it decays faster)."""
    tau_h = (t_s - t_s[0]) / 3600.0
    onset_h = float(rng.uniform(0.0, min(3.0, 0.5 * tau_h[-1])))
    main_h = float(rng.uniform(1.0, 4.0))
    tau_rec_h, tau_asy_h = float(rng.uniform(5.0, 12.0)), float(rng.uniform(1.0, 3.0))
    peak = float(rng.uniform(40.0, 160.0))
    grid_h = np.arange(0.0, tau_h[-1] + 1.0 / 6.0, 1.0 / 6.0)
    q = np.where((grid_h >= onset_h) & (grid_h < onset_h + main_h), 1.0, 0.0)
    q *= rng.lognormal(0.0, 0.5, size=len(grid_h))
    sym, asy = np.zeros(len(grid_h)), np.zeros(len(grid_h))
    for k in range(1, len(grid_h)):
        dt = grid_h[k] - grid_h[k - 1]
        sym[k] = sym[k - 1] * np.exp(-dt / tau_rec_h) + q[k - 1] * dt
        asy[k] = asy[k - 1] * np.exp(-dt / tau_asy_h) + q[k - 1] * dt
    scale = peak / max(sym.max(), 1e-9)
    asy_ratio = float(rng.uniform(0.3, 0.8))
    sym_nt = np.interp(tau_h, grid_h, sym * scale)
    asy_nt = np.interp(tau_h, grid_h, asy * scale * asy_ratio / max(asy.max() / sym.max(), 1e-9))
    dusk_h = float(rng.uniform(16.0, 20.0))
    size = -(sym_nt + asy_nt * np.cos(2 * np.pi * (mlt_h - dusk_h) / 24.0))
    truth = {
        "sym_peak_nt": peak,
        "asy_peak_nt": float(asy_nt.max()),
        "dusk_mlt_h": dusk_h,
        "storm_onset_h": onset_h,
        "recovery_h": tau_rec_h,
    }
    return size, truth


def sq_and_electrojet(
    rng: np.random.Generator,
    r_itrs_km: np.ndarray,
    sun_itrs: np.ndarray,
    dip_lat_deg: np.ndarray,
    nec_basis: np.ndarray,
) -> tuple[np.ndarray, dict]:
    """Field in ITRS [nT] (N, 3) of the Sq vortices and the equatorial electrojet."""
    rho = np.linalg.norm(r_itrs_km, axis=1)
    lat = np.arcsin(r_itrs_km[:, 2] / rho)
    lon = np.arctan2(r_itrs_km[:, 1], r_itrs_km[:, 0])
    sun_lon = np.arctan2(sun_itrs[:, 1], sun_itrs[:, 0])
    lt_h = (12.0 + np.degrees(lon - sun_lon) / 15.0) % 24.0
    day = np.clip(np.cos(2 * np.pi * (lt_h - 12.0) / 24.0), 0.0, None) ** 1.5
    sq_nt = float(rng.uniform(8.0, 30.0))
    focus = np.radians(rng.uniform(25.0, 35.0))
    # above the vortex currents: north component changes sign at the foci, down component peaks
    b_n = sq_nt * day * np.sin(np.pi * lat / (2 * focus)) * np.exp(-((lat / (2 * focus)) ** 2))
    b_c = -sq_nt * day * np.cos(lat) ** 4 * np.sin(2 * np.pi * (lt_h - 12.0) / 24.0)
    # electrojet: an eastward line current I at 110 km over the dip equator, dayside
    current_a = float(rng.uniform(30e3, 120e3))
    x_km = np.radians(dip_lat_deg) * (R_EARTH_KM + 110.0)  # northward distance from the jet
    z_km = rho - (R_EARTH_KM + 110.0)  # height above it
    d2_m2 = (x_km**2 + z_km**2) * 1e6
    amp = MU0_OVER_2PI * current_a * day / d2_m2 * 1e9  # B / d: [nT / m]
    # B = mu0 I / (2 pi d) (east x d_hat): north = -z, down = -x (above an eastward current the
    # field points south)
    eej_n = -amp * z_km * 1e3
    eej_c = -amp * x_km * 1e3
    nec = np.column_stack([b_n + eej_n, np.zeros_like(b_n), b_c + eej_c])
    itrs = np.einsum("nki,nk->ni", nec_basis, nec)
    truth = {"sq_nt": sq_nt, "electrojet_ka": current_a / 1e3}
    return itrs, truth


def solar_array_field(
    rng: np.random.Generator, sun_body: np.ndarray, sunlit: np.ndarray
) -> tuple[np.ndarray, dict]:
    """Stray field of the solar-array current [nT] (N, 3): proportional to max(cos i, 0)."""
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    current = np.clip(sun_body @ normal, 0.0, None) * sunlit
    vec = rng.normal(size=3)
    vec *= rng.uniform(3.0, 15.0) / np.linalg.norm(vec)
    return np.outer(current, vec), {"solar_array_nt": float(np.linalg.norm(vec))}


def star_tracker_steps(
    rng: np.random.Generator, t_s: np.ndarray, orbit_s: float
) -> tuple[np.ndarray, dict]:
    """Rotation vectors [rad] (N, 3): per-head misalignment with switches, plus a wander."""
    n_heads = int(rng.integers(2, 4))
    step_deg = float(rng.uniform(0.01, 0.06))
    heads = rng.normal(size=(n_heads, 3))
    heads *= np.radians(step_deg) / np.linalg.norm(heads, axis=1, keepdims=True)
    # a head is blinded once an orbit at a drawn phase, for a drawn part of the orbit
    phase = (t_s - t_s[0]) / orbit_s + rng.uniform(0.0, 1.0)
    blind = (phase % 1.0) < rng.uniform(0.15, 0.45)
    which = np.where(blind, 1, 0)
    if n_heads == 3:  # the third takes over in some orbits
        which = np.where(blind & (np.floor(phase) % 3 == 2), 2, which)
    rv = heads[which]
    tau_s = float(rng.uniform(600.0, 3000.0))
    wander = np.zeros((len(t_s), 3))
    kick = rng.normal(size=(len(t_s), 3))
    a = np.exp(-np.r_[0.0, np.diff(t_s)] / tau_s)
    sigma = 0.2 * np.radians(step_deg)
    for k in range(1, len(t_s)):
        wander[k] = a[k] * wander[k - 1] + np.sqrt(1 - a[k] ** 2) * sigma * kick[k]
    truth = {
        "heads": n_heads,
        "step_deg": step_deg,
        "switches": int(np.count_nonzero(np.diff(which))),
    }
    return rv + wander, truth


def cross_nonlinearity(rng: np.random.Generator, b_nt: np.ndarray) -> tuple[np.ndarray, dict]:
    """Field added [nT] (N, 3): cross-axis quadratic terms and a soft saturation."""
    full = 5e4
    pairs = ((0, 1), (1, 2), (0, 2))
    cross = rng.uniform(5.0, 30.0, size=(3, 3)) * rng.choice([-1.0, 1.0], size=(3, 3))
    added = np.zeros_like(b_nt)
    for i in range(3):
        for j, (a, b) in enumerate(pairs):
            added[:, i] += cross[i, j] * b_nt[:, a] * b_nt[:, b] / full**2
    sat_nt = float(rng.uniform(5.0, 20.0))
    # soft saturation: sat_nt less at full scale, odd in b
    added += -sat_nt * (b_nt / full) ** 3 / (1.0 + (b_nt / full) ** 2) * 2.0
    return added, {
        "cross_nt_at_full_scale_max": float(np.abs(cross).max()),
        "saturation_nt": sat_nt,
    }


def settling_drift(
    rng: np.random.Generator, t_s: np.ndarray, b_body_nt: np.ndarray
) -> tuple[np.ndarray, dict]:
    """Field added [nT] (N, 3): offsets settling exponentially, a scale change along a sigmoid."""
    span = t_s[-1] - t_s[0]
    tau_s = float(rng.uniform(0.2, 1.0)) * span
    settle = rng.uniform(5.0, 30.0, size=3) * rng.choice([-1.0, 1.0], size=3)
    added = np.outer(1.0 - np.exp(-(t_s - t_s[0]) / tau_s), settle)
    mid = t_s[0] + rng.uniform(0.3, 0.8) * span
    width_s = float(rng.uniform(600.0, 3600.0))
    ppm = rng.uniform(100.0, 600.0, size=3) * rng.choice([-1.0, 1.0], size=3)
    ramp = 1.0 / (1.0 + np.exp(-(t_s - mid) / width_s))
    added += b_body_nt * (1e-6 * np.outer(ramp, ppm))
    truth = {
        "settle_nt_max": float(np.abs(settle).max()),
        "settle_time_s": tau_s,
        "scale_change_ppm_max": float(np.abs(ppm).max()),
        "scale_change_at_h": float((mid - t_s[0]) / 3600.0),
    }
    return added, truth


def auroral_currents(
    rng: np.random.Generator,
    t_s: np.ndarray,
    mlat_deg: np.ndarray,
    mlt_h: np.ndarray,
    amp_nt: float,
) -> tuple[np.ndarray, dict]:
    """Magnetic-east perturbation [nT] (N,): region-1 and region-2 sheets per oval crossing."""
    am = np.abs(mlat_deg)
    crossing = np.cumsum(np.r_[0, np.diff((am > 55).astype(int)) == 1])
    n_cross = int(crossing.max()) + 1
    r1 = rng.uniform(66.0, 74.0, size=n_cross)[crossing]  # poleward sheet
    r2 = r1 - rng.uniform(3.0, 6.0, size=n_cross)[crossing]  # equatorward sheet
    strength = amp_nt * rng.lognormal(0.0, 0.4, size=n_cross)[crossing]
    w = 1.2
    inner = 0.5 * (np.tanh((am - r2) / w) - np.tanh((am - r1) / w))
    # dawn (MLT < 12) and dusk sheets carry the opposite sign
    side = np.where(mlt_h < 12.0, 1.0, -1.0)
    east = strength * inner * side * np.sign(mlat_deg)
    fine = np.convolve(rng.normal(size=len(t_s)), np.ones(5) / 5.0, mode="same")
    east = east * (1.0 + 0.2 * fine)
    return east, {"amplitude_nt": amp_nt, "crossings": n_cross}
