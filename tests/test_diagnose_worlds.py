"""Small synthetic worlds for the diagnosis tests: a tilted dipole on a circular orbit.

Independent of the simulator on purpose: the attribution engine works on plain arrays, and these
worlds inject each effect with a forward model written here (a time-tag error re-evaluates the field
at the shifted time, an orbit error moves the position, ...), not with the catalogue's regressors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from orbitcal.arrays import FloatArray
from orbitcal.diagnose.effects import DiagnosisData
from orbitcal.geomag import dipole_axis_itrs

R_EARTH_KM = 6371.2
OMEGA_EARTH_RAD_S = 7.2921150e-5
G10_NT = -29404.8  # IGRF-14 2020 axial dipole; the dipole below uses its full strength


def dipole_b_itrs_nt(r_itrs_km: FloatArray) -> FloatArray:
    """Field of a centred dipole along the geomagnetic axis, ITRS [nT]."""
    m_hat = -dipole_axis_itrs()  # Earth's dipole moment points to the south geomagnetic pole
    b0 = np.sqrt(29404.8**2 + 1450.9**2 + 4652.5**2)
    r = np.linalg.norm(r_itrs_km, axis=1, keepdims=True)
    r_hat = r_itrs_km / r
    mdotr = r_hat @ m_hat
    return np.asarray(b0 * (R_EARTH_KM / r) ** 3 * (3 * mdotr[:, None] * r_hat - m_hat))


def crust_b_itrs_nt(r_itrs_km: FloatArray, *, seed: int = 7, scale: float = 1.0) -> FloatArray:
    """A static "crust": 40 dipoles 50 km below the surface, a few nT to ~15 nT at 450 km."""
    rng = np.random.default_rng(seed)
    pos = rng.normal(size=(40, 3))
    pos *= (R_EARTH_KM - 50.0) / np.linalg.norm(pos, axis=1, keepdims=True)
    mom = rng.normal(size=(40, 3)) * 1.5e9 * scale  # nT km^3
    out = np.zeros_like(r_itrs_km)
    for p, m in zip(pos, mom, strict=True):
        d = r_itrs_km - p
        dist = np.linalg.norm(d, axis=1, keepdims=True)
        dh = d / dist
        out += (3 * (dh @ m)[:, None] * dh - m) / dist**3
    return out


@dataclass
class World:
    data: DiagnosisData
    injected_nt: FloatArray  # the injected effect in sensor axes [nT]
    truth: dict[str, float]


def _orbit(t: FloatArray, *, alt_km: float, incl_deg: float, raan_deg: float) -> FloatArray:
    """Inertial circular orbit positions [km] and ITRS positions."""
    a = R_EARTH_KM + alt_km
    n = np.sqrt(398600.4418 / a**3)
    u = n * t
    inc = np.radians(incl_deg)
    raan = np.radians(raan_deg)
    x_orb = np.stack([np.cos(u), np.sin(u), np.zeros_like(u)], axis=1) * a
    rot = Rotation.from_euler("zx", [raan, inc])  # intrinsic not needed: extrinsic z then x
    rot = Rotation.from_euler("ZX", [raan, inc])
    return np.asarray(rot.apply(x_orb))


def _gcrs_to_itrs(t: FloatArray) -> FloatArray:
    th = OMEGA_EARTH_RAD_S * t
    c, s = np.cos(th), np.sin(th)
    m = np.zeros((t.size, 3, 3))
    m[:, 0, 0] = c
    m[:, 0, 1] = s
    m[:, 1, 0] = -s
    m[:, 1, 1] = c
    m[:, 2, 2] = 1.0
    return m


def make_world(
    effect: str = "none",
    magnitude: float = 1.0,
    *,
    attitude: str = "nadir",
    seed: int = 0,
    n_orbits: float = 4.0,
    step_s: float = 10.0,
    noise_nt: float = 2.0,
    alt_km: float = 450.0,
) -> World:
    """A world with one injected effect; ``magnitude`` scales its natural size (1 = typical)."""
    rng = np.random.default_rng(seed)
    period = 2 * np.pi * np.sqrt((R_EARTH_KM + alt_km) ** 3 / 398600.4418)
    t_rel = np.arange(0.0, n_orbits * period, step_s)
    t0 = 1.6e9 + rng.uniform(0, 1e7)
    incl = rng.uniform(50, 97)
    raan = rng.uniform(0, 360)

    def geometry(
        t_shift: FloatArray, along_km: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        tt = t_rel + t_shift
        r_gcrs = _orbit(tt, alt_km=alt_km, incl_deg=incl, raan_deg=raan)
        v_gcrs = np.gradient(r_gcrs, tt, axis=0)
        r_gcrs = r_gcrs + along_km[:, None] * v_gcrs / np.linalg.norm(v_gcrs, axis=1, keepdims=True)
        m = _gcrs_to_itrs(tt + t0 - 1.6e9)
        r_itrs = np.einsum("nij,nj->ni", m, r_gcrs)
        if attitude == "nadir":
            z = -r_gcrs / np.linalg.norm(r_gcrs, axis=1, keepdims=True)
            h = np.cross(r_gcrs, v_gcrs)
            y = -h / np.linalg.norm(h, axis=1, keepdims=True)
            x = np.cross(y, z)
            g2b = np.stack([x, y, z], axis=1)  # rows: body axes in GCRS
        else:
            axis = np.array([0.3, -0.5, 0.81])
            axis /= np.linalg.norm(axis)
            rate = 0.02  # rad/s
            rot = Rotation.from_rotvec(np.outer(tt, axis) * rate) * Rotation.from_euler(
                "xyz", [0.3, 0.2, 0.1]
            )
            g2b = rot.inv().as_matrix()
        i2b = np.einsum("nij,nkj->nik", g2b, m)  # body <- gcrs <- itrs
        return r_itrs, i2b, g2b

    zeros = np.zeros_like(t_rel)
    r_itrs, i2b, g2b = geometry(zeros, zeros)
    b_ref_itrs = dipole_b_itrs_nt(r_itrs)
    b_ref_body = np.einsum("nij,nj->ni", i2b, b_ref_itrs)

    sun_gcrs = np.array([0.8, 0.5, 0.33])
    sun_gcrs /= np.linalg.norm(sun_gcrs)
    r_gcrs = np.einsum("nji,nj->ni", _gcrs_to_itrs(t_rel + t0 - 1.6e9), r_itrs)
    along = r_gcrs @ sun_gcrs
    perp = np.linalg.norm(r_gcrs - along[:, None] * sun_gcrs, axis=1)
    sunlit = (along > 0) | (perp > R_EARTH_KM)
    sun_body = np.einsum("nij,j->ni", g2b, sun_gcrs)

    temperature = 20.0 + 8.0 * np.convolve(sunlit.astype(float) - 0.5, np.ones(60) / 60, "same")
    temperature += 0.5 * rng.normal(size=t_rel.size).cumsum() * 0.05
    mtq = np.zeros((t_rel.size, 3))
    for k in range(3):
        level = rng.choice([-1.0, 0.0, 1.0], size=t_rel.size // 30 + 1) * 5.0
        mtq[:, k] = np.repeat(level, 30)[: t_rel.size]
    rc = (
        -20.0
        - 60.0 * np.sin(np.pi * t_rel / t_rel[-1])
        + rng.normal(size=t_rel.size).cumsum() * 0.2
    )

    b_true_body = b_ref_body.copy()
    extra = np.zeros_like(b_ref_body)
    truth: dict[str, float] = {}
    if effect == "time_offset":
        dt = 1.0 * magnitude
        r2, i2b2, _ = geometry(np.full_like(t_rel, dt), zeros)
        b_true_body = np.einsum("nij,nj->ni", i2b2, dipole_b_itrs_nt(r2))
        truth["dt_s"] = dt
    elif effect == "orbit_error":
        s = (3.0 + 4.0 * t_rel / 86400.0 * 10) * magnitude
        r2, _, _ = geometry(zeros, s)
        b_true_body = np.einsum("nij,nj->ni", i2b, dipole_b_itrs_nt(r2))
        truth["along_track_km"] = float(np.mean(s))
    elif effect == "external_field":
        amp = 0.6 * rc * magnitude
        b_true_body = b_ref_body + amp[:, None] * np.einsum("nij,j->ni", i2b, dipole_axis_itrs())
    elif effect == "crustal_field":
        b_true_body = b_ref_body + np.einsum(
            "nij,nj->ni", i2b, crust_b_itrs_nt(r_itrs, scale=magnitude)
        )
    elif effect == "field_aligned_currents":
        from orbitcal.geomag import magnetic_latitude_deg

        mlat = magnetic_latitude_deg(r_itrs)
        env = np.exp(-0.5 * ((np.abs(mlat) - 68.0) / 3.0) ** 2)
        east = np.cross(dipole_axis_itrs(), r_itrs / np.linalg.norm(r_itrs, axis=1, keepdims=True))
        east /= np.linalg.norm(east, axis=1, keepdims=True)
        b_true_body = (
            b_ref_body
            + np.einsum("nij,nj->ni", i2b, east)
            * (150.0 * magnitude * env * np.sign(mlat))[:, None]
        )
    elif effect == "sun_driven":
        d = np.array([[3.0, 1.0, -2.0], [0.5, -4.0, 1.0], [2.0, 0.0, 3.0]]) * magnitude
        extra = sunlit[:, None] * (sun_body @ d.T + np.array([2.0, -1.0, 3.0]) * magnitude)
    elif effect == "attitude_error":
        phase = 2 * np.pi * t_rel / period
        ang = (
            1e-3
            * magnitude
            * np.stack([np.sin(phase + 0.3), 0.7 * np.cos(phase), 0.5 * np.sin(2 * phase)], axis=1)
        )
        b_true_body = Rotation.from_rotvec(ang).inv().apply(b_ref_body)
    b_true_body = b_true_body + extra

    a = np.eye(3) + rng.normal(scale=0.01, size=(3, 3))
    o = rng.normal(scale=100.0, size=3)
    b_raw = b_true_body @ a.T + o
    if effect == "temperature":
        dtemp = temperature - 20.0
        b_raw += (np.array([1.5, -1.0, 2.0]) * magnitude) * dtemp[:, None]
        b_raw += (1e-4 * magnitude) * dtemp[:, None] * b_true_body
    elif effect == "magnetorquer":
        c = np.array([[4.0, -1.0, 0.5], [1.0, 3.0, -2.0], [0.0, 1.5, 5.0]]) * magnitude
        b_raw += mtq @ c.T
    elif effect == "nonlinearity":
        b_raw += 40.0 * magnitude * (b_true_body / 5e4) ** 3 * np.array([1.0, -0.7, 0.5])
    elif effect == "parameter_drift":
        tau = (t_rel - t_rel[0]) / 86400.0
        b_raw += np.outer(tau, np.array([60.0, -40.0, 30.0]) * magnitude)
    injected = b_raw - (b_ref_body @ a.T + o)
    b_raw = b_raw + rng.normal(scale=noise_nt, size=b_raw.shape)

    crust_model = np.einsum(
        "nij,nj->ni", i2b, crust_b_itrs_nt(r_itrs) * 0.9 + crust_b_itrs_nt(r_itrs, seed=8) * 0.1
    )
    hk_names = ("temperature", "mtq_x", "mtq_y", "mtq_z")
    x_hk = np.column_stack([temperature, mtq])
    data = DiagnosisData(
        t_utc_s=t_rel + t0,
        b_raw_nt=b_raw,
        b_ref_body_nt=b_ref_body,
        rot_itrs_to_body=i2b,
        r_itrs_km=r_itrs,
        x_hk=x_hk,
        hk_names=hk_names,
        sunlit=sunlit,
        sun_body=sun_body,
        rc_index_nt=rc,
        b_crust_body_nt=crust_model,
        crust_model="test-crust",
        reference_fn=lambda _t, r: dipole_b_itrs_nt(r),
    )
    return World(data=data, injected_nt=injected, truth=truth)


def test_world_null_is_noise_only() -> None:
    w = make_world("none", seed=1)
    assert np.allclose(w.injected_nt, 0.0, atol=1e-6)
    # the reference field has the size of the geomagnetic field at 450 km
    assert 15000 < np.median(np.linalg.norm(w.data.b_ref_body_nt, axis=1)) < 60000
