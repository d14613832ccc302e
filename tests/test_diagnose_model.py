"""The model core of the diagnosis (orbitcal.diagnose.model): noise model, exact evidence,
posterior, the confirmation's separation from selection, and the contract keys it writes."""

from __future__ import annotations

import dataclasses
import itertools
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_diagnose_worlds import make_world

from orbitcal.diagnose.attribution.engine import training_split
from orbitcal.diagnose.model import candidate_forms, model_diagnosis
from orbitcal.diagnose.model.confirm import (
    Confirmation,
    andrews_bandwidth,
    confirm,
    newey_west_variance,
)
from orbitcal.diagnose.model.core import ModelDiagnosis
from orbitcal.diagnose.model.evidence import Posterior, augment, log_evidence, posterior, project
from orbitcal.diagnose.model.gram import Form, Gram
from orbitcal.diagnose.model.noise_model import (
    AxisNoise,
    fit_axis_noise,
    forecast_noise,
    runs_of_index,
)
from orbitcal.diagnose.model.report_keys import model_named, model_status, unconfirmed
from orbitcal.diagnose.options import ModelOptions

pytestmark = pytest.mark.usefixtures("single_thread_blas")


def _ar1(n: int, phi: float, rng: np.random.Generator) -> np.ndarray:
    e = rng.normal(size=n)
    x = np.zeros(n)
    for t in range(1, n):
        x[t] = phi * x[t - 1] + e[t]
    return x


def test_noise_model_recovers_an_ar1_coefficient() -> None:
    rng = np.random.default_rng(0)
    r = _ar1(20_000, 0.7, rng)
    nz = fit_axis_noise(r, runs_of_index(np.arange(r.size)), max_order=4)
    assert nz.kind == "ar" and nz.phi.size >= 1
    assert nz.phi[0] == pytest.approx(0.7, abs=0.03)
    assert nz.sigma_nt == pytest.approx(1.0, rel=0.03)


def test_noise_model_takes_a_random_walk_offset_and_white_noise_as_white() -> None:
    rng = np.random.default_rng(1)
    walk = np.cumsum(rng.normal(scale=0.3, size=20_000)) + rng.normal(size=20_000)
    starts = runs_of_index(np.arange(walk.size))
    assert fit_axis_noise(walk, starts, max_order=4).kind in {"rw", "level"}
    white = fit_axis_noise(rng.normal(scale=2.0, size=20_000), starts, max_order=4)
    assert white.kind == "ar" and white.phi.size == 0
    assert white.sigma_nt == pytest.approx(2.0, rel=0.03)


def test_whitening_restarts_at_each_run() -> None:
    index = np.r_[np.arange(10), np.arange(50, 60)]
    starts = runs_of_index(index)
    assert starts.tolist() == [0] * 10 + [10] * 10


@pytest.mark.parametrize(
    "noise",
    [
        AxisNoise("ar", np.array([0.5, 0.2]), 1.0, 0.0),
        AxisNoise("rw", np.array([0.3]), 1.0, 0.0),
        AxisNoise("level", np.array([-0.8]), 1.0, 0.0),
        AxisNoise("frac", np.array([0.3, 0.1]), 1.0, 0.0),
        AxisNoise("ar", np.zeros(0), 1.0, 0.0),
    ],
    ids=["ar2", "rw+ar1", "level", "frac", "white"],
)
def test_the_noise_forecast_runs_the_filter_on_from_the_training_span(noise: AxisNoise) -> None:
    """Innovations zero beyond the span: ``r_t = -sum a_j r_(t-j)`` on the deviations from the
    residual's mean, read at each target's grid position (training samples 2 apart)."""
    rng = np.random.default_rng(5)
    r = np.cumsum(rng.normal(size=300))[:, None]
    index = 2 * np.arange(300)
    targets = index[-1] + np.array([2, 3, 4, 10, 40, 41])  # 3 and 41 round to 4 and 40 (even)
    got = forecast_noise([noise], r, index, 2, targets)[:, 0]
    a, mean = noise.filter, float(r.mean())
    lag = a.size - 1
    x = list(r[-lag:, 0] - mean) if lag else []
    for _ in range(20):
        x.append(-float(a[1:] @ np.asarray(x[::-1][:lag])) if lag else 0.0)
    path = np.asarray(x[lag:]) + mean
    np.testing.assert_allclose(got, path[[0, 1, 1, 4, 19, 19]], atol=1e-9)
    if noise.kind == "level":  # a random-walk offset carries the level the span ended at
        assert abs(got[-1] - r[-1, 0]) < 3.0
    if noise.kind == "ar" and noise.phi.size == 0:  # white noise: the residual's mean
        np.testing.assert_allclose(got, mean)


