"""orbitcal.frames against Skyfield (IAU 2006/2000A, TEME), chaosmagpy (spherical, USE basis) and
the Swarm fixtures (VirES, geocentric ITRF positions and B_NEC)."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from skyfield.api import wgs84
from skyfield.framelib import itrs
from skyfield.sgp4lib import TEME, TEME_to_ITRF
from skyfield.toposlib import ITRSPosition
from skyfield.units import Distance

from orbitcal import frames as fr
from orbitcal.timescales import utc_s_to_skyfield

AUTHORITIES = Path(__file__).resolve().parent / "authorities"
ARCSEC = np.pi / (180.0 * 3600.0)
T_2000 = 946_684_800.0
T_2026 = 1_767_225_600.0


def _rotation_angle_rad(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle of the rotation a @ b.T, from its antisymmetric part (accurate for small angles)."""
    d = np.einsum("nij,nkj->nik", a, b)
    axis = np.stack([d[:, 2, 1] - d[:, 1, 2], d[:, 0, 2] - d[:, 2, 0], d[:, 1, 0] - d[:, 0, 1]], 1)
    return np.arcsin(np.clip(np.linalg.norm(axis, axis=1) / 2.0, 0.0, 1.0))


def _swarm(name: str) -> dict[str, np.ndarray]:
    with h5py.File(AUTHORITIES / f"fixture_paldata_item_MAG{name}.nc4") as f:
        g = f[f"SW_OPER_MAG{name}_LR_1B"]
        return {
            "lat": g["Latitude"][:],  # geocentric, ITRF [deg]
            "lon": g["Longitude"][:],
            "radius_km": g["Radius"][:] / 1000.0,
            "b_nec_igrf": g["B_NEC_IGRF"][:],
            "t_utc_s": 1_451_606_400.0 + g["Timestamp"][:],  # seconds since 2016-01-01
        }


def test_gcrs_to_itrs_matrix_matches_skyfield_2000_2026() -> None:
    rng = np.random.default_rng(11)
    t = rng.uniform(T_2000, T_2026, 1500)
    m = fr.gcrs_to_itrs_matrix(t)
    ref = np.moveaxis(itrs.rotation_at(utc_s_to_skyfield(t)), -1, 0)
    err_arcsec = _rotation_angle_rad(m, ref) / ARCSEC
    # Required < 0.1 arcsec; measured ~1e-5 arcsec (interpolation of C over 1 h).
    assert err_arcsec.max() < 1e-3
    # Orthonormal to rounding.
    np.testing.assert_allclose(
        np.einsum("nij,nkj->nik", m, m), np.broadcast_to(np.eye(3), m.shape), atol=1e-12
    )


def test_gcrs_to_itrs_dense_day_across_leap_second() -> None:
    # 2016-12-31 12:00 .. 2017-01-01 12:00 every 97 s: UT1 − UTC jumps by 1 s at the leap second.
    t = 1_483_185_600.0 + np.arange(0.0, 86_400.0, 97.0)
    m = fr.gcrs_to_itrs_matrix(t)
    ref = np.moveaxis(itrs.rotation_at(utc_s_to_skyfield(t)), -1, 0)
    assert (_rotation_angle_rad(m, ref) / ARCSEC).max() < 1e-3


def test_gcrs_itrs_round_trip_and_physics() -> None:
    rng = np.random.default_rng(12)
    t = rng.uniform(T_2000, T_2026, 500)
    r = rng.normal(size=(500, 3)) * 7000.0
    back = fr.itrs_to_gcrs(fr.gcrs_to_itrs(r, t), t)
    np.testing.assert_allclose(back, r, atol=1e-9)
    # The celestial pole stays within 0.4 deg of ITRS z (precession since J2000 < 0.4 deg).
    z_itrs = fr.gcrs_to_itrs(np.array([0.0, 0.0, 1.0]), t)
    assert np.degrees(np.arccos(z_itrs[:, 2])).max() < 0.4
    # The Earth turns eastward: a GCRS-fixed direction drifts westward in ITRS by ~ω per second.
    t0 = np.array([1.6e9, 1.6e9 + 1.0])
    x = fr.gcrs_to_itrs(np.array([1.0, 0.0, 0.0]), t0)
    dlon = np.arctan2(x[1, 1], x[1, 0]) - np.arctan2(x[0, 1], x[0, 0])
    assert dlon == pytest.approx(-7.2921e-5, rel=1e-3)


