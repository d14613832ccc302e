"""Issue 25: the real Swarm A storm pass through ``orbitcal diagnose``, as a user runs it.

The measured B_NEC of Swarm A (2016-01-01 00:00-00:30, a storm: ring current about -160 nT at low
latitude, auroral currents; ``tests/authorities/test_fac_singlesat_swarm.nc4``) is turned into a
section-1 table through a drawn sensor and a drawn attitude -- a tumble, and nadir pointing, under
which a uniform external field is a change of scale the 12 parameters take whole -- and diagnosed
by the command line with its defaults and no prior. The pass's effects are the external field and
the auroral currents; nothing else may be called significant, the final model may never be worse
than the calibration alone on the held-out blocks, and the verdict is the external field or an
explicit "cannot be separated from the calibration on this span" naming it.

The same construction with 20 draws of each attitude is ``benchmarks/independent/real_pass.py``
(rates in ``benchmarks/results/diagnose_independent.md``); here two fixed draws of each.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from orbitcal import frames
from orbitcal.cli import main

AUTH = Path(__file__).parent / "authorities"
SWARM_EPOCH_UTC_S = 1451606400.0  # 2016-01-01T00:00:00Z
ALLOWED = {"external_field", "field_aligned_currents"}


def _pass() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    with h5py.File(AUTH / "test_fac_singlesat_swarm.nc4") as f:
        g = f["SW_OPER_MAGA_LR_1B"]
        t = SWARM_EPOCH_UTC_S + g["Timestamp"][:].astype(float)
        r = frames.spherical_to_itrs(
            g["Radius"][:] / 1000.0, 90.0 - g["Latitude"][:], g["Longitude"][:]
        )
        b_itrs = frames.nec_to_itrs(np.asarray(g["B_NEC"][:], dtype=float), r)
    return t, r, b_itrs


def _attitude(
    kind: str, t: np.ndarray, r: np.ndarray, rng: np.random.Generator, rate_deg_s: float = 1.0
) -> Rotation:
    """Body -> ITRS: a spin at ``rate_deg_s`` about a random axis, or LVLH (z to nadir, x along
    track) with a mounting rotation of a few degrees."""
    if kind == "tumbling":
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        spin = Rotation.from_rotvec(np.outer(np.radians(rate_deg_s) * (t - t[0]), axis))
        return Rotation.random(random_state=int(rng.integers(1 << 31))) * spin
    v = np.gradient(r, t, axis=0)
    z = -r / np.linalg.norm(r, axis=1, keepdims=True)
    y = np.cross(z, v)
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    m = np.stack([np.cross(y, z), y, z], axis=2)
    return Rotation.from_matrix(m) * Rotation.from_rotvec(np.radians(rng.uniform(-5, 5, size=3)))


def _table(path: Path, kind: str, seed: int, rate_deg_s: float = 1.0) -> None:
    t, r, b_itrs = _pass()
    rng = np.random.default_rng(seed)
    a = np.eye(3) + rng.normal(scale=rng.uniform(0.005, 0.03), size=(3, 3))
    offset = rng.uniform(50.0, 500.0, size=3) * rng.choice([-1.0, 1.0], size=3)
    noise = rng.uniform(0.5, 2.0)
    rot = _attitude(kind, t, r, rng, rate_deg_s)
    raw = rot.inv().apply(b_itrs) @ a.T + offset + rng.normal(scale=noise, size=b_itrs.shape)
    q = rot.as_quat()  # x, y, z, w
    cols = np.column_stack([t, raw, q[:, [3, 0, 1, 2]], r])
    header = "time,b_x,b_y,b_z,q_w,q_x,q_y,q_z,r_x,r_y,r_z"
    np.savetxt(path, cols, delimiter=",", header=header, comments="", fmt="%.17g")


def _diagnosed(tmp_path: Path, kind: str, seed: int, rate_deg_s: float = 1.0) -> dict[str, Any]:
    """``orbitcal diagnose``'s report (defaults, no prior) on the pass through draw ``seed``."""
    table, out = tmp_path / "pass.csv", tmp_path / "report.json"
    _table(table, kind, seed, rate_deg_s)
    assert main(["diagnose", str(table), "--attitude-frame", "ITRS", "--out", str(out)]) == 0
    report: dict[str, Any] = json.loads(out.read_text())
    return report