def test_a_model_whose_level_the_noise_holds_is_confirmed(real_tles_text: str) -> None:
    """Under a random-walk offset in the noise model the differenced data do not pin the
    calibration's offsets, so a right model's forecast is off by a level; its noise model's
    forecast carries the level the training span ended at. Without it, compound world 22000
    no. 49 (time offset, nonlinearity, drift; nadir) had a chosen model whose final-block errors
    were a level of 25-54 nT per axis around 3 nT of scatter: 35.9 -> 37.4 nT, not named.
    Since the drift's step is searched beside the other effects that world's residual is
    white, so a random-walk offset (0.3 nT a sample) is added here: with the noise forecast
    the final block goes 17.9 -> 6.3 nT, without it 25.0 -> 16.5 nT."""
    from orbitcal.diagnose.bench import plan_compound_cases, simulate_compound_world

    case = plan_compound_cases(50, seed=22000)[49]
    assert case.effects == ("time_offset", "nonlinearity", "parameter_drift")
    _world, data = simulate_compound_world(
        case, tle_text=real_tles_text, n_orbits=4.0, cadence_s=10.0, crust_model="LCS-1"
    )
    walk = np.cumsum(np.random.default_rng(0).normal(0.0, 0.3, data.b_raw_nt.shape), axis=0)
    data = dataclasses.replace(data, b_raw_nt=data.b_raw_nt + walk)
    train, holdout = training_split(data)
    md = model_diagnosis(data, train, holdout)
    assert {n.kind for n in md.noise} & {"rw", "level"}, [n.kind for n in md.noise]
    assert "nonlinearity" in md.chosen
    c = md.confirmation
    assert c.passes(ModelOptions().confirmation_level), c
    assert c.holdout_rms_after_nt < 0.5 * c.holdout_rms_before_nt, c
    assert "nonlinearity" in model_named(md, ModelOptions())


@pytest.mark.parametrize(("number", "forecast"), [(44, "parameter_drift"), (29, "time_offset")])
def test_forecasts_are_compared_outside_the_events_of_an_effect_fitted_beside_them(
    real_tles_text: str, number: int, forecast: str
) -> None:
    """An auroral crossing's currents change from crossing to crossing: no forecast holds them,
    so inside the crossings they are an error of the chosen model and of the calibration alike.
    Compared over the whole final block (compound worlds 22400 nos. 44 and 29, tuning worlds),
    the drift was withdrawn by the cross-validation (gain -3682) and the time offset, forecast
    at p 3e-6, was not closer (49.7 -> 52.1 nT): neither was named. Outside the crossings both
    are."""
    from orbitcal.diagnose.bench import plan_compound_cases, simulate_compound_world
    from orbitcal.diagnose.model.core import outside_events

    case = plan_compound_cases(50, seed=22400)[number]
    assert "field_aligned_currents" in case.effects and forecast in case.effects
    _world, data = simulate_compound_world(case, tle_text=real_tles_text)
    train, holdout = training_split(data)
    md = model_diagnosis(data, train, holdout)
    assert md.beside == ("field_aligned_currents",)
    h_index = np.flatnonzero(holdout)
    quiet = outside_events(data, h_index, md.beside)
    # the crossings are the samples above the auroral latitude, and only they are left out
    auroral = np.abs(data.mlat_deg[h_index]) > 55.0
    assert not np.any(quiet & auroral)
    assert 0.2 < np.mean(~quiet) < 0.6
    assert np.all(quiet | auroral)
    assert md.confirmation.n_samples == int(np.sum(quiet))
    assert forecast in md.crossval.kept, md.crossval
    assert forecast in model_named(md, ModelOptions())
    assert outside_events(data, h_index, ()).all()


