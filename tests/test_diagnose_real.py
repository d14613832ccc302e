"""The diagnosis on real data: the Swarm A storm pass, real TLE orbit errors, a real crust (MF7).

* Swarm A MAG_LR_1B, 2016-01-01 00:00-00:30 (``authorities/test_fac_singlesat_swarm.nc4``; storm,
  RC about -129 nT, Kp 6, southern auroral crossing): its *measured* B_NEC is put through a
  synthetic tumbling attitude and sensor; the diagnosis sees raw counts and IGRF-14 only.
* Orbit error: the truth is propagated from a later real Swarm A TLE, the diagnosis is given the
  older one (``authorities/swarm_iss_real_tles.tle``).
* Crust: the world's crust is MF7 (Maus), the diagnosis offers LCS-1 (Olsen et al. 2017).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from shared_worlds import swarm_class_sensor

from orbitcal import frames
from orbitcal.diagnose.api import diagnose_data, diagnosis_data
from orbitcal.diagnose.effects import DiagnosisData
from orbitcal.diagnose.options import AttributionOptions, DiagnosisOptions
from orbitcal.diagnose.prepare import field_body_nt
from orbitcal.diagnose.prior import CalibrationPrior

AUTH = Path(__file__).parent / "authorities"
SWARM_EPOCH_UTC_S = 1451606400.0  # 2016-01-01T00:00:00Z, the file's Timestamp origin


pytestmark = pytest.mark.usefixtures("single_thread_blas")  # tests/conftest.py


#: The synthetic sensor of the storm pass: 1 % matrix errors, 100 nT offsets, 1 nT noise.
_STORM_RNG_SEED = 5


def _diagnose_parts(
    data: DiagnosisData,
    *,
    learned: bool = True,
    holdout_blocks: int = AttributionOptions().holdout_blocks,
    fit_mask: np.ndarray | None = None,
    rng: np.random.Generator | None = None,
) -> tuple[dict[str, Any], Any]:
    """The report (as JSON) and the attribution of :func:`orbitcal.diagnose.diagnose_data`."""
    options = DiagnosisOptions(
        learned=learned, attribution=AttributionOptions(holdout_blocks=holdout_blocks)
    )
    diagnosis = diagnose_data(data, options=options, rng=rng, fit_mask=fit_mask)
    return diagnosis.report.to_json(), diagnosis.attribution


def _storm_sensor() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(_STORM_RNG_SEED)
    return np.eye(3) + rng.normal(scale=0.01, size=(3, 3)), rng.normal(scale=100.0, size=3)


def _quiet_day_calibration() -> dict[str, object]:
    """The calibration in service before the storm: the same sensor, one quiet day, linear fit.

    The quiet day is a simulated Swarm A day (real TLE) whose truth holds what a quiet calibration
    cannot model either -- the MF7 crust and a -20 nT uniform magnetospheric field -- so the prior
    is imperfect as real ones are (its offsets come out ~10 nT off: the spin axis is fixed, and a
    uniform field's part along it looks like an offset).
    """
    from orbitcal.orbit import Orbit
    from orbitcal.pipeline import calibrate_telemetry
    from orbitcal.sensor import SensorModel
    from orbitcal.simulate import Tumbling, make_effect, simulate_world

    a, o = _storm_sensor()
    tle = _swarm_tles()[0]
    world = simulate_world(
        tle,  # type: ignore[arg-type]
        start_utc_s=tle.epoch_utc_s + 3600.0,  # type: ignore[attr-defined]
        duration_s=86400.0,
        cadence_s=10.0,
        rng=np.random.default_rng(11),
        attitude=Tumbling(),
        sensor=SensorModel(a_matrix=a, bias_nt=o, noise_std_nt=1.0),
        effects=[
            make_effect("crustal_field", model="MF7"),
            make_effect("external_field", amplitude_nt=-20.0),
        ],
    )
    _, doc = calibrate_telemetry(
        world.telemetry,
        orbit=Orbit.from_tle(tle.text),  # type: ignore[attr-defined]
        method="linear",
        rng=np.random.default_rng(0),
    )
    return doc


def _swarm_storm_data(
    prior: CalibrationPrior | None = None,
) -> tuple[DiagnosisData, np.ndarray, np.ndarray]:
    from orbitcal.field.external import ring_current_field
    from orbitcal.sun import illumination_conical, sun_position_gcrs_km
    from orbitcal.truth import reference_field_itrs_nt

    with h5py.File(AUTH / "test_fac_singlesat_swarm.nc4") as f:
        g = f["SW_OPER_MAGA_LR_1B"]
        t = SWARM_EPOCH_UTC_S + g["Timestamp"][:].astype(float)
        lat = g["Latitude"][:]
        lon = g["Longitude"][:]
        radius_km = g["Radius"][:] / 1000.0
        b_nec = g["B_NEC"][:]
    r = frames.spherical_to_itrs(radius_km, 90.0 - lat, lon)
    b_meas_itrs = frames.nec_to_itrs(b_nec, r)
    a, o = _storm_sensor()
    rng = np.random.default_rng(_STORM_RNG_SEED + 1)
    # Synthetic attitude (steady spin, ITRS frame) and the sensor.
    rot = (
        (
            Rotation.from_rotvec(np.outer(t - t[0], np.radians([0.6, -1.1, 1.4])))
            * Rotation.from_euler("xyz", [0.4, 0.1, -0.3])
        )
        .inv()
        .as_matrix()
    )
    b_true_body = np.einsum("nij,nj->ni", rot, b_meas_itrs)
    b_raw = b_true_body @ a.T + o + rng.normal(scale=1.0, size=b_true_body.shape)
    b_ref_body = np.einsum("nij,nj->ni", rot, reference_field_itrs_nt(t, r, field="IGRF-14"))
    r_gcrs = frames.itrs_to_gcrs(r, t)
    sun = sun_position_gcrs_km(t)
    s = sun - r_gcrs
    s_itrs = frames.gcrs_to_itrs(s / np.linalg.norm(s, axis=1, keepdims=True), t)
    ill = illumination_conical(r_gcrs, sun)
    rc_e, rc_i = ring_current_field().rc_nt(t)
    data = DiagnosisData(
        t_utc_s=t,
        b_raw_nt=b_raw,
        b_ref_body_nt=b_ref_body,
        rot_itrs_to_body=rot,
        r_itrs_km=r,
        sunlit=ill > 0.5,
        illumination=ill,
        sun_body=np.einsum("nij,nj->ni", rot, s_itrs),
        rc_index_nt=rc_e + rc_i,
        b_ext_body_nt=field_body_nt("RC", t, r, rot),
        b_crust_body_nt=field_body_nt("LCS-1", t, r, rot),
        crust_model="LCS-1",
        calibration_prior=prior,
        positions_measured=True,  # Swarm's GPS positions
    )
    return data, lat, rot


def _low_latitude_nec(
    data: DiagnosisData, residual: np.ndarray, rot: np.ndarray, mask: np.ndarray
) -> np.ndarray:
    nec = frames.itrs_to_nec(np.einsum("nji,nj->ni", rot, residual), data.r_itrs_km)
    return np.asarray(nec[mask])


def test_swarm_storm_pass_external_field_and_auroral_currents() -> None:
    from orbitcal.diagnose.prior import prior_from_document

    doc = _quiet_day_calibration()
    data, lat, rot = _swarm_storm_data(prior_from_document(doc))
    amlat = np.abs(data.mlat_deg)
    # 30 min only: the last 20 % is held out; fits use quiet |magnetic latitude| < 50 deg, as
    # Swarm processing does (the auroral crossing would otherwise drag the 12 parameters).
    report, att = _diagnose_parts(data, learned=False, holdout_blocks=2, fit_mask=amlat < 50.0)
    assert report["baseline"]["calibration_prior"]["source"].startswith("calibration document")
    assert report["verdict"] == "external_field"
    ext = report["effects"][0]
    assert ext["name"] == "external_field" and ext["significant"] and ext["shrink"] > 4.0

    # Where: with the ring current modelled, what is left lies at high magnetic latitude,
    # perpendicular to B.
    where = report["final"]["where"]
    assert where["concentration"].startswith("|mlat|")
    lo_band = float(where["concentration"].split()[1].split("-")[0])
    assert lo_band >= 50.0
    high = [b for b in where["magnetic_latitude"] if b["band_deg"][0] >= 50.0]
    quiet = [b for b in where["magnetic_latitude"] if b["band_deg"][1] <= 50.0]
    assert max(b["rms_nt"] for b in high) > 3.0 * max(b["rms_nt"] for b in quiet)
    assert all(b["perpendicular_rms_nt"] > 1.5 * b["scalar_rms_nt"] for b in high)
    # ... and is attributed to field-aligned currents.
    fac = {e["name"]: e for e in report["effects"]}["field_aligned_currents"]
    assert fac["significant"], fac

    # The low-latitude residual against IGRF-14 on the held-out samples, NEC: the calibration
    # alone leaves most of the storm's ring current (measured: mean [-99, 45, -41] nT; the data
    # README gives -166 nT in N for the measured field itself, and the prior cannot stop the
    # calibration-only fit absorbing some of it). With the external field (the RC-driven model
    # scaled by 1.26, a uniform -22.5 nT and a within-hour trend: the RC index is hourly) the mean
    # is [4.8, -6.9, -10.0] nT, rms [7.2, 7.3, 10.8] -- within the 15 nT the issue asks; over
    # sensor seeds 1-6 the worst component was 11.4 nT.
    low = (np.abs(lat) < 40.0) & att.holdout
    before = _low_latitude_nec(data, att.baseline_residual_nt, rot, low).mean(axis=0)
    after = _low_latitude_nec(data, att.final_residual_nt, rot, low).mean(axis=0)
    print("low-latitude held-out mean NEC [nT]: calibration only", before.round(1), "with", after)
    assert before[0] < -80.0
    assert np.all(np.abs(after) <= 15.0)


def test_swarm_storm_pass_without_a_prior() -> None:
    """Without the calibration in service the 30-minute joint fit is ill-posed in one direction.

    The ring current at low latitude is nearly parallel to the main field, so a free scale factor
    absorbs part of it. With the parameters held to their physical ranges (the RC model's scale
    near its published 1, no crust turned upside down, no ring current changing by thousands of
    nT per hour) the verdict is external_field, the auroral currents are significant, nothing
    else is named, and the report says the ring current's size is not separable from the
    calibration on 30 minutes (what would: a prior calibration, a longer span). Measured: RC model
    x 1.13 and a uniform -50.5 nT; low-latitude held-out mean [30.0, -14.8, -6.4] nT (N, E, C)
    against [-62, 88, -60] for the calibration alone ([4.8, -6.9, -10.0] with the prior).
    """
    from orbitcal.diagnose.effects import effect_param_range

    data, lat, rot = _swarm_storm_data()
    report, att = _diagnose_parts(
        data, learned=False, holdout_blocks=2, fit_mask=np.abs(data.mlat_deg) < 50.0
    )
    assert report["verdict"] == "external_field"
    assert report["baseline"]["calibration_prior"] is None
    by_name = {e["name"]: e for e in report["effects"]}
    assert by_name["external_field"]["significant"]
    assert by_name["field_aligned_currents"]["significant"]
    assert set(report["final"]["effects"]) <= {"external_field", "field_aligned_currents"}
    # Every reported parameter inside its physical range, with an interval inside it too.
    for e in report["effects"]:
        if e["name"] != "field_aligned_currents":  # the regional test reports RMS values only
            assert set(e["param_intervals_90"]) == {
                k for k, v in e["params"].items() if isinstance(v, float)
            }
        for name, (lo, hi) in e["param_intervals_90"].items():
            value = e["params"][name]
            rng = effect_param_range(e["name"], name)
            assert rng.contains(value), (e["name"], name, value)
            assert rng.lower <= lo <= value + 1e-3 and value - 1e-3 <= hi <= rng.upper
    ext = by_name["external_field"]["params"]
    assert 0.5 < ext["rc_model_scale"] < 2.0
    # The crust candidate, which once fitted LCS-1 x -15, is implausible or inside its range.
    crust = by_name["crustal_field"]
    assert crust["status"] == "implausible" or crust["params"]["crust_scale"] > 0.3
    # The size of the ring current is not separable from the calibration on 30 minutes.
    sep = {s["effect"]: s for s in report["separation"]}
    assert "prior calibration" in sep["external_field"]["would_separate"]
    assert report["verdict_status"].startswith("tentative")
    assert 0.5 < report["verdict_confidence"] <= 1.0
    low = (np.abs(lat) < 40.0) & att.holdout
    before = _low_latitude_nec(data, att.baseline_residual_nt, rot, low).mean(axis=0)
    after = _low_latitude_nec(data, att.final_residual_nt, rot, low).mean(axis=0)
    print("low-latitude held-out mean NEC [nT] without a prior:", before.round(1), after.round(1))
    assert before[0] < -50.0
    assert 8.0 < abs(float(after[0])) < 166.0 / 4


def _swarm_tles() -> list[object]:
    from orbitcal.simulate import parse_tles

    sets = parse_tles((AUTH / "swarm_iss_real_tles.tle").read_text())
    return sorted((s for s in sets if s.norad_id == 39452), key=lambda s: s.epoch_utc_s)


@pytest.mark.parametrize("attitude", ["tumbling", "nadir"])
def test_real_orbit_error_from_an_older_tle(attitude: str) -> None:
    """A week-old Swarm A element set against a later one: the whole RTN error is recovered.

    The true difference (later minus older set, over the 4 orbits): along track 7.24 km mean
    with a +-2 km once-per-revolution term, radial +-0.95 km, cross track +-0.19 km. Measured:
    along track 7.19 km (tumbling) / 7.12 km (nadir), held-out residual 58.4 -> 3.72 nT and
    30.4 -> 3.56 nT (noise floor 3.46 nT), radial amplitude 0.98 / 0.93 km, along-track
    amplitude 1.96 / 1.97 km.
    """
    from orbitcal.orbit import Orbit
    from orbitcal.simulate import NadirLVLH, Tumbling, make_effect, simulate_world

    sets = _swarm_tles()
    old = sets[0]  # epoch 2022-08-01 (22213.52)
    new = next(s for s in sets if s.epoch_utc_s > old.epoch_utc_s + 6 * 86400)  # type: ignore[attr-defined]
    world = simulate_world(
        old,  # type: ignore[arg-type]
        start_utc_s=new.epoch_utc_s,  # type: ignore[attr-defined]
        duration_s=4 * 5650.0,
        cadence_s=10.0,
        rng=np.random.default_rng(8),
        attitude=Tumbling() if attitude == "tumbling" else NadirLVLH(),
        effects=[make_effect("orbit_error", true_tle=new.text)],  # type: ignore[attr-defined]
    )
    truth_km = world.truth["effects"][0]["info"]["along_track_km_mean"]
    assert abs(truth_km) > 1.0  # a week-old element set is km off along track
    options = DiagnosisOptions(crust_model=None)
    orbit = Orbit.from_tle(old.text)  # type: ignore[attr-defined]
    data = diagnosis_data(world.telemetry, orbit=orbit, options=options)
    report, att = _diagnose_parts(data, learned=False)
    assert report["verdict"] == "orbit_error"
    assert report["final"]["effects"] == ["orbit_error"]
    top = report["effects"][0]
    params = top["params"]
    assert params["variant"] == "rtn"
    # Along-track error over the world: the model's constant (at the training centre) plus its
    # growth rate, averaged over every sample (the once-per-rev terms average out).
    tau_d = (data.t_utc_s - data.t_utc_s[att.train].mean()) / 86400.0
    est = params["along_track_km"] + params.get("along_track_rate_km_per_day", 0.0) * tau_d
    assert float(np.mean(est)) == pytest.approx(truth_km, rel=0.05)
    radial_amp = np.hypot(params["radial_cos_km"], params["radial_sin_km"])
    along_amp = np.hypot(params["along_track_cos_km"], params["along_track_sin_km"])
    assert radial_amp == pytest.approx(0.95, abs=0.15)
    assert along_amp == pytest.approx(2.0 * radial_amp, rel=0.2)  # eccentricity error: 2:1
    assert top["holdout_rms_after_nt"] < 1.15 * 2.0  # noise 2 nT per axis (per component)


def test_real_crust_mf7_found_with_lcs1() -> None:
    from orbitcal.orbit import Orbit
    from orbitcal.simulate import Tumbling, make_effect, simulate_world

    sets = _swarm_tles()
    tle = sets[-1]
    rng = np.random.default_rng(9)
    sensor = swarm_class_sensor(rng)  # tests/shared_worlds.py
    world = simulate_world(
        tle,  # type: ignore[arg-type]
        start_utc_s=tle.epoch_utc_s + 3600.0,  # type: ignore[attr-defined]
        duration_s=5 * 5650.0,
        cadence_s=10.0,
        rng=rng,
        attitude=Tumbling(),
        sensor=sensor,
        effects=[make_effect("crustal_field", model="MF7")],
    )
    data = diagnosis_data(world.telemetry, orbit=Orbit.from_tle(tle.text))  # type: ignore[attr-defined]
    assert data.crust_model == "LCS-1"
    report, _ = _diagnose_parts(data, rng=np.random.default_rng(0))
    assert report["verdict"] == "crustal_field"
    crust = report["effects"][0]
    assert crust["shrink"] > 1.3
    assert 0.5 < crust["params"]["crust_scale"] < 1.5  # LCS-1 stands for MF7 nearly one to one
    # The seed-003 learned model is reported with its own held-out score.
    assert report["learned"]["holdout_rms_after_nt"] > 0.0


@pytest.mark.slow
def test_swarm_storm_pass_through_the_public_entry_with_defaults(tmp_path: Path) -> None:
    """Issue 25: the storm pass as a user gives it -- a section-1 table (ITRS quaternions,
    Swarm's GPS positions) read by :func:`orbitcal.api.read_table` and diagnosed by
    :func:`orbitcal.api.diagnose_table` with its defaults, no prior, no fit mask, no held-out
    blocks chosen by hand. The diagnosis chooses both itself from the data, and what it claims
    holds on the held-out blocks: no model worse than the calibration alone, nothing named but
    the external field and the auroral currents, and a verdict of none only with the gap
    stated."""
    from orbitcal.api import diagnose_table, read_table

    data, _, rot = _swarm_storm_data()
    q = Rotation.from_matrix(np.transpose(rot, (0, 2, 1))).as_quat()  # body -> ITRS, x y z w
    table = tmp_path / "pass.csv"
    cols = np.column_stack([data.t_utc_s, data.b_raw_nt, q[:, [3, 0, 1, 2]], data.r_itrs_km])
    header = "time,b_x,b_y,b_z,q_w,q_x,q_y,q_z,r_x,r_y,r_z"
    np.savetxt(table, cols, delimiter=",", header=header, comments="", fmt="%.10g")
    report = diagnose_table(read_table(table), attitude_frame="ITRS")
    chosen = " ".join(report["data"]["chosen_from_data"])
    assert "shorter than an orbit" in chosen and "auroral latitudes" in chosen, chosen
    assert report["final"]["holdout_rms_nt"] <= report["baseline"]["holdout_rms_nt"]
    significant = {e["name"] for e in report["effects"] if e["significant"]}
    assert significant <= {"external_field", "field_aligned_currents"}, report["verdict_status"]
    gap = report["gap"]
    assert gap["noise_floor_nt"] == pytest.approx(1.0, rel=0.3)  # the sensor's 1 nT
    if report["verdict"] == "none":
        assert gap["unexplained"] and report["verdict_confidence"] is None
        assert report["verdict_status"].startswith("none: an unexplained gap")
    else:
        assert report["verdict"] == "external_field"
    for e in report["effects"]:
        assert set(e["param_bound_limited"]) == set(e["param_intervals_90"])