@pytest.mark.slow
@pytest.mark.parametrize(
    ("kind", "seed"), [("tumbling", 3101), ("tumbling", 3102), ("nadir", 3201), ("nadir", 3202)]
)
def test_the_storm_pass_through_the_command_line(tmp_path: Path, kind: str, seed: int) -> None:
    report = _diagnosed(tmp_path, kind, seed)
    status = report["verdict_status"]
    significant = {e["name"] for e in report["effects"] if e["significant"]}
    assert significant <= ALLOWED, status
    assert report["final"]["holdout_rms_nt"] <= report["baseline"]["holdout_rms_nt"] + 1e-9
    explicit = (
        "cannot be separated from the calibration on this span" in status
        and "external_field" in status
    )
    # Tumbling: the external field, the auroral currents, or "none" with the gap stated (on the
    # benchmark's 20 tumbling draws the external field or the explicit statement in 15; the
    # others are such a "none": the external field's template needs a ring-current change the
    # physics does not allow, and the report says so).
    assert report["verdict"] in {"external_field", "field_aligned_currents", "none"}, status
    if report["verdict"] == "none":
        assert report["gap"]["unexplained"] and report["verdict_confidence"] is None
        assert status.startswith("none: ") and "x the noise floor" in status
    if kind == "nadir":
        # Under nadir pointing every candidate but the crust is >= 99 % a change of the 12
        # parameters on this span: nothing can be named, and the report says what would decide.
        assert explicit, status
        assert "prior calibration" in status


@pytest.mark.slow
@pytest.mark.parametrize(
    ("seed", "small", "status", "verdict"),
    [
        (3314, "nonlinearity", "immaterial", "external_field"),
        # Until the external field's forms were kept within their ranges on short spans its
        # trend ran out of range here, the verdict was "none" and the time offset was withdrawn
        # as immaterial; now the external field's constant is named (held-out 173 -> 99 nT) and
        # the time offset beside it is a possible residue.
        (3317, "time_offset", "possible residue", "external_field"),
    ],
)
def test_a_small_gain_beside_a_large_gap_is_not_named(
    tmp_path: Path, seed: int, small: str, status: str, verdict: str
) -> None:
    # A slow tumble (0.3 deg/s: half a turn in the 30 minutes): the held-out residual stays
    # 50-100 x the noise floor whatever is fitted, and a flexible effect that removes a few per
    # cent of it was named (drawn after the rule was written: seeds 3300-3329, the two it acts on).
    report = _diagnosed(tmp_path, "tumbling", seed, rate_deg_s=0.3)
    by_name = {e["name"]: e for e in report["effects"]}
    if status == "immaterial":
        assert report["honesty"]["immaterial"] == [small]
    else:
        assert small in report["honesty"]["possible_residue"]
    assert by_name[small]["significant"] is False
    assert by_name[small]["status"] == status
    assert report["verdict"] == verdict
    assert {e["name"] for e in report["effects"] if e["significant"]} <= ALLOWED
    assert report["gap"]["unexplained"] and report["gap"]["times_noise"] > 10.0
    if verdict == "none":
        assert report["verdict_status"].startswith("none: ")
        assert report["verdict_confidence"] is None


@pytest.mark.slow
def test_a_time_offset_beside_the_external_field_on_a_short_span_is_a_possible_residue(
    tmp_path: Path,
) -> None:
    # On a span shorter than an orbit a time shift bends any smooth misfit a little: beside the
    # external field it must explain what an imperfect model of the field cannot (the residue
    # test). Drawn after the rule was written (seeds 3300-3329 at 0.3 deg/s).
    report = _diagnosed(tmp_path, "tumbling", 3316, rate_deg_s=0.3)
    residues = {r["effect"] for r in report["honesty"]["residue_tests"] if r["possible_residue"]}
    assert "time_offset" in residues
    assert report["verdict"] == "external_field"
    assert {e["name"] for e in report["effects"] if e["significant"]} <= ALLOWED