@pytest.mark.parametrize(("seed", "number"), [(301, 24), (301, 14), (301, 21), (22400, 44)])
def test_a_step_is_placed_beside_the_other_effects_fields(
    real_tles_text: str, seed: int, number: int
) -> None:
    """A drift's step time searched alone (the calibration and the step against the data) is
    placed where the step best takes up the other effects' fields: in compound worlds 301
    nos. 24 (a temperature) and 14 (a time offset), tuning worlds, it fell at 0.17 and 0.24 of
    the span against steps at 0.288 and 0.310; the misplaced drift forecast the final block
    worse than none (2.2 -> 5.2 nT) and was not named. Searched beside the other effects' best
    forms it falls within a minute of the step, and the drift is named. In 301 no. 21 and
    22400 no. 44 the best grid time beside them was on a lesser peak (0.55 and 0.25 of the
    span, the steps at 0.30 and 0.50): the halving starts from every peak of the grid."""
    from orbitcal.diagnose.bench import plan_compound_cases, simulate_compound_world

    case = plan_compound_cases(50, seed=seed)[number]
    assert "parameter_drift" in case.effects
    world, data = simulate_compound_world(case, tle_text=real_tles_text)
    md = _placed_step_diagnosis(world, data)
    assert "parameter_drift" in model_named(md, ModelOptions())


def _placed_step_diagnosis(world: Any, data: Any) -> ModelDiagnosis:
    """The model core's diagnosis of a world with a drift, its step placed within a minute of
    the injected one."""
    (truth,) = [e for e in world.effects if getattr(e, "name", "") == "parameter_drift"]
    t = data.t_utc_s
    step_s = t[0] + truth.step_at_fraction * (t[-1] - t[0])
    train, holdout = training_split(data)
    md = model_diagnosis(data, train, holdout)
    variant = md.forms["parameter_drift"]
    assert variant.startswith("step@"), variant
    assert abs(float(variant[5:].split("+")[0]) - step_s) < 60.0, (variant, step_s)
    return md


@pytest.mark.parametrize("number", [152, 224])
def test_a_step_alone_is_not_searched_beside_an_absent_effects_form(
    real_tles_text: str, number: int
) -> None:
    """Blind worlds 22500 nos. 152 and 224 hold a drift alone. Searched beside every other
    effect's best form at once, the step was scored with the attitude error's three sinusoids
    and drift (its best form alone: they take up part of the step) always there, and the search
    ended on a trend; nothing was named. Summed over the models that hold the step (with none,
    one or two of the others, at their priors) the step is placed, and the drift named."""
    from orbitcal.diagnose import bench

    case = bench.plan_cases(240, seed=22500)[number]
    assert case.effect == "parameter_drift"
    rng = np.random.default_rng(case.seed)
    tle, start, attitude = bench._case_orbit(case.norad_id, case.attitude, real_tles_text, rng)
    effects = [bench._scaled_effect(case.effect, case.magnitude, rng)]
    world, data = bench._world_and_data(
        tle, start, attitude, effects, rng, n_orbits=4.0, cadence_s=10.0, crust_model="LCS-1"
    )
    md = _placed_step_diagnosis(world, data)
    assert model_named(md, ModelOptions()) == ("parameter_drift",)


