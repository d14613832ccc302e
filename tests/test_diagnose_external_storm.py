"""The external field of a storm with a main phase and a recovery (Burton et al. 1975).

A ring current that builds up for hours and then recovers is a V in time that neither a linear
trend nor an exponential decay from the start of the data draws; under a nadir attitude the
calibration takes up its constant part and only that change in time shows. Before the storm
variants the diagnosis named nothing, or a Sun-driven field, on every world below (18 of 18;
issue 25: the independent generator's storms were missed in 10 of 14 worlds).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from test_diagnose_worlds import make_world

from orbitcal.diagnose.api import diagnose_data
from orbitcal.diagnose.attribution import fit_joint
from orbitcal.diagnose.attribution.joint_fit import INDEX_TRACKS_BIC, _resolve, _train_bic
from orbitcal.diagnose.data import DiagnosisData
from orbitcal.diagnose.design import (
    STORM_MIN_SPAN_S,
    _design_external,
    _main_phase_h,
    _recovery_from,
)
from orbitcal.geomag import dipole_axis_itrs


def _with_storm(
    attitude: str, seed: int, peak_nt: float, minimum_h: float, recovery_h: float = 6.0
) -> DiagnosisData:
    """A world of :func:`make_world` with a storm of its own shape (linear main phase to the
    minimum, exponential recovery of ``recovery_h``), no RC index."""
    d = make_world("none", attitude=attitude, seed=seed).data
    t_h = (d.t_utc_s - d.t_utc_s[0]) / 3600.0
    dst = np.where(
        t_h < minimum_h,
        peak_nt * t_h / minimum_h,
        peak_nt * np.exp(-(t_h - minimum_h) / recovery_h),
    )
    axis_body = np.einsum("nij,j->ni", d.rot_itrs_to_body, dipole_axis_itrs())
    return dataclasses.replace(d, b_raw_nt=d.b_raw_nt - dst[:, None] * axis_body, rc_index_nt=None)


def test_storm_columns_are_continuous_at_the_minimum() -> None:
    t = np.arange(0.0, 20000.0, 10.0)
    tm = 7200.0
    idx = np.arange(t.size)
    main, rec = _main_phase_h(t, tm, idx), _recovery_from(t, tm, 7.7, idx)
    assert np.all(main[t >= tm] == 0.0) and np.allclose(main[t < tm], (t[t < tm] - tm) / 3600)
    assert np.all(rec[t <= tm] == 1.0)
    after = t > tm
    assert np.allclose(rec[after], np.exp(-(t[after] - tm) / (7.7 * 3600.0)))


def _variants(data: DiagnosisData, train: np.ndarray) -> list[str]:
    block = _design_external(data, train)
    assert block is not None
    return [str(b.variant) for b in (block, *block.alternatives)]


def test_storm_variants_only_over_two_orbits_of_training() -> None:
    d = make_world("none", seed=1).data
    train = np.ones(d.n, dtype=bool)
    block = _design_external(d, train)
    assert block is not None
    storms = [b for b in block.alternatives if str(b.variant).startswith("storm@")]
    assert len(storms) == 9 and all(b.unless_indexed and b.searched == 2 for b in storms)
    short = d.t_utc_s - d.t_utc_s[0] < 0.9 * STORM_MIN_SPAN_S
    assert not any(v.startswith("storm@") for v in _variants(d, short))


def test_where_the_rc_index_follows_the_field_its_shape_is_kept() -> None:
    """A ring current 0.6 x the RC index: the index-driven form beats the first one on training
    BIC by far more than INDEX_TRACKS_BIC, and the storm shapes (which beat the index on training
    by 700 and extrapolated worse) lose the forward check on the training span."""
    w = make_world("external_field", attitude="nadir", seed=3)
    train = np.arange(w.data.n) < int(0.7 * w.data.n)
    block = _design_external(w.data, train)
    assert block is not None
    assert _resolve(w.data, train, [], block).variant == "rc_index"
    # without the index the same world's storm is drawn from the data
    d = dataclasses.replace(w.data, rc_index_nt=None)
    block = _design_external(d, train)
    assert block is not None
    assert str(_resolve(d, train, [], block).variant).startswith(("storm@", "recovery_"))


def test_a_storm_with_a_main_phase_is_named() -> None:
    """18 worlds: minimum at 1, 2 or 3 h of 6.3, recovery of 6 h (the template's grid has 4,
    7.7 and 15 h), three seeds, nadir and tumbling. At 16f6f12 (no storm variants) none of the
    18 named the external field: 7 named nothing, 7 a Sun-driven field, 3 an orbit error, 1 a
    crust beside a magnetorquer."""
    others = []
    for attitude in ("nadir", "tumbling"):
        for seed in (3, 4, 5):
            for minimum_h in (1.0, 2.0, 3.0):
                data = _with_storm(attitude, seed, -90.0, minimum_h)
                report = diagnose_data(data, rng=np.random.default_rng(0)).report.to_json()
                assert report["verdict"] == "external_field"
                ext = next(e for e in report["effects"] if e["name"] == "external_field")
                assert ext["significant"] and ext["params"]["variant"].startswith("storm@")
                # the gap closes to the noise (2 nT per component) once the storm is modelled
                assert report["final"]["holdout_rms_nt"] < 2.6
                assert report["baseline"]["holdout_rms_nt"] > 8.0
                significant = {e["name"] for e in report["effects"] if e["significant"]}
                others += sorted(significant - {"external_field"})
    # what the template's recovery time misses is taken up by another effect in one world of
    # 18 (a magnetorquer: nadir, seed 5, minimum at 3 h)
    assert len(others) <= 1, others


def test_an_index_that_only_resembles_the_storm_gives_way_to_its_shape() -> None:
    """The storm of :func:`_with_storm` beside an RC index of another shape (the world's
    sin-shaped index with a walk): the index beats a constant on training BIC by 750-6,000,
    far more than INDEX_TRACKS_BIC, yet extrapolates worse than the storm's own shape. Until
    the forward check the index's lead kept the storm shapes from being tried (independent
    worlds' synthetic storms beside the real day's RC index: 5 missed on seed 9700)."""
    for attitude in ("nadir", "tumbling"):
        for minimum_h in (1.0, 3.0):
            rc = make_world("none", attitude=attitude, seed=3).data.rc_index_nt
            d = dataclasses.replace(_with_storm(attitude, 3, -90.0, minimum_h), rc_index_nt=rc)
            train = np.arange(d.n) < int(0.7 * d.n)
            block = _design_external(d, train)
            assert block is not None
            rc_form = next(b for b in block.alternatives if b.variant == "rc_index")
            lead = _train_bic(d, train, [block]) - _train_bic(d, train, [rc_form])
            assert lead > 50 * INDEX_TRACKS_BIC
            assert str(_resolve(d, train, [], block).variant).startswith("storm@")


def _holdout_rms_nt(d: DiagnosisData, train: np.ndarray, blocks: list) -> float:
    """RMS per component on the samples outside ``train`` of the joint fit of ``blocks``."""
    fit = fit_joint(d, train, blocks)
    r = (d.b_raw_nt - fit.predict_nt(d))[~train]
    return float(np.sqrt(np.mean(r**2)))


def _burton_storm_with_a_decaying_index(
    attitude: str, seed: int, minimum_h: float
) -> DiagnosisData:
    """A storm of Burton's equation with a constant injection until ``minimum_h`` (the main
    phase saturates towards the minimum) and a recovery of 6 h, beside an hourly index (and an
    RC-model field along the dipole) that only decays through the day: it follows the storm no
    better than a decay without any index does."""
    d = make_world("none", attitude=attitude, seed=seed).data
    t_h = (d.t_utc_s - d.t_utc_s[0]) / 3600.0
    tau_h, peak_nt = 6.0, -120.0
    dst = np.where(
        t_h < minimum_h,
        peak_nt * (1.0 - np.exp(-t_h / tau_h)) / (1.0 - np.exp(-minimum_h / tau_h)),
        peak_nt * np.exp(-(t_h - minimum_h) / tau_h),
    )
    axis_body = np.einsum("nij,j->ni", d.rot_itrs_to_body, dipole_axis_itrs())
    rc = -30.0 * np.exp(-np.floor(t_h) / 6.0)
    return dataclasses.replace(
        d,
        b_raw_nt=d.b_raw_nt - dst[:, None] * axis_body,
        rc_index_nt=rc,
        b_ext_body_nt=-rc[:, None] * axis_body,
    )


def test_an_index_that_leads_only_the_trend_does_not_follow_the_field(monkeypatch) -> None:
    """The index (with a trend) beats the first form, a constant and a trend, by 100-190 in
    training BIC, but a decay without any index beats the index by 3,700-5,000: the index does
    not follow the field, and the storm's shape is chosen by its training BIC with no forward
    check. Until 2026-11-27 a lead over the first form alone sent the storm to the forward check
    on two thirds of the training span; in independent world 12600 no. 13 (minimum at 2.9 h of
    a 4.4 h training span, a temperature beside it) the check kept the decay, which extrapolated
    to 24.9 nT against 19.0 for the calibration alone, and the storm was missed (the storm's
    shape: 3.5 nT)."""
    import orbitcal.diagnose.attribution.joint_fit as joint_fit

    def no_forward_check(*args, **kwargs):
        raise AssertionError("the index was taken to follow the field")

    monkeypatch.setattr(joint_fit, "_forward_choice", no_forward_check)
    for attitude in ("nadir", "tumbling"):
        for minimum_h in (2.6, 2.9, 3.2):
            d = _burton_storm_with_a_decaying_index(attitude, 3, minimum_h)
            train = np.arange(d.n) < int(0.7 * d.n)
            block = _design_external(d, train)
            assert block is not None
            forms = (block, *block.alternatives)
            bic = {b.variant: _train_bic(d, train, [b]) for b in forms}
            indexed = min(bic[b.variant] for b in forms if b.indexed)
            plain = min(bic[b.variant] for b in forms if not (b.indexed or b.unless_indexed))
            assert bic[block.variant] - indexed > 10 * INDEX_TRACKS_BIC  # leads the first form
            assert indexed - plain > 100 * INDEX_TRACKS_BIC  # not the decay
            chosen = _resolve(d, train, [], block)
            assert str(chosen.variant).startswith("storm@"), chosen.variant
            assert _holdout_rms_nt(d, train, [chosen]) < 0.35 * _holdout_rms_nt(d, train, [])
