"""The Swarm A storm pass of 2016-01-01 00:00-00:30 UTC (RC ≈ -129 nT, Kp 6), real ESA data.

Authorities: the measured ``B_NEC`` of Swarm A MAG_LR_1B, and ChaosMagPy's CHAOS-7 external-field
prediction (``CHAOS-7.mat`` with ChaosMagPy's shipped RC index). Facts pinned here:

- IGRF-14 at the file's positions leaves a mean residual of about [-166, -6, -11] nT (N, E, C) at
  |lat| < 40° (the storm-time ring current);
- orbitcal's ``RC`` model equals ChaosMagPy's CHAOS-7 SM+GSM external field (external and induced
  parts) to < 6 nT everywhere on the pass, and CHAOS-8.1 core + CHAOS-8.1 static + RC reduces the
  low-latitude N residual from -166 to about -46 nT — the same as ChaosMagPy's full CHAOS-7 model
  (-46 nT).
- Not reached: the ~15 nT left by VirES's ``B_NEC_CHAOS`` column ([-12, -0.6, -7] nT). VirES's
  CHAOS magnetospheric part is ~34 nT stronger in N than ChaosMagPy's CHAOS-7 external field with
  the RC index ChaosMagPy ships (measured below); neither the CHAOS-7 coefficients nor that RC
  index reproduce it, so the test records the gap instead of tuning to it. (Driving the external
  part by the total RC instead of its external part RC_e would leave -18 nT, close to VirES; that
  is not the CHAOS parameterisation, so it is only noted here.)
"""

from __future__ import annotations

import warnings
from pathlib import Path

import chaosmagpy
import h5py
import numpy as np
import pytest

from orbitcal.field import get_field
from orbitcal.field._base import utc_s_to_mjd2000
from orbitcal.frames import spherical_to_itrs
from orbitcal.truth import reference_field_nec_nt

T_2016_S = 1_451_606_400.0  # 2016-01-01T00:00Z, origin of the file's Timestamp


@pytest.fixture(scope="module")
def storm(authorities: Path) -> dict[str, np.ndarray]:
    with h5py.File(authorities / "test_fac_singlesat_swarm.nc4", "r") as f:
        g = f["SW_OPER_MAGA_LR_1B"]
        lat = g["Latitude"][:]
        lon = g["Longitude"][:]
        radius_km = g["Radius"][:] / 1e3
        return {
            "t": g["Timestamp"][:] + T_2016_S,
            "lat": lat,
            "lon": lon,
            "radius_km": radius_km,
            "r_itrs_km": spherical_to_itrs(radius_km, 90.0 - lat, lon),
            "b_nec": g["B_NEC"][:],
            "b_nec_chaos_vires": g["B_NEC_CHAOS"][:],
        }


@pytest.fixture(scope="module")
def chaos7(authorities: Path) -> chaosmagpy.CHAOS:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return chaosmagpy.load_CHAOS_matfile(str(authorities / "CHAOS-7.mat"))


def _low_lat_mean(storm: dict[str, np.ndarray], model: np.ndarray) -> np.ndarray:
    low = np.abs(storm["lat"]) < 40.0
    return np.mean((storm["b_nec"] - model)[low], axis=0)


def test_igrf14_leaves_the_known_storm_residual(storm: dict[str, np.ndarray]) -> None:
    b = reference_field_nec_nt(storm["t"], storm["r_itrs_km"], field="IGRF-14")
    mean = _low_lat_mean(storm, b)  # measured [-165.97, -6.04, -11.18]
    np.testing.assert_allclose(mean, [-166.0, -6.0, -11.0], atol=1.0)


def test_rc_model_matches_chaosmagpy_chaos7_external(
    storm: dict[str, np.ndarray], chaos7: chaosmagpy.CHAOS
) -> None:
    mjd = utc_s_to_mjd2000(storm["t"])
    colat = 90.0 - storm["lat"]
    ref = np.zeros_like(storm["b_nec"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # chaosmagpy's RC-file notice
        for synth in (chaos7.synth_values_sm, chaos7.synth_values_gsm):
            b_r, b_t, b_p = synth(mjd, storm["radius_km"], colat, storm["lon"])
            ref += np.stack([-b_t, b_p, -b_r], axis=-1)
    ours = get_field("RC").b_nec_nt(storm["t"], storm["radius_km"], colat, storm["lon"])
    # the storm field itself is ~100 nT; the terms orbitcal leaves out (baseline corrections,
    # degree 2, induced GSM) are each below 2 nT: measured max |diff| 4.5 nT, rms <= 3.1 nT
    assert np.sqrt(np.mean(ref[:, 0] ** 2)) > 80.0
    assert np.abs(ours - ref).max() < 6.0
    assert np.sqrt(np.mean((ours - ref) ** 2, axis=0)).max() < 4.0


def test_chaos_core_crust_rc_explain_most_of_the_storm_residual(
    storm: dict[str, np.ndarray], chaos7: chaosmagpy.CHAOS
) -> None:
    b = reference_field_nec_nt(
        storm["t"], storm["r_itrs_km"], field="CHAOS-8.1+CHAOS-8.1-static+RC"
    )
    mean = _low_lat_mean(storm, b)  # measured [-45.68, -2.43, -8.46]
    assert -50.0 < mean[0] < -40.0
    assert abs(mean[1]) < 5.0 and abs(mean[2]) < 12.0
    # ChaosMagPy's complete CHAOS-7 (core + static + external) leaves the same N residual
    mjd = utc_s_to_mjd2000(storm["t"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        b_r, b_t, b_p = chaos7(mjd, storm["radius_km"], 90.0 - storm["lat"], storm["lon"])
    chaos7_mean = _low_lat_mean(storm, np.stack([-b_t, b_p, -b_r], axis=-1))  # [-45.95, ...]
    assert abs(mean[0] - chaos7_mean[0]) < 2.0
    # the gap to VirES's CHAOS column, recorded (see the module docstring)
    vires_mean = _low_lat_mean(storm, storm["b_nec_chaos_vires"])
    np.testing.assert_allclose(vires_mean, [-12.2, -0.6, -7.1], atol=0.5)
    assert 25.0 < vires_mean[0] - mean[0] < 40.0