@pytest.mark.parametrize(("seed", "number"), [(22400, 24), (301, 2)])
def test_the_number_of_attitude_periods_is_chosen_by_evidence(
    real_tles_text: str, seed: int, number: int
) -> None:
    """Our simulator's attitude error is three sinusoids (5,400 s x 1, 1.3, 0.7). The scan's
    forward rule (a fit to the first 70 % of the training span forecasting the rest) kept two
    periods in compound world 22400 no. 24 (5,556 and 3,755 s): the forecast drifted out of
    phase, the final block went 17.3 -> 20.2 nT and the attitude error was not named; in 301
    no. 2 (nadir) it kept one (6,389 s) and the attitude error got probability 0. The model
    core now chooses among every number of periods by evidence: three, and the effect is
    named."""
    from orbitcal.diagnose.bench import plan_compound_cases, simulate_compound_world

    case = plan_compound_cases(50, seed=seed)[number]
    assert "attitude_error" in case.effects
    _, data = simulate_compound_world(case, tle_text=real_tles_text)
    train, holdout = training_split(data)
    sizes = {
        f.block.width
        for f in candidate_forms(data, train, ModelOptions())
        if f.effect == "attitude_error" and f.block.variant.startswith("periods_s=")
    }
    assert sizes == {9, 15, 21}, sizes  # one, two and three periods (6 columns each) + drift
    md = model_diagnosis(data, train, holdout)
    periods = md.forms["attitude_error"].split("=")[1].split(" ")[0].split(",")
    assert len(periods) == 3, md.forms["attitude_error"]
    assert "attitude_error" in model_named(md, ModelOptions())


def _tiny(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, Gram]:
    n = 40
    xc = np.column_stack([np.ones(n), rng.normal(size=(n, 11))])
    xe = rng.normal(size=(n, 3))
    y = xc @ rng.normal(size=12) + 0.8 * xe[:, 0] + rng.normal(size=n)
    gram = Gram(xc.T @ xc, xc.T @ xe, xc.T @ y, xe.T @ xe, xe.T @ y, float(y @ y), n)
    return xc, xe, y, gram


def _log_normal(y: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> float:
    _sign, logdet = np.linalg.slogdet(cov)
    d = y - mean
    return float(-0.5 * (logdet + d @ np.linalg.solve(cov, d) + y.size * np.log(2 * np.pi)))


def test_evidence_matches_a_brute_force_gaussian_integral() -> None:
    """The flat prior on the calibration is the limit of a wide Gaussian one: the log ratio of
    two models' evidence equals the brute-force ratio of marginal densities as the width grows."""
    xc, xe, y, gram = _tiny(np.random.default_rng(2))
    proj = project(gram)
    wide = 1e4
    cov_c = wide**2 * xc @ xc.T
    mean = np.array([0.2, -0.1, 0.0])
    sd = np.array([1.5, 0.7, 2.0])
    null = log_evidence(proj, np.zeros(0, dtype=np.intp), np.zeros(0), np.zeros(0))[0]
    brute_null = _log_normal(y, np.zeros_like(y), np.eye(y.size) + cov_c)
    for cols in ([0], [1, 2], [0, 1, 2]):
        ix = np.array(cols, dtype=np.intp)
        ours = log_evidence(proj, ix, mean[ix], sd[ix])[0] - null
        cov = np.eye(y.size) + cov_c + xe[:, ix] @ np.diag(sd[ix] ** 2) @ xe[:, ix].T
        brute = _log_normal(y, xe[:, ix] @ mean[ix], cov) - brute_null
        assert ours == pytest.approx(brute, abs=1e-4)


def test_posterior_probabilities_sum_to_one_over_every_model() -> None:
    _, _, _, gram = _tiny(np.random.default_rng(3))
    aug = augment(gram, np.zeros(12), np.full(12, 1e3), 0.0)
    forms = [
        Form(name, None, slice(i, i + 1), np.zeros(1), np.ones(1), 1)  # type: ignore[arg-type]
        for i, name in enumerate(["a", "b", "c"])
    ]
    post = posterior(aug, forms, expected_effects=1.0, max_effects=2, n_catalogue=11)
    assert len(post.models) == 1 + 3 + 3
    assert post.prob.sum() == pytest.approx(1.0)
    inc = post.inclusion()
    assert all(0.0 <= p <= 1.0 for p in inc.values())
    # inclusion = the sum over the models that hold the effect
    for name, i in zip("abc", range(3), strict=True):
        assert inc[name] == pytest.approx(
            sum(p for m, p in zip(post.models, post.prob, strict=True) if i in m)
        )
    assert inc["a"] > 0.9  # the injected column
    for a, b in itertools.combinations("abc", 2):
        assert post.pair(a, b) <= min(inc[a], inc[b]) + 1e-12


def test_the_median_model_is_always_a_model() -> None:
    """Four effects can each reach inclusion 0.5 while every model holds at most three of them
    (here the three-effect models share the mass): the effects at 0.5 or more are then no model
    of the posterior, and the choice is the most probable model (a degenerate constant field
    with four such effects stopped the diagnosis with a ValueError)."""
    models = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)]
    prob = np.array([0.3, 0.25, 0.25, 0.2])
    post = Posterior(("a", "b", "c", "d"), models, prob, np.log(prob), [np.zeros(12)] * 4)
    assert min(post.inclusion().values()) >= 0.5
    assert set(post.median_model()) == {"a", "b", "c"}
    # a median model that is a model stays the rule
    post = Posterior(
        ("a", "b", "c"), [(), (0,), (0, 1)], np.array([0.2, 0.5, 0.3]), np.zeros(3), []
    )
    assert post.median_model() == ("a",)


