"""The model core's within-event confirmation (orbitcal.diagnose.model.within_event): the
auroral currents change from crossing to crossing, so no fit on the training span forecasts
them; each crossing's own amplitudes, fitted on part of it, must predict the rest. Its size
under the noise kinds we see, its power on currents that change from crossing to crossing, and
the model core naming them."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_diagnose_worlds import make_world

from orbitcal.diagnose.attribution.engine import training_split
from orbitcal.diagnose.effects import get_effect
from orbitcal.diagnose.event_design import fac_events
from orbitcal.diagnose.model import model_diagnosis
from orbitcal.diagnose.model.confirm import Confirmation
from orbitcal.diagnose.model.core import ModelDiagnosis
from orbitcal.diagnose.model.evidence import Posterior
from orbitcal.diagnose.model.noise_model import fit_noise, run_starts, runs_of_index
from orbitcal.diagnose.model.report_keys import model_named, model_status, with_model_keys
from orbitcal.diagnose.model.within_event import EVENT_SCALES, event_confirmation
from orbitcal.diagnose.options import ModelOptions

pytestmark = pytest.mark.usefixtures("single_thread_blas")

FAC = get_effect("field_aligned_currents")
LEVEL = 0.05


def _world():  # type: ignore[no-untyped-def]
    world = make_world("none", attitude="tumbling", seed=1, n_orbits=6.0)
    _train, holdout = training_split(world.data)
    return world.data, np.flatnonzero(holdout)


def _noise(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) noise [nT] of one kind."""
    white = rng.normal(scale=2.0, size=(n, 3))
    if kind == "white":
        return white
    if kind == "ar1":
        out = np.zeros((n, 3))
        for t in range(1, n):
            out[t] = 0.9 * out[t - 1] + white[t]
        return out
    if kind == "random_walk":
        return np.cumsum(rng.normal(scale=0.5, size=(n, 3)), axis=0) + 0.5 * white
    if kind == "pink":  # 1/f power, as the model calibration's pink worlds
        spec = rng.normal(size=(n // 2 + 1, 3)) + 1j * rng.normal(size=(n // 2 + 1, 3))
        f = np.fft.rfftfreq(n)
        f[0] = f[1]
        pink = np.fft.irfft(spec / np.sqrt(f)[:, None], n, axis=0)
        return 0.5 * white + 2.0 * pink / np.std(pink, axis=0)
    if kind == "spiky":
        spikes = (rng.random((n, 1)) < 0.005) * rng.normal(scale=50.0, size=(n, 3))
        return white + spikes
    if kind == "spikes_300":  # the model calibration's and the independent generator's spikes
        hit = rng.random(n) < 0.005
        out = white.copy()
        out[hit] += 300.0 * rng.choice([-1.0, 1.0], size=(int(hit.sum()), 3))
        return out
    raise ValueError(kind)


def _currents(
    data, index: np.ndarray, rng: np.random.Generator, peak_nt: float = 150.0
) -> np.ndarray:  # type: ignore[no-untyped-def]
    """A field across B at high latitude whose strength and sign change from leg to leg of each
    crossing (the independent generator's way), (m, 3) [nT]."""
    out = np.zeros((index.size, 3))
    for ev in fac_events(data, index):
        amlat = np.abs(data.mlat_deg[index[ev.rows]])
        shape = np.exp(-0.5 * ((amlat - rng.uniform(62.0, 72.0)) / 2.5) ** 2)
        east = data.transverse_body[index[ev.rows], 0, :]
        out[ev.rows] = rng.uniform(-peak_nt, peak_nt) * shape[:, None] * east
    return out


KINDS = ["white", "ar1", "random_walk", "pink", "spiky"]


@pytest.mark.parametrize("kind", KINDS)
def test_within_event_test_has_its_stated_level_under_each_noise_kind(kind: str) -> None:
    """No currents: the test rejects at 0.05 in 0.5-2x 5 % of 300 final blocks (the noise
    model fitted, as the core does, on a training span of the same noise)."""
    data, index = _world()
    assert len(fac_events(data, index)) >= 4
    rng = np.random.default_rng(KINDS.index(kind))
    noise = fit_noise(_noise(kind, 4000, rng), runs_of_index(np.arange(4000)), max_order=4)
    starts = run_starts(data, index, 1)
    trials, rejected = 300, 0
    for _ in range(trials):
        r = _noise(kind, index.size, rng)
        conf = event_confirmation(data, index, r, FAC, noise, starts, 1.0 / 3.0)
        assert conf is not None
        rejected += conf.rejects(LEVEL)
    assert 0.5 * LEVEL <= rejected / trials <= 2.0 * LEVEL, (kind, rejected)


@pytest.mark.parametrize("kind", ["pink", "spiky", "spikes_300"])
def test_within_event_test_is_not_liberal_with_the_core_s_settings_on_a_coarse_block(
    kind: str,
) -> None:
    """The core's settings on four orbits at 20 s (each 20 s chunk one sample): the noise model
    fitted on a training residual less its mean (the calibration's offsets), the within-event
    fits at that residual's RMS per axis and the evidence's narrowest prior scale. Judged by its
    normal approximation, the test rejected 59 of 200 final blocks with 300 nT spikes at 0.05
    here (a spike in one fold pulls the fit that predicts the next sample); its Monte Carlo
    p-value over shifts of the block rejects at most 2x the level."""
    world = make_world("none", attitude="tumbling", seed=1, n_orbits=4.0, step_s=20.0)
    data = world.data
    _train, holdout = training_split(data)
    index = np.flatnonzero(holdout)
    m = index.size
    starts = run_starts(data, index, 1)
    rng = np.random.default_rng(11)
    trials, rejected = 200, 0
    for _ in range(trials):
        x = _noise(kind, 3 * m, rng)
        quiet = x[: 2 * m] - x[: 2 * m].mean(axis=0)
        noise = fit_noise(quiet, runs_of_index(np.arange(2 * m)), max_order=4)
        r = x[2 * m :] - x[: 2 * m].mean(axis=0)
        sigma = np.sqrt(np.mean(quiet**2, axis=0)).tolist()
        conf = event_confirmation(
            data, index, r, FAC, noise, starts, 1.0 / 3.0, sigma_nt=sigma, scale=EVENT_SCALES[0]
        )
        assert conf is not None
        rejected += conf.rejects(LEVEL)
    assert rejected / trials <= 2.0 * LEVEL, (kind, rejected)


def test_within_event_test_finds_currents_that_change_from_crossing_to_crossing() -> None:
    data, index = _world()
    rng = np.random.default_rng(7)
    noise = fit_noise(_noise("ar1", 4000, rng), runs_of_index(np.arange(4000)), max_order=4)
    starts = run_starts(data, index, 1)
    r = _noise("ar1", index.size, rng) + _currents(data, index, rng)
    conf = event_confirmation(data, index, r, FAC, noise, starts, 1.0 / 3.0)
    assert conf is not None and conf.passes(0.01), conf
    assert conf.holdout_rms_after_nt < 0.8 * conf.holdout_rms_before_nt


def test_no_events_no_test() -> None:
    data, index = _world()
    low = index[np.abs(data.mlat_deg[index]) < 40.0]
    noise = fit_noise(
        np.random.default_rng(0).normal(size=(500, 3)), np.zeros(500, int), max_order=1
    )
    r = np.zeros((low.size, 3))
    assert event_confirmation(data, low, r, FAC, noise, run_starts(data, low, 1), 1.0 / 3.0) is None


def test_model_core_names_currents_that_change_from_crossing_to_crossing() -> None:
    """A null world given currents whose strength and sign change from leg to leg: the model
    core names field_aligned_currents by its events; without them, nothing."""
    world = make_world("none", attitude="tumbling", seed=1, n_orbits=6.0)
    data = world.data
    train, holdout = training_split(data)
    every = np.arange(data.n)
    extra = _currents(data, every, np.random.default_rng(3))
    opts = ModelOptions(engine="model")
    with_fac = dataclasses.replace(data, b_raw_nt=data.b_raw_nt + extra)
    md = model_diagnosis(with_fac, train, holdout, opts)
    assert "field_aligned_currents" in md.event_confirmations
    assert model_named(md, opts) == ("field_aligned_currents",), model_status(md, opts)
    assert "named by its events: field_aligned_currents" in model_status(md, opts)
    assert md.probability("field_aligned_currents") > 0.99
    null = model_diagnosis(data, train, holdout, opts)
    assert model_named(null, opts) == (), model_status(null, opts)
    assert null.probability("field_aligned_currents") < 0.5


def test_weak_sheets_are_not_the_auroral_currents() -> None:
    """Sheets of a few nT (the independent generator's small unmodelled fields of its null
    worlds) are real but under the catalogue's least amplitude of the large-scale currents: the
    training events' evidence gives them to the null, nothing is named."""
    world = make_world("none", attitude="tumbling", seed=1, n_orbits=6.0, noise_nt=1.0)
    data = world.data
    train, holdout = training_split(data)
    extra = _currents(data, np.arange(data.n), np.random.default_rng(3), peak_nt=6.0)
    opts = ModelOptions(engine="model")
    md = model_diagnosis(
        dataclasses.replace(data, b_raw_nt=data.b_raw_nt + extra), train, holdout, opts
    )
    assert md.probability("field_aligned_currents") < 0.5, md.event_probability
    assert model_named(md, opts) == (), model_status(md, opts)


def _conf(p: float, before: float, after: float) -> Confirmation:
    return Confirmation(before, after, p, 3.0, 100, 0.0)


def test_an_effect_named_by_its_events_ranks_by_what_it_explains() -> None:
    """Beside a confirmed forecast of a, the events' test of c passes at the level over the
    number of such tests; c takes more of the block than a and is the verdict, whose
    probability is the posterior's (of one set of amplitudes for every event)."""
    effects = ("a", "b", "c")
    post = Posterior(effects, [(), (0,)], np.array([0.1, 0.9]), np.zeros(2), [np.zeros(12)] * 2)
    md = ModelDiagnosis(
        posterior=post,
        chosen=("a",),
        confirmation=_conf(1e-6, 10.0, 9.0),
        noise=(),
        event_confirmations={"c": _conf(1e-4, 9.0, 5.0)},
    )
    opts = ModelOptions(engine="model")
    assert model_named(md, opts) == ("c", "a")
    doc = {"verdict": "none", "effects": [{"name": e} for e in effects]}
    out = with_model_keys(doc, md, opts)
    assert out["verdict"] == "c" and out["verdict_probability"] == 0.0
    assert out["model"]["event_confirmations"]["c"]["p_value"] == pytest.approx(1e-4)
    weak = dataclasses.replace(md, event_confirmations={"c": _conf(0.06, 9.0, 8.0)})
    assert model_named(weak, opts) == ("a",)


def test_an_effect_named_by_its_events_is_not_called_inseparable_from_the_calibration() -> None:
    """An effect its events name is not also listed among those the calibration absorbs (the
    one-set form's share of the calibration says nothing about its events' own amplitudes)."""
    post = Posterior(("a", "c"), [(), (0,)], np.array([0.9, 0.1]), np.zeros(2), [np.zeros(12)] * 2)
    md = ModelDiagnosis(
        posterior=post,
        chosen=(),
        confirmation=_conf(1.0, 10.0, 10.0),
        noise=(),
        absorbed={"a": 0.8, "c": 0.9},
        event_probability={"c": 1.0},
        event_confirmations={"c": _conf(1e-4, 10.0, 5.0)},
    )
    opts = ModelOptions(engine="model")
    status = model_status(md, opts)
    assert "named by its events: c" in status
    assert "most of the field of a (80 %)" in status and "c (90 %)" not in status, status


@pytest.mark.parametrize("kind", ["ar", "level"])
def test_event_evidence_equals_the_dense_gaussian_evidence(kind: str) -> None:
    """The clustered evidence (events whose whitened columns overlap taken together) equals
    log N(y; 0, I + X S X') - log N(y; 0, I) over every valid whitened row, X the whitened
    columns of every event over whole runs (two runs; a level model's 48-tap filter makes the
    events of a run overlap)."""
    from types import SimpleNamespace

    from orbitcal.diagnose.bounds import symmetric
    from orbitcal.diagnose.effects import Effect
    from orbitcal.diagnose.event_design import Event, EventDesign
    from orbitcal.diagnose.model.noise_model import AxisNoise
    from orbitcal.diagnose.model.within_event import event_evidence

    rng = np.random.default_rng(5)
    n = 400
    spans = [(20, 35), (60, 80), (150, 170), (230, 250), (300, 330)]
    shapes = [rng.normal(size=(b - a, 3, 2)) for a, b in spans]

    def events(_data: object, _index: np.ndarray) -> list[Event]:
        return [
            Event(np.arange(a, b), sh, [f"amp_{k}_{j}" for j in range(2)])
            for k, ((a, b), sh) in enumerate(zip(spans, shapes, strict=True))
        ]

    effect = Effect(
        "x",
        "",
        "",
        lambda d, t: None,
        param_ranges=(("amp_", symmetric(30.0, "test")),),
        event_design=EventDesign(events, 20.0, 5, 0.0),
    )
    if kind == "ar":
        noise = tuple(AxisNoise("ar", np.array([0.6 - 0.1 * i]), 1.5, 0.0) for i in range(3))
    else:
        noise = tuple(AxisNoise("level", np.array([-0.8]), 1.2, 0.0) for _ in range(3))
    starts = np.r_[np.zeros(200, dtype=np.intp), np.full(200, 200, dtype=np.intp)]
    y = rng.normal(size=(n, 3)) * 3.0
    data = SimpleNamespace()
    evidence = event_evidence(
        data,  # type: ignore[arg-type]
        np.arange(n),
        y,
        effect,
        noise,
        starts,
        1.0 / 3.0,
        scales=(1.0,),
    )
    assert evidence is not None
    got = evidence.log_bayes_factor
    # dense: every column over the whole span, whitened with the runs
    cols = np.zeros((n, 3, 2 * len(spans)))
    for k, ((a, b), sh) in enumerate(zip(spans, shapes, strict=True)):
        cols[a:b, :, 2 * k : 2 * k + 2] = sh
    wx = np.zeros_like(cols)
    wy = np.zeros_like(y)
    valid = np.ones(n, dtype=bool)
    for i, nz in enumerate(noise):
        wy[:, i], ok = nz.whiten(y[:, i], starts)
        wx[:, i, :], _ = nz.whiten(cols[:, i, :], starts)
        valid &= ok
    x = wx[valid].reshape(-1, cols.shape[2])
    v = wy[valid].reshape(-1)
    sd = np.full(x.shape[1], 10.0)
    cov = np.eye(v.size) + (x * sd**2) @ x.T
    _s, logdet = np.linalg.slogdet(cov)
    want = -0.5 * (logdet + v @ np.linalg.solve(cov, v)) + 0.5 * v @ v
    assert got == pytest.approx(want, rel=1e-8, abs=1e-8)
