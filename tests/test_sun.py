"""Analytic Sun and Earth shadow: published equinox/solstice/perihelion and the eclipse geometry."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from orbitcal.simulate import NadirLVLH, kinematics, select_tle
from orbitcal.sun import (
    AU_KM,
    R_EARTH_KM,
    illumination_conical,
    in_shadow_cylindrical,
    sun_direction_gcrs,
    sun_position_gcrs_km,
)

# The Astronomical Almanac low-precision formula is good to 0.01°; we also ignore the
# precession since J2000 (~0.3°), so positions are checked to 0.05° in declination and
# 0.4° in right ascension.
DEC_TOL_DEG = 0.05
RA_TOL_DEG = 0.4


def _ra_dec_deg(t_iso: str) -> tuple[float, float, float]:
    s = sun_position_gcrs_km([pd.Timestamp(t_iso).timestamp()])[0]
    r = float(np.linalg.norm(s))
    return (
        float(np.degrees(np.arctan2(s[1], s[0]))),
        float(np.degrees(np.arcsin(s[2] / r))),
        r / AU_KM,
    )


def test_equinox_solstice_and_perihelion_2023() -> None:
    # USNO: March equinox 2023-03-20 21:24 UTC, June solstice 2023-06-21 14:58 UTC,
    # perihelion 2023-01-04 16:17 UTC at 0.983296 AU.
    ra, dec, _ = _ra_dec_deg("2023-03-20T21:24:00Z")
    assert abs(dec) < DEC_TOL_DEG and abs(ra) < RA_TOL_DEG
    ra, dec, _ = _ra_dec_deg("2023-06-21T14:58:00Z")
    assert abs(dec - 23.436) < DEC_TOL_DEG and abs(ra - 90.0) < RA_TOL_DEG
    _, _, dist_au = _ra_dec_deg("2023-01-04T16:17:00Z")
    assert abs(dist_au - 0.983296) < 2e-5
    u = sun_direction_gcrs([0.0, 1e9])
    np.testing.assert_allclose(np.linalg.norm(u, axis=1), 1.0, rtol=0, atol=1e-15)


def test_shadow_models_on_simple_geometry() -> None:
    sun = np.array([AU_KM, 0.0, 0.0])
    r = np.array([[7000.0, 0, 0], [-7000.0, 0, 0], [-7000.0, 6000.0, 0], [-7000.0, 6500.0, 0]])
    np.testing.assert_array_equal(in_shadow_cylindrical(r, sun), [False, True, True, False])
    nu = illumination_conical(r, np.tile(sun, (4, 1)))
    assert nu[0] == 1.0 and nu[1] == 0.0 and nu[2] == 0.0 and nu[3] == 1.0
    # Across the terminator the penumbra is a smooth ramp from 0 to 1.
    y = np.linspace(6300.0, 6500.0, 201)
    ramp = illumination_conical(np.column_stack([np.full(201, -7000.0), y, np.zeros(201)]), sun)
    assert np.all(np.diff(ramp) >= 0) and ramp[0] == 0.0 and ramp[-1] == 1.0
    assert 0.0 < ramp[(ramp > 0) & (ramp < 1)].size < 200


@pytest.mark.parametrize(
    ("norad", "start"),
    [
        (25544, "2022-08-02T00:00:00Z"),
        (25544, "2023-07-05T00:00:00Z"),
        (39452, "2023-07-05T00:00:00Z"),
    ],
)
def test_eclipse_fraction_of_leo_matches_the_beta_angle_formula(
    authorities, norad: int, start: str
) -> None:
    """Eclipse fraction over whole orbits vs the circular-orbit formula (Wertz, SMAD):
    f = acos(√(h² + 2Rh) / ((R + h) cos β)) / π."""
    t0 = pd.Timestamp(start).timestamp()
    tle = select_tle(
        (authorities / "swarm_iss_real_tles.tle").read_text(), norad_id=norad, at_utc_s=t0
    )
    period_s = 86400.0 / float(tle.line2[52:63])
    t = t0 + np.arange(0.0, 3 * period_s, 2.0)
    kin = kinematics(tle, NadirLVLH(), t)
    sun = sun_position_gcrs_km(t)
    frac = float(np.mean(illumination_conical(kin.r_gcrs_km, sun) < 0.5))
    h_hat = np.cross(kin.r_gcrs_km, kin.v_gcrs_km_s)
    h_hat /= np.linalg.norm(h_hat, axis=1, keepdims=True)
    beta = float(np.mean(np.arcsin(np.sum(h_hat * sun, axis=1) / np.linalg.norm(sun, axis=1))))
    alt = float(np.mean(np.linalg.norm(kin.r_gcrs_km, axis=1))) - R_EARTH_KM
    expected = (
        np.arccos(np.sqrt(alt**2 + 2 * R_EARTH_KM * alt) / ((R_EARTH_KM + alt) * np.cos(beta)))
        / np.pi
    )
    assert abs(frac - expected) < 0.003  # ~17 s per orbit: sampling, eccentricity, oblateness
    assert 0.30 < frac < 0.40  # a LEO orbit at |β| < 50°: about a third in eclipse