def test_noise_model_takes_one_over_f_noise_as_long_memory() -> None:
    # a 1/f spectrum (the benchmark's pink noise): no AR(<=4) or local level whitens it
    rng = np.random.default_rng(5)
    n = 20_000
    spec = rng.normal(size=n // 2 + 1) + 1j * rng.normal(size=n // 2 + 1)
    f = np.fft.rfftfreq(n)
    f[0] = f[1]
    pink = np.fft.irfft(spec / np.sqrt(f), n)
    nz = fit_axis_noise(pink / np.std(pink), runs_of_index(np.arange(n)), max_order=4)
    assert nz.kind == "frac" and nz.phi[0] >= 0.3


def test_andrews_bandwidth_grows_with_the_autocorrelation() -> None:
    rng = np.random.default_rng(6)
    white = andrews_bandwidth(rng.normal(size=2_000))
    persistent = andrews_bandwidth(_ar1(2_000, 0.8, rng))
    assert white <= 2 and persistent > 5 * max(white, 1)


def test_newey_west_variance_of_white_noise_is_its_variance() -> None:
    x = np.random.default_rng(4).normal(size=50_000)
    assert newey_west_variance(x) == pytest.approx(1.0, rel=0.03)


def _simulated(effect: str | None, seed: int, real_tles_text: str):  # type: ignore[no-untyped-def]
    from orbitcal.diagnose.options import DiagnosisOptions
    from orbitcal.diagnose.prepare import diagnosis_data
    from orbitcal.orbit import Orbit
    from orbitcal.simulate import Tumbling, make_effect, select_tle, simulate_world

    tle = select_tle(real_tles_text, norad_id=39452, at_utc_s=1.69e9)
    world = simulate_world(
        tle,
        start_utc_s=tle.epoch_utc_s + 3600.0,
        duration_s=4 * 5600.0,
        cadence_s=20.0,
        rng=np.random.default_rng(seed),
        attitude=Tumbling(),
        effects=[make_effect(effect)] if effect else [],
    )
    options = DiagnosisOptions(learned=False)
    return diagnosis_data(world.telemetry, orbit=Orbit.from_tle(tle.text), options=options)


def test_inclusion_high_for_an_injected_effect_and_low_on_a_null_world(
    real_tles_text: str,
) -> None:
    """Worlds of the project's simulator: a magnetorquer coupling, and none."""
    for effect in ("magnetorquer", None):
        data = _simulated(effect, 5, real_tles_text)
        train, holdout = training_split(data)
        md = model_diagnosis(data, train, holdout)
        inc = md.inclusion()
        assert md.posterior.prob.sum() == pytest.approx(1.0)
        if effect is None:
            assert max(inc.values()) < 0.5, inc
            assert md.chosen == () and md.confirmation.p_value == 1.0
            assert md.probability("none") > 0.5
        else:
            assert inc[effect] > 0.99, inc
            assert md.chosen[0] == effect
            assert md.confirmation.p_value < 1e-3
            c = md.confirmation
            assert c.holdout_rms_after_nt < c.holdout_rms_before_nt


def test_the_final_block_does_not_take_part_in_selection() -> None:
    """Changing only the final block's data leaves the posterior and the chosen model as they
    were, and changes the confirmation."""
    world = make_world("temperature", attitude="tumbling", seed=3)
    train, holdout = training_split(world.data)
    forms = candidate_forms(world.data, train, ModelOptions())
    before = model_diagnosis(world.data, train, holdout, forms=forms)
    raw = world.data.b_raw_nt.copy()
    raw[holdout] += 50.0 * np.random.default_rng(9).normal(size=(int(holdout.sum()), 3))
    changed = dataclasses.replace(world.data, b_raw_nt=raw)
    after = model_diagnosis(changed, train, holdout, forms=forms)
    assert after.chosen == before.chosen == ("temperature",)
    np.testing.assert_array_equal(after.posterior.prob, before.posterior.prob)
    assert after.confirmation.holdout_rms_before_nt > 4 * before.confirmation.holdout_rms_before_nt


def _check_keys(report: dict) -> None:  # type: ignore[type-arg]
    assert report["effects"]
    for e in report["effects"]:
        assert 0.0 <= e["probability"] <= 1.0
    assert 0.0 <= report["verdict_probability"] <= 1.0
    conf = report["confirmation"]
    assert set(conf) >= {"holdout_rms_before_nt", "holdout_rms_after_nt", "p_value"}
    assert 0.0 <= conf["p_value"] <= 1.0
    assert conf["holdout_rms_before_nt"] > 0.0 and conf["holdout_rms_after_nt"] > 0.0
    json.dumps(report, allow_nan=False)


def test_library_report_has_the_probability_keys() -> None:
    from orbitcal.diagnose.api import diagnose_data
    from orbitcal.diagnose.options import DiagnosisOptions

    world = make_world("external_field", attitude="tumbling", seed=7)
    report = diagnose_data(world.data, options=DiagnosisOptions(learned=False)).report.to_json()
    _check_keys(report)
    assert report["verdict"] == "external_field"
    assert report["verdict_probability"] > 0.99
    assert report["model"]["inclusion_probability"]["external_field"] > 0.99
    c = report["confirmation"]
    assert c["p_value"] < 1e-3


def test_cli_report_has_the_probability_keys_under_the_model_engine(
    tmp_path: Path, real_tles_text: str
) -> None:
    from orbitcal.cli import main
    from orbitcal.simulate import Tumbling, make_effect, select_tle, simulate_world

    tle = select_tle(real_tles_text, norad_id=39452, at_utc_s=1.69e9)
    world = simulate_world(
        tle,
        start_utc_s=tle.epoch_utc_s + 3600.0,
        duration_s=3 * 5600.0,
        cadence_s=20.0,
        rng=np.random.default_rng(1),
        attitude=Tumbling(),
        effects=[make_effect("magnetorquer")],
    )
    paths = world.write(tmp_path / "world")
    out = tmp_path / "report.json"
    args = ["diagnose", str(paths["telemetry"]), "--tle", str(paths["tle"]), "--out", str(out)]
    assert main([*args, "--engine", "model"]) == 0
    report = json.loads(out.read_text())
    _check_keys(report)
    assert report["model"]["engine"] == "model"
    assert report["verdict"] == "magnetorquer" and report["verdict_probability"] > 0.99
    assert report["effects"][0]["name"] == "magnetorquer"


def test_model_options_refuse_an_unknown_engine() -> None:
    with pytest.raises(ValueError, match="engine"):
        ModelOptions(engine="votes")


def test_orbit_folds_are_orbit_long_and_join_a_short_last_block() -> None:
    from orbitcal.diagnose.model.crossval import orbit_folds

    t = np.arange(0.0, 3.2 * 5600.0, 10.0)
    fold = orbit_folds(t, 5600.0)
    assert fold.max() == 2  # the last 0.2 orbit joins the third fold
    assert np.all(np.diff(fold) >= 0)
    assert np.sum(fold == 0) == 560
    assert orbit_folds(t[:100], 5600.0).max() == 0


def test_cross_validation_keeps_a_real_effect_and_withdraws_columns_that_do_not_predict(
    real_tles_text: str,
) -> None:
    """A magnetorquer world: the coupling predicts every left-out orbit; a 12-column group that
    is not in the data (fitted to noise alone) does not, and leaves the model."""
    import dataclasses as dc

    from orbitcal.diagnose.model.core import CAL_PRIOR_SD_NT, _compact
    from orbitcal.diagnose.model.crossval import cross_validated

    data = _simulated("magnetorquer", 5, real_tles_text)
    train, holdout = training_split(data)
    md = model_diagnosis(data, train, holdout)
    assert md.chosen == ("magnetorquer",) and md.crossval.folds >= 2
    assert md.crossval.gain["magnetorquer"] > 0.0
    forms = {f.effect: f for f in candidate_forms(data, train, ModelOptions())}
    absent = max(
        (f for f in forms.values() if f.effect != "magnetorquer"), key=lambda f: f.block.width
    )
    assert absent.block.width >= 6
    chosen = _compact([forms["magnetorquer"], absent])
    cv = cross_validated(
        data,
        train,
        chosen,
        md.noise,
        skip=60,
        cal_mean=md.posterior.thetas[0][:12],
        cal_sd=np.full(12, CAL_PRIOR_SD_NT),
    )
    assert cv.kept == ("magnetorquer",), cv
    assert cv.withdrawn == (absent.effect,) and cv.gain[absent.effect] <= 0.0
    assert dc.asdict(cv)["folds"] == md.crossval.folds


def _confirmation(p: float, before: float, after: float) -> Confirmation:
    """A confirmation under unit white noise: the whitened gain is the squared RMS's change."""
    return Confirmation(before, after, p, 3.0, 100, 3.0 * (before**2 - after**2))


def _diagnosis(
    chosen: tuple[str, ...],
    whole: Confirmation,
    each: dict[str, Confirmation],
    absorbed: dict[str, float] | None = None,
) -> ModelDiagnosis:
    """A model diagnosis of three candidates whose posterior includes ``chosen`` with 0.9."""
    effects = ("a", "b", "c")
    key = tuple(sorted(effects.index(e) for e in chosen))
    models = [(), key] if key else [()]
    prob = np.array([0.1, 0.9]) if key else np.array([1.0])
    post = Posterior(effects, models, prob, np.zeros(len(models)), [np.zeros(12)] * len(models))
    return ModelDiagnosis(
        posterior=post,
        chosen=chosen,
        confirmation=whole,
        noise=(),
        absorbed=absorbed or {},
        effect_confirmations=each,
    )


def test_a_forecast_that_overshoots_is_not_confirmed() -> None:
    """The Clark-West statistic rewards a forecast that moves the right way whatever its size:
    three times too far is 'significant' with a worse RMS. Confirmed means both."""
    rng = np.random.default_rng(11)
    n = 400
    signal = 20.0 * np.sin(np.linspace(0.0, 6.0, n))[:, None] * np.ones((1, 3))
    noise = rng.normal(size=(n, 3))
    white = (AxisNoise("ar", np.zeros(0), 1.0, float("nan")),) * 3
    starts = np.zeros(n, dtype=bool)
    starts[0] = True
    e_base = signal + noise
    overshoot = confirm(e_base, e_base - 4.0 * signal, white, starts)
    assert overshoot.p_value < 1e-3
    assert overshoot.holdout_rms_after_nt > overshoot.holdout_rms_before_nt
    assert not overshoot.passes(0.05)
    right = confirm(e_base, noise, white, starts)
    assert right.p_value < 1e-3 and right.passes(0.05)


def test_each_chosen_effect_must_forecast_the_final_block_better_beside_the_others() -> None:
    """Holm's step-down over the chosen effects' own tests; the whole model first."""
    good, weak = _confirmation(1e-6, 10.0, 5.0), _confirmation(0.04, 10.0, 9.0)
    worse = _confirmation(1e-9, 10.0, 12.0)
    opts = ModelOptions()
    md = _diagnosis(("a", "b"), good, {"a": good, "b": weak})
    # by p: a at 0.05 / 2, then b at 0.05 / 1: both pass
    assert model_named(md, opts) == ("a", "b")
    md = _diagnosis(("a", "b", "c"), good, {"a": good, "b": weak, "c": worse})
    # c's test rejects first (p 1e-9 at 0.05 / 3) but its forecast is farther: c is not named,
    # and the step-down goes on to a (0.05 / 2) and b (0.05 / 1)
    assert model_named(md, opts) == ("a", "b")
    md = _diagnosis(("a", "b", "c"), good, {"a": good, "b": _confirmation(0.9, 10, 9), "c": weak})
    # a (1e-6) passes at 0.05 / 3; c (0.04) fails at 0.05 / 2 and stops the step-down: b (0.9) is
    # never reached
    assert model_named(md, opts) == ("a",)
    md = _diagnosis(("a", "b", "c"), good, {"a": good, "b": _confirmation(0.03, 10, 9), "c": weak})
    # a at 0.05/3, b 0.02 > 0.05/2 stops: only a
    assert model_named(md, opts) == ("a",)
    assert unconfirmed(md, opts) == ("b", "c")
    assert "beside them, not confirmed on its own" in model_status(md, opts)
    md = _diagnosis(("a",), worse, {})
    assert model_named(md, opts) == ()
    # equally sure (0.90 each): the one that shrinks the block more beside the other first
    md = _diagnosis(("a", "b"), good, {"a": _confirmation(1e-6, 10, 9), "b": good})
    assert model_named(md, opts) == ("b", "a")


def test_the_status_says_why_nothing_is_named() -> None:
    opts = ModelOptions()
    md = _diagnosis(("a",), _confirmation(1e-9, 721.0, 1126.0), {}, {"b": 0.97, "c": 0.3})
    status = model_status(md, opts)
    assert status.startswith("none: the model chosen on the training span, a (probability")
    assert "does not forecast the final block better than the calibration alone" in status
    assert "721.0 -> 1126.0 nT" in status
    assert "most of the field of b (97 %)" in status and "c (" not in status
    assert "cannot be separated from the calibration" in status
    good = _confirmation(1e-6, 10.0, 5.0)
    md = _diagnosis(
        ("a", "b"), good, {"a": _confirmation(0.3, 6, 5), "b": _confirmation(0.4, 6, 5)}
    )
    status = model_status(md, opts)
    assert status.startswith("none named alone: the chosen model")
    assert "cannot tell which of a, b carries the gain" in status


def test_the_verdict_is_the_named_effect_that_explains_most_of_the_final_block() -> None:
    """CONTRACT section 5: the verdict is the effect that explains most of the gap, and the
    effects are ranked most explanatory first. b (probability 0.90) takes the final block from
    10 to 5 nT beside a; a (0.99) from 10 to 9 nT beside b: b is the verdict, ranked first."""
    from orbitcal.diagnose.model.report_keys import with_model_keys

    effects = ("a", "b", "c")
    post = Posterior(
        effects,
        [(), (0,), (0, 1)],
        np.array([0.01, 0.09, 0.9]),
        np.zeros(3),
        [np.zeros(12)] * 3,
    )
    good = _confirmation(1e-6, 10.0, 5.0)
    md = ModelDiagnosis(
        posterior=post,
        chosen=("a", "b"),
        confirmation=good,
        noise=(),
        effect_confirmations={
            "a": _confirmation(1e-6, 6.0, 5.0),
            "b": _confirmation(1e-6, 10.0, 5.0),
        },
    )
    opts = ModelOptions(engine="model")
    assert md.inclusion()["a"] > md.inclusion()["b"]
    assert model_named(md, opts) == ("b", "a")
    doc = {"verdict": "none", "effects": [{"name": e} for e in ("c", "a", "b")]}
    out = with_model_keys(doc, md, opts)
    assert out["verdict"] == "b"
    assert [e["name"] for e in out["effects"]] == ["b", "a", "c"]
    assert out["verdict_probability"] == pytest.approx(0.9)
