"""An along-track error of hundreds of km, and the orbit error's ranges for an old element set.

Independent worlds built from real ISS element sets 2-8 days apart had their orbit error refused
as implausible (97-725 km off, drifting at 197-580 km/day after a reboost): the first-order form
missed the second-order term and took it up in radial and cross-track terms beyond their ranges,
and the ranges were those of a fresh, drag-only element set.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from shared_worlds import simulated_report

from orbitcal.diagnose.data import DiagnosisData
from orbitcal.diagnose.effects import effect_param_range, get_effect
from orbitcal.diagnose.orbit_shift import moved_along_arc


def _circular(n: int = 600, step_s: float = 10.0) -> DiagnosisData:
    """A circular polar orbit 450 km up, inertially fixed plane, ITRS positions."""
    t = 1.7e9 + step_s * np.arange(n)
    radius = 6371.2 + 450.0
    u = 2.0 * np.pi * (t - t[0]) / 5640.0
    r_in = radius * np.column_stack([np.cos(u), np.zeros(n), np.sin(u)])
    theta = 7.292115e-5 * (t - t[0])  # the Earth turns under it
    c, s = np.cos(theta), np.sin(theta)
    r = np.column_stack(
        [c * r_in[:, 0] + s * r_in[:, 1], -s * r_in[:, 0] + c * r_in[:, 1], r_in[:, 2]]
    )
    b = np.tile([20000.0, 0.0, 30000.0], (n, 1))
    return DiagnosisData(
        t_utc_s=t,
        b_raw_nt=b,
        b_ref_body_nt=b,
        rot_itrs_to_body=np.tile(np.eye(3), (n, 1, 1)),
        r_itrs_km=r,
    )


def test_positions_move_along_the_arc_at_the_orbits_radius() -> None:
    data = _circular()
    s_km = 450.0
    moved, frame = moved_along_arc(data, s_km)
    r = data.r_itrs_km
    radius = np.linalg.norm(r, axis=1)
    np.testing.assert_allclose(np.linalg.norm(moved, axis=1), radius, rtol=1e-6)
    angle = np.arccos(np.clip(np.sum(moved * r, axis=1) / radius**2, -1.0, 1.0))
    np.testing.assert_allclose(angle, s_km / radius, rtol=1e-6)
    gram = np.einsum("nik,nil->nkl", frame, frame)
    np.testing.assert_allclose(gram, np.tile(np.eye(3), (data.n, 1, 1)), atol=1e-9)
    np.testing.assert_allclose(frame[:, :, 0], moved / radius[:, None], atol=1e-6)
    # ahead: the moved position is where the inertial motion goes (the Earth held still)
    ahead = np.sum((moved - r) * data.orbit_frame_itrs[:, :, 1], axis=1)
    assert np.all(ahead > 0.99 * s_km)


def test_an_old_element_sets_ranges_widen_with_its_age() -> None:
    fresh = effect_param_range("orbit_error", "along_track_km", 0.05)
    assert (fresh.lower, fresh.upper) == (-100.0, 100.0)  # a manoeuvre: >= 600 km/day x age
    assert effect_param_range("orbit_error", "along_track_km", None) == fresh
    one_day = effect_param_range("orbit_error", "along_track_km", 1.0)
    assert one_day.upper == pytest.approx(600.0)
    eight = effect_param_range("orbit_error", "along_track_km", -8.0)
    assert eight.upper == pytest.approx(max(100.0 * 16.0, 600.0 * 8.0))
    assert "8.0 days from the data" in eight.why
    assert effect_param_range("orbit_error", "radial_km", 8.0).upper == pytest.approx(80.0)
    rate = effect_param_range("orbit_error", "along_track_rate_km_per_day", 8.0)
    assert (rate.lower, rate.upper) == (-600.0, 600.0)
    assert get_effect("orbit_error").param_range("along_track_cos_km", 4.0).upper == 40.0
    # no other effect's ranges know an age
    assert effect_param_range("time_offset", "dt_s", 8.0) == effect_param_range(
        "time_offset", "dt_s"
    )


@pytest.mark.parametrize(("along_km", "attitude"), [(400.0, "tumbling"), (-250.0, "nadir")])
def test_an_orbit_error_of_hundreds_of_km_is_named_and_sized(
    tmp_path: Path, along_km: float, attitude: str
) -> None:
    effect = f"orbit_error:along_track_km={along_km:g}"
    report, truth = simulated_report(tmp_path, effect, attitude=attitude)
    info = next(e for e in truth["effects"] if e["name"] == "orbit_error")["info"]
    assert report["verdict"] == "orbit_error", report["verdict_status"]
    orbit = next(e for e in report["effects"] if e["name"] == "orbit_error")
    assert orbit["params"]["variant"].startswith("rtn_shifted_")
    assert orbit["params"]["along_track_km"] == pytest.approx(info["along_track_km_mean"], rel=2e-3)
    # the element set's age at the middle of the data, from its epoch (YYDDD.DDDDDDDD)
    epoch_doy = float(truth["tle"]["line1"][20:32])
    start_doy = 186.0  # 2023-07-05T00:00:00Z
    expected = start_doy + 0.5 * 22590.0 / 86400.0 - epoch_doy
    assert report["data"]["element_age_days"] == pytest.approx(expected, abs=1e-3)
    # what is left is the noise (2 nT): the form is exact where the spacecraft is
    assert (
        report["final"]["holdout_rms_nt"] < 1.3 * report["gap"]["noise_floor_nt"]
        or not report["gap"]["unexplained"]
    )
    assert report["final"]["holdout_rms_nt"] < 3.0
    assert "remark" not in orbit  # a constant offset: no drift beyond what drag gives
    assert math.isfinite(report["baseline"]["holdout_rms_nt"])


def test_a_drift_faster_than_drag_points_to_a_manoeuvre() -> None:
    from orbitcal.diagnose.report import _remark

    remark = _remark(_score("orbit_error", {"along_track_rate_km_per_day": -226.6}), 6.42)
    assert remark is not None and "-227 km/day" in remark and "6.4 days old" in remark
    assert "manoeuvre" in remark
    assert _remark(_score("orbit_error", {"along_track_rate_km_per_day": 12.0}), 6.4) is None
    assert _remark(_score("time_offset", {"dt_s": 0.5}), None) is None


def _score(name: str, params: dict[str, float]) -> Any:
    from orbitcal.diagnose.attribution import EffectScore

    return EffectScore(
        name=name,
        significant=True,
        holdout_rms_before_nt=10.0,
        holdout_rms_after_nt=2.0,
        p_value=1e-6,
        params=dict(params),
        unique_rms_increase_nt=8.0,
    )
