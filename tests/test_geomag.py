"""orbitcal.geomag: the one centred dipole of the simulator and the diagnosis (issue 13)."""

from __future__ import annotations

import numpy as np

from orbitcal import geomag
from orbitcal.field import get_field
from orbitcal.timescales import decimal_year_to_utc_s


def test_the_dipole_is_igrf14_degree_one_at_its_epoch() -> None:
    t = decimal_year_to_utc_s(np.array([geomag.DIPOLE_EPOCH_YEAR]))
    g10, g11, h11 = get_field("IGRF-14").gauss_coeffs(t)[0, :3]  # type: ignore[attr-defined]
    np.testing.assert_allclose((g10, g11, h11), geomag.IGRF14_DIPOLE_2020_NT, atol=1e-6)


def test_pole_axis_and_magnetic_latitude_agree() -> None:
    lat, lon = geomag.dipole_pole_deg()
    assert abs(lat - 80.59) < 0.01 and abs(lon + 72.68) < 0.01
    z = geomag.dipole_axis_itrs()
    assert abs(np.linalg.norm(z) - 1.0) < 1e-12
    # the pole itself is at magnetic latitude 90, the antipode -90, the equator of the dipole 0
    east = np.cross(z, [0.0, 0.0, 1.0])
    r_km = 6371.0 * np.stack([z, -z, east / np.linalg.norm(east)])
    np.testing.assert_allclose(geomag.magnetic_latitude_deg(r_km), [90.0, -90.0, 0.0], atol=1e-6)
    assert geomag.magnetic_latitude_deg(r_km[None]).shape == (1, 3)  # any leading shape
