"""The joint fit's design accumulated a block of samples at a time equals the dense design."""

from __future__ import annotations

import numpy as np
import pytest
from test_diagnose_worlds import make_world

from orbitcal.diagnose import blocked
from orbitcal.diagnose.attribution import fit_joint, time_blocks
from orbitcal.diagnose.blocked import BlockedDesign
from orbitcal.diagnose.effects import FIELD_SCALE_NT, DesignBlock, DiagnosisData, get_effect


def _dense(data: DiagnosisData, blocks: list[DesignBlock]) -> tuple[np.ndarray, np.ndarray]:
    """The whole unit-scaled design (3N, p) and its column scales, formed at once."""
    b = data.b_ref_body_nt / FIELD_SCALE_NT
    p = 12 + sum(len(bl.names) for bl in blocks)
    x = np.zeros((data.n, 3, p))
    for i in range(3):
        x[:, i, 3 * i : 3 * i + 3] = b
        x[:, i, 9 + i] = 1.0
    x[:, :, 12:] = np.concatenate([bl.g for bl in blocks], axis=2)
    x2 = x.reshape(3 * data.n, p)
    scale = np.sqrt(np.mean(x2**2, axis=0))
    q, _ = np.linalg.qr(x2[:, :12])
    eff = x2[:, 12:]
    rest = np.sqrt(np.mean((eff - q @ (q.T @ eff)) ** 2, axis=0))
    scale[12:] = np.maximum(rest, 1e-6 * scale[12:])
    return x2 / scale, scale


@pytest.fixture(scope="module")
def world() -> tuple[DiagnosisData, np.ndarray, list[DesignBlock]]:
    data = make_world("crustal_field", attitude="tumbling", seed=3).data
    train, _, _ = time_blocks(data.t_utc_s)
    blocks = []
    for name in ("crustal_field", "parameter_drift", "time_offset"):
        bl = get_effect(name).design(data, train)
        assert bl is not None
        blocks.append(bl)
    return data, train, blocks


@pytest.mark.parametrize("block_samples", [1, 7, 100, 10**6])
def test_blocked_products_equal_the_dense_design(world, block_samples: int) -> None:
    data, train, blocks = world
    x, scale = _dense(data, blocks)
    d = BlockedDesign(data, blocks, block_samples=block_samples)
    np.testing.assert_allclose(d.scale, scale, rtol=1e-10)
    index = np.flatnonzero(train)
    rows = np.repeat(train, 3)
    xt = x[rows]
    y = data.b_raw_nt[index].reshape(-1)
    w = np.random.default_rng(0).uniform(0.0, 1.0, y.size)
    gram, rhs = d.normal_equations(index, y, w)
    np.testing.assert_allclose(gram, xt.T @ (xt * w[:, None]), rtol=1e-10, atol=1e-9 * gram.max())
    np.testing.assert_allclose(rhs, (xt * w[:, None]).T @ y, rtol=1e-10, atol=1e-9 * abs(rhs).max())
    theta = np.linalg.solve(gram, rhs)
    np.testing.assert_allclose(d.residual(index, y, theta), y - xt @ theta, atol=1e-9)
    # Least squares through the block-updated QR factor = numpy's on the whole matrix.
    dense = np.linalg.lstsq(xt, y, rcond=None)[0]
    np.testing.assert_allclose(d.lstsq(index, y), dense, rtol=1e-7, atol=1e-9 * abs(dense).max())
    sw = np.sqrt(w)
    dense_w = np.linalg.lstsq(xt * sw[:, None], y * sw, rcond=None)[0]
    np.testing.assert_allclose(
        d.lstsq(index, y, w), dense_w, rtol=1e-7, atol=1e-9 * abs(dense_w).max()
    )