def test_teme_to_itrs_matches_skyfield() -> None:
    rng = np.random.default_rng(13)
    t = rng.uniform(T_2000, T_2026, 800)
    sky = utc_s_to_skyfield(t)
    # Frame: ITRS <- GCRS <- TEME from Skyfield's frame objects.
    ref = np.einsum(
        "nij,nkj->nik",
        np.moveaxis(itrs.rotation_at(sky), -1, 0),
        np.moveaxis(TEME.rotation_at(sky), -1, 0),
    )
    assert (_rotation_angle_rad(fr.teme_to_itrs_matrix(t), ref) / ARCSEC).max() < 1e-3
    # Positions and velocities against Skyfield's TEME_to_ITRF (Vallado 2006), km and km/s.
    r = rng.normal(size=(800, 3)) * 7000.0
    v = rng.normal(size=(800, 3)) * 7.5
    r_i, v_i = fr.teme_to_itrs(r, v, t)
    r_ref, v_ref_per_day = TEME_to_ITRF(sky.whole, r.T, v.T * 86_400.0, 0.0, 0.0, sky.ut1_fraction)
    np.testing.assert_allclose(r_i, r_ref.T, atol=1e-6)  # 1 mm
    np.testing.assert_allclose(v_i, v_ref_per_day.T / 86_400.0, atol=1e-9)  # 1 µm/s
    r_t, v_t = fr.itrs_to_teme(r_i, v_i, t)
    np.testing.assert_allclose(r_t, r, atol=1e-9)
    np.testing.assert_allclose(v_t, v, atol=1e-12)


def test_teme_gcrs_matches_skyfield() -> None:
    rng = np.random.default_rng(17)
    t = rng.uniform(T_2000, T_2026, 800)
    ref = np.moveaxis(TEME.rotation_at(utc_s_to_skyfield(t)), -1, 0)
    assert (_rotation_angle_rad(fr.gcrs_to_teme_matrix(t), ref) / ARCSEC).max() < 1e-3
    r = rng.normal(size=(800, 3)) * 7000.0
    np.testing.assert_allclose(fr.teme_to_gcrs(fr.gcrs_to_teme(r, t), t), r, atol=1e-9)
    # Consistent with the ITRS path: TEME → ITRS → GCRS.
    via_itrs = fr.itrs_to_gcrs(np.einsum("nij,nj->ni", fr.teme_to_itrs_matrix(t), r), t)
    np.testing.assert_allclose(fr.teme_to_gcrs(r, t), via_itrs, atol=1e-7)


def test_spherical_round_trip_and_chaosmagpy() -> None:
    from chaosmagpy.coordinate_utils import cartesian_to_spherical

    rng = np.random.default_rng(14)
    r = rng.normal(size=(1000, 3)) * 7000.0
    radius, colat, lon = fr.itrs_to_spherical(r)
    ref_r, ref_theta, ref_phi = cartesian_to_spherical(r[:, 0], r[:, 1], r[:, 2])
    np.testing.assert_allclose(radius, ref_r, rtol=1e-14)
    np.testing.assert_allclose(colat, ref_theta, atol=1e-12)
    np.testing.assert_allclose(np.mod(lon - ref_phi + 180.0, 360.0) - 180.0, 0.0, atol=1e-12)
    np.testing.assert_allclose(fr.spherical_to_itrs(radius, colat, lon), r, atol=1e-9)
    # Signs: colatitude 0 at +z, longitude +90 at +y.
    assert fr.itrs_to_spherical(np.array([[0.0, 0.0, 7000.0]]))[1][0] == 0.0
    np.testing.assert_allclose(
        fr.spherical_to_itrs(7000.0, 90.0, 90.0), [0.0, 7000.0, 0.0], atol=1e-9
    )


def test_geodetic_against_skyfield_wgs84() -> None:
    rng = np.random.default_rng(15)
    lat = rng.uniform(-90.0, 90.0, 500)
    lon = rng.uniform(-180.0, 180.0, 500)
    h_km = rng.uniform(-1.0, 2000.0, 500)
    r = fr.geodetic_to_itrs(lat, lon, h_km)
    ref = wgs84.latlon(lat, lon, elevation_m=h_km * 1000.0).itrs_xyz.km.T
    np.testing.assert_allclose(r, ref, atol=1e-9)  # 1 µm
    lat2, lon2, h2 = fr.itrs_to_geodetic(r)
    np.testing.assert_allclose(lat2, lat, atol=1e-9)
    np.testing.assert_allclose(np.mod(lon2 - lon + 180.0, 360.0) - 180.0, 0.0, atol=1e-9)
    np.testing.assert_allclose(h2, h_km, atol=1e-8)  # 10 µm
    # Skyfield's inverse on the same points.
    pos = ITRSPosition(Distance(km=r.T)).at(utc_s_to_skyfield(1.6e9))
    sky = wgs84.geographic_position_of(pos)
    np.testing.assert_allclose(lat2, sky.latitude.degrees, atol=1e-8)
    np.testing.assert_allclose(h2, sky.elevation.km, atol=1e-6)