@pytest.mark.slow
@pytest.mark.parametrize("seed", [3303])  # 3320 too, until its external field was named
def test_a_gap_the_calibration_extrapolation_makes_is_said_to_be_inseparable(
    tmp_path: Path, seed: int
) -> None:
    # A slow tumble: the 12 parameters fitted on the first 80 % extrapolate badly; fitted with
    # the held-out blocks too they remove most of the held-out residual. The report says the gap
    # cannot be separated from the calibration on this span, with the closest candidates.
    report = _diagnosed(tmp_path, "tumbling", seed, rate_deg_s=0.3)
    extrapolation = report["gap"]["calibration_extrapolation"]
    assert extrapolation["share_of_holdout_mean_square"] >= 0.5
    assert extrapolation["holdout_rms_refit_nt"] < report["gap"]["holdout_rms_nt"]
    status = report["verdict_status"]
    assert report["verdict"] in ALLOWED | {"none"}
    assert "cannot be separated from the calibration on this span" in status
    assert "extrapolation error" in status
    assert all(c["name"] in status for c in report["gap"]["closest_candidates"])
    assert report["verdict_confidence"] is None
    assert {e["name"] for e in report["effects"] if e["significant"]} <= ALLOWED


@pytest.mark.slow
@pytest.mark.parametrize(("seed", "rate_deg_s"), [(3404, 2.5), (3320, 0.3)])
def test_the_external_field_named_by_its_constant_when_its_trend_leaves_the_physics(
    tmp_path: Path, seed: int, rate_deg_s: float
) -> None:
    # On the quiet latitudes of the pass the training BIC preferred a form of the external field
    # with a change the ring current cannot have (beyond 300 nT/h: a trend taking up the latitude
    # structure along the one track), the field was refused whole as implausible, and a
    # nonlinearity (3404, a fast tumble) or "none" with the gap said to be the calibration's
    # extrapolation (3320, a slow one) stood in its place. The forms within the physical ranges
    # are tried first now (3404 drawn after the rule was written: seeds 3400-3411 at 1 deg/s
    # changed the chosen form in 3 of 12, and this is the one at 2.5 deg/s whose verdict moved;
    # 3320 is an earlier test's draw, held-out 157 -> 72 nT with the constant).
    report = _diagnosed(tmp_path, "tumbling", seed, rate_deg_s=rate_deg_s)
    by_name = {e["name"]: e for e in report["effects"]}
    external = by_name["external_field"]
    assert report["verdict"] == "external_field", report["verdict_status"]
    assert external["status"] == "selected" and external["implausible_reason"] is None
    assert {e["name"] for e in report["effects"] if e["significant"]} <= ALLOWED
    assert report["final"]["holdout_rms_nt"] < report["baseline"]["holdout_rms_nt"]


@pytest.mark.slow
@pytest.mark.parametrize(("seed", "rate_deg_s"), [(3517, 1.0), (3522, 1.5)])
def test_a_sun_driven_field_without_an_eclipse_gives_way_to_the_external_field(
    tmp_path: Path, seed: int, rate_deg_s: float
) -> None:
    # The pass is lit throughout and shorter than an orbit: the Sun-driven template's one
    # signature (on when lit, off in eclipse) is absent, and what it draws is a field fixed in
    # space, the ring current's among them. The report said so and still named it significant
    # (3522: the verdict, "tentative"; 3517: withdrawn as overshadowed). Drawn after the rule was
    # written: seeds 3500-3523, the two where it acts. Withdrawn, it left the verdict to the
    # currents with 27 (7.9) nT more held out than its model; the external field, significant on
    # its own and a field fixed in space, now stands in for it (held-out 74.6 -> 22.7 nT, 78.8 ->
    # 12.0 nT; fresh draws 3400 no. 8 and 3300 no. 17 had lost the external field this way).
    report = _diagnosed(tmp_path, "tumbling", seed, rate_deg_s=rate_deg_s)
    by_name = {e["name"]: e for e in report["effects"]}
    sun = by_name["sun_driven"]
    assert report["honesty"]["unlit"] == ["sun_driven"]
    assert sun["significant"] is False and sun["status"] == "unlit"
    assert "no eclipse" in sun["unlit_reason"] and "external_field" in sun["unlit_reason"]
    assert report["verdict"] == "external_field", report["verdict_status"]
    assert report["honesty"]["stood_in"] == ["external_field"]
    external = by_name["external_field"]
    assert external["significant"] and external["stands_in_for"] == ["sun_driven"]
    assert {e["name"] for e in report["effects"] if e["significant"]} <= ALLOWED
    # the gap no longer says a field fixed in space may take it up: the model holds one now
    assert "a field fixed in space" not in report["gap"]["statement"]
    refused = {c["name"]: c["refused_because"] for c in report["gap"]["closest_candidates"]}
    assert refused.get("sun_driven", "not the Sun's").startswith("not the Sun's")
    assert report["final"]["holdout_rms_nt"] < 0.4 * report["baseline"]["holdout_rms_nt"]