@pytest.mark.parametrize("pattern", ["thinned", "runs_and_singles", "one_sample"])
def test_products_of_scattered_samples_equal_the_dense_design(world, pattern: str) -> None:
    """Samples mostly apart (read by index), long runs mixed with single samples (read by
    views, a single sample as a view of one) and one sample give the dense design's products."""
    data, _, blocks = world
    n = data.n
    if pattern == "thinned":
        index = np.arange(0, n, 3)
    elif pattern == "runs_and_singles":
        index = np.r_[np.arange(10, 400), np.arange(401, 1200, 97), np.arange(1300, n)]
    else:
        index = np.array([n // 2])
    x, _ = _dense(data, blocks)
    rows = (3 * index[:, None] + np.arange(3)).reshape(-1)
    xt = x[rows]
    y = data.b_raw_nt[index].reshape(-1)
    w = np.random.default_rng(1).uniform(0.0, 1.0, y.size)
    d = BlockedDesign(data, blocks, block_samples=100)
    gram, rhs = d.normal_equations(index, y, w)
    np.testing.assert_allclose(gram, xt.T @ (xt * w[:, None]), rtol=1e-10, atol=1e-9 * gram.max())
    np.testing.assert_allclose(rhs, (xt * w[:, None]).T @ y, rtol=1e-10, atol=1e-9 * abs(rhs).max())
    theta = np.random.default_rng(2).normal(size=d.p)
    np.testing.assert_allclose(d.residual(index, y, theta), y - xt @ theta, rtol=1e-10, atol=1e-8)


def test_plain_joint_fit_is_the_dense_normal_equation_solve(world) -> None:
    data, train, blocks = world
    fit = fit_joint(data, train, blocks, robust=False, bounded=False)
    x, scale = _dense(data, blocks)
    xt = x[np.repeat(train, 3)]
    y = data.b_raw_nt[train].reshape(-1)
    p = x.shape[1]
    ridge = np.diag(np.r_[np.full(12, 1e-10), np.full(p - 12, 1e-5)]) * xt.shape[0]
    theta = np.linalg.solve(xt.T @ xt + ridge, xt.T @ y) / scale
    np.testing.assert_allclose(fit.a.ravel(), theta[:9] / FIELD_SCALE_NT, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(fit.o_nt, theta[9:12], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(np.concatenate(fit.coef), theta[12:], rtol=1e-8, atol=1e-10)


def test_robust_bounded_fit_does_not_depend_on_the_block_size(world, monkeypatch) -> None:
    data, train, blocks = world
    fits = []
    for size in (5, 10**6):
        monkeypatch.setattr(blocked, "FIT_BLOCK_SAMPLES", size)
        fits.append(fit_joint(data, train, blocks))
    a, b = fits
    np.testing.assert_allclose(a.a, b.a, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(a.o_nt, b.o_nt, rtol=1e-9, atol=1e-9)
    # Effect parameters to a millionth of their standard error: the order of the sums moves an
    # ill-determined one (a clock drift's quadratic term) by ~1e-8 of its value.
    for ca, cb, cov in zip(a.coef, b.coef, b.coef_cov, strict=True):
        np.testing.assert_allclose(ca, cb, rtol=0.0, atol=1e-6 * float(np.sqrt(np.diag(cov)).min()))
    assert a.sigma_nt == pytest.approx(b.sigma_nt, rel=1e-9)
    np.testing.assert_allclose(a.cov_cal, b.cov_cal, rtol=1e-7, atol=1e-20)


@pytest.mark.parametrize("with_prior", [False, True])
def test_pair_screen_from_gram_matrices_equals_one_weighted_fit_per_pair(
    world, with_prior: bool
) -> None:
    """The pair screen solves every pair from two Gram matrices; each value equals the held-out
    RMS of that pair fitted on its own with the screen's fixed weights (fit_joint, one pass),
    beside fixed effects, with the bounds, the crust's prior and a calibration prior."""
    import dataclasses
    from itertools import combinations

    from orbitcal.diagnose.attribution import GroupSelection
    from orbitcal.diagnose.prior import CalibrationPrior

    data, train, blocks = world
    if with_prior:
        prior = CalibrationPrior(a=np.eye(3), o_nt=np.zeros(3))
        data = dataclasses.replace(data, calibration_prior=prior)
    _, holdout, _ = time_blocks(data.t_utc_s)
    names = ["temperature", "nonlinearity", "external_field", "sun_driven", "magnetorquer"]
    designs = {}
    for name in names:
        bl = get_effect(name).design(data, train)
        if bl is not None:
            designs[name] = bl
    assert len(designs) >= 3
    sel = GroupSelection(data, train, holdout, designs)
    fixed = [blocks[0]]  # the crust selected before
    base = fit_joint(data, train, fixed)
    sel.screen_huber_weights(data.b_raw_nt - base.predict_nt(data))
    pairs = list(combinations(designs.values(), 2))
    screened = sel.screen_pairs(fixed, pairs)
    each = [sel.screen_rms(fixed, [a, b]) for a, b in pairs]
    np.testing.assert_allclose(screened, each, rtol=1e-9)


def test_estimation_samples_are_all_up_to_the_cap_then_every_kth(monkeypatch) -> None:
    monkeypatch.setattr(blocked, "FIT_MAX_SAMPLES", 100)
    mask = np.zeros(1000, dtype=bool)
    mask[:100] = True
    np.testing.assert_array_equal(blocked.estimation_samples(mask), np.arange(100))
    mask[100:250] = True  # 250 samples: every 3rd (ceil(250 / 100))
    mask[600:601] = True  # a sample apart counts as any other
    index = blocked.estimation_samples(mask)
    np.testing.assert_array_equal(index, np.flatnonzero(mask)[::3])
    assert index.size <= 100
    assert blocked.estimation_samples(np.ones(1001, dtype=bool)).size == 91  # every 11th


def test_a_fit_on_every_kth_sample_agrees_with_the_full_fit_within_its_errors(
    world, monkeypatch
) -> None:
    """Above the cap a fit estimates on every k-th sample: its parameters are those of the fit on
    all of them within a few of their standard errors, its sum of squares stands for all the
    samples, and its residual (predicted at every sample) is as small to a hundredth."""
    data, train, blocks = world
    full = fit_joint(data, train, blocks)
    monkeypatch.setattr(blocked, "FIT_MAX_SAMPLES", int(train.sum()) // 3)
    thin = fit_joint(data, train, blocks)
    assert blocked.estimation_samples(train).size < 0.3 * train.sum()
    sd = np.sqrt(np.diag(thin.cov_cal))
    theta_full = np.r_[full.a.ravel(), full.o_nt]
    theta_thin = np.r_[thin.a.ravel(), thin.o_nt]
    assert np.all(np.abs(theta_thin - theta_full) < 4.0 * sd)
    for cf, ct, cov in zip(full.coef, thin.coef, thin.coef_cov, strict=True):
        assert np.all(np.abs(ct - cf) < 4.0 * np.sqrt(np.diag(cov)) + 1e-9 * np.abs(cf))
    assert thin.train_rss_nt2 == pytest.approx(full.train_rss_nt2, rel=0.1)
    r_full = data.b_raw_nt - full.predict_nt(data)
    r_thin = data.b_raw_nt - thin.predict_nt(data)
    assert np.sqrt(np.mean(r_thin**2)) == pytest.approx(np.sqrt(np.mean(r_full**2)), rel=0.01)


def test_rows_held_between_reweighting_steps_change_nothing(world, monkeypatch) -> None:
    """A fit's rows built once and held for its reweighting steps give the very same fit as rows
    built again at every step (bit for bit)."""
    data, train, blocks = world
    held = fit_joint(data, train, blocks)
    design = BlockedDesign(data, blocks)
    index = np.flatnonzero(train)
    y = data.b_raw_nt[index].reshape(-1)
    design.normal_equations(index, y, np.ones_like(y))
    assert design._held is not None and design._held[0] is index  # held for the next step
    monkeypatch.setattr(blocked, "HELD_ROWS_BYTES", 0)
    again = fit_joint(data, train, blocks)
    np.testing.assert_array_equal(held.a, again.a)
    np.testing.assert_array_equal(held.o_nt, again.o_nt)
    for a, b in zip(held.coef, again.coef, strict=True):
        np.testing.assert_array_equal(a, b)
    assert held.sigma_nt == again.sigma_nt and held.train_rss_nt2 == again.train_rss_nt2