def test_geodetic_poles_and_equator() -> None:
    b_km = fr.WGS84_A_KM * (1.0 - 1.0 / fr.WGS84_INV_F)
    np.testing.assert_allclose(fr.geodetic_to_itrs(90.0, 0.0, 0.0), [0.0, 0.0, b_km], atol=1e-9)
    np.testing.assert_allclose(fr.geodetic_to_itrs(0.0, 0.0, 1.0), [fr.WGS84_A_KM + 1.0, 0, 0])
    lat, lon, h = fr.itrs_to_geodetic(np.array([[0.0, 0.0, -b_km - 450.0], [fr.WGS84_A_KM, 0, 0]]))
    np.testing.assert_allclose(lon, [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(lat, [-90.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(h, [450.0, 0.0], atol=1e-9)
    # Geodetic latitude exceeds geocentric latitude in the northern hemisphere (~0.19 deg at 45).
    r = fr.geodetic_to_itrs(45.0, 10.0, 0.0)
    geocentric_lat = 90.0 - fr.itrs_to_spherical(r)[1]
    assert 45.0 - geocentric_lat == pytest.approx(0.1924, abs=1e-3)


def test_nec_basis_against_chaosmagpy_use() -> None:
    from chaosmagpy.coordinate_utils import basevectors_use

    rng = np.random.default_rng(16)
    colat = rng.uniform(1.0, 179.0, 300)
    lon = rng.uniform(-180.0, 180.0, 300)
    r = fr.spherical_to_itrs(6800.0, colat, lon)
    up, south, east = basevectors_use(colat, lon)
    basis = fr.nec_basis_itrs(r)
    np.testing.assert_allclose(basis[:, 0], -south, atol=1e-14)  # North
    np.testing.assert_allclose(basis[:, 1], east, atol=1e-14)
    np.testing.assert_allclose(basis[:, 2], -up, atol=1e-14)  # Centre (down)
    v = rng.normal(size=(300, 3))
    np.testing.assert_allclose(fr.nec_to_itrs(fr.itrs_to_nec(v, r), r), v, atol=1e-13)


@pytest.mark.parametrize("name", ["A", "B"])
def test_swarm_positions_and_field_signs(name: str) -> None:
    """Swarm B_NEC_IGRF at its ITRF positions vs the IGRF-12 2015 tilted dipole (Cartesian formula).

    The dipole is ~90 % of the field: the full IGRF vector lies within 15 deg of it; reversing the
    sign convention of N or C moves it to > 50 deg at one fixture or the other.
    """
    s = _swarm(name)
    r = fr.spherical_to_itrs(s["radius_km"], 90.0 - s["lat"], s["lon"])
    radius, colat, lon = fr.itrs_to_spherical(r)
    np.testing.assert_allclose(radius, s["radius_km"], rtol=1e-15)
    np.testing.assert_allclose(90.0 - colat, s["lat"], atol=1e-12)
    np.testing.assert_allclose(lon, s["lon"], atol=1e-12)
    # IGRF-12 (Thébault et al. 2015) 2015.0 degree-1 coefficients [nT]: (g11, h11, g10).
    g = np.array([-1501.0, 4797.1, -29442.0])
    a_km = 6371.2
    rn = np.linalg.norm(r, axis=1, keepdims=True)
    rh = r / rn
    b_dip_itrs = (a_km / rn) ** 3 * (3.0 * (rh @ g)[:, None] * rh - g)
    b_igrf_itrs = fr.nec_to_itrs(s["b_nec_igrf"], r)
    cos = np.sum(b_dip_itrs * b_igrf_itrs, 1) / np.linalg.norm(b_dip_itrs, axis=1)
    cos /= np.linalg.norm(b_igrf_itrs, axis=1)
    assert np.degrees(np.arccos(cos)).max() < 15.0
    np.testing.assert_allclose(fr.itrs_to_nec(b_igrf_itrs, r), s["b_nec_igrf"], atol=1e-9)


def test_shape_errors() -> None:
    with pytest.raises(ValueError, match="shape"):
        fr.gcrs_to_itrs(np.zeros((3, 2)), np.zeros(3) + 1.6e9)
    with pytest.raises(ValueError, match="1972"):
        fr.gcrs_to_itrs_matrix([0.0])
    assert fr.gcrs_to_itrs_matrix(np.array([])).shape == (0, 3, 3)


@settings(max_examples=200, deadline=None)
@given(
    st.floats(min_value=-90.0, max_value=90.0),
    st.floats(min_value=-179.999, max_value=180.0),
    st.floats(min_value=-5.0, max_value=40_000.0),
)
def test_geodetic_round_trip_property(lat: float, lon: float, h_km: float) -> None:
    lat2, lon2, h2 = fr.itrs_to_geodetic(fr.geodetic_to_itrs(lat, lon, h_km))
    assert abs(float(h2) - h_km) < 1e-8  # 10 µm
    assert abs(float(lat2) - lat) < 1e-9
    if abs(lat) < 89.9999:
        assert abs((float(lon2) - lon + 180.0) % 360.0 - 180.0) < 1e-9
