"""Exact marginal likelihoods of every model of up to ``max_effects`` effects, and the posterior.

In whitened space (unit innovations) a model ``S`` is the Gaussian linear model

    y = X_cal beta + X_S theta + e,    e ~ N(0, I),
    beta ~ N(beta_0, diag(v^2)),  theta ~ N(mu, diag(s^2)),

the calibration a group present in every model, with a wide proper prior centred on its
least-squares value (so that models whitened by different noise models compare: an improper
prior's constant would not cancel between them). With ``X = [X_cal X_S]``, ``m = [beta_0 mu]``,
``D = diag([v s])``, ``z = y - X m``, ``G = X'X`` and ``u = D X' z``, Woodbury's identity on
``y ~ N(X m, I + X D^2 X')`` gives

    -2 log m(S) = log det(I + D G D) + z'z - u' (I + D G D)^-1 u     (+ n log 2 pi)

Every term is a block of the one Gram matrix (:class:`~orbitcal.diagnose.model.gram.Gram`), so
~230 models cost ~230 Cholesky factorisations of at most a few tens of rows. An effect whose
columns the calibration absorbs leaves the evidence as the calibration alone has it: its
inclusion probability stays at the prior, which is how "cannot be separated from the
calibration" is read (:func:`project` measures how much of each group the calibration takes).

The prior on models: each of the ``K`` candidate effects present independently with probability
``pi = expected_effects / K`` (so that a larger catalogue does not make more effects likely: Scott
& Berger 2010), truncated to models of at most ``max_effects``.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray
from orbitcal.diagnose.model.gram import Form, Gram

__all__ = ["Augmented", "Posterior", "Projected", "augment", "log_evidence", "posterior", "project"]


@dataclass(frozen=True)
class Projected:
    """The Gram matrix with the calibration's columns integrated out."""

    cc_pinv: FloatArray
    g: FloatArray  # X_E' P X_E
    b: FloatArray  # X_E' P y
    q: float  # y' P y
    g_raw_diag: FloatArray  # diag(X_E' X_E)


@dataclass(frozen=True)
class Augmented:
    """The whole Gram matrix (calibration columns first) with the calibration's prior.

    ``g``, ``b``, ``q``: ``X'X``, ``X'y``, ``y'y`` over the calibration's 12 columns and then the
    effect columns; ``cal_mean``, ``cal_sd``: the calibration's prior; ``log_scale``: the sum over
    whitened rows of ``log sigma`` of their axis (the Jacobian of whitening: what makes the
    evidence of two noise models compare).
    """

    g: FloatArray
    b: FloatArray
    q: float
    cal_mean: FloatArray
    cal_sd: FloatArray
    log_scale: float


def augment(gram: Gram, cal_mean: FloatArray, cal_sd: FloatArray, log_scale: float) -> Augmented:
    """The Gram matrix as one block (calibration columns first)."""
    g = np.block([[gram.cc, gram.ce], [gram.ce.T, gram.ee]])
    return Augmented(0.5 * (g + g.T), np.r_[gram.cy, gram.ey], gram.yy, cal_mean, cal_sd, log_scale)


def _pinv_psd(a: FloatArray) -> FloatArray:
    """Pseudo-inverse of a symmetric positive semi-definite matrix (eigenvalues below 1e-10 of
    the largest dropped: a random-walk noise model's differencing removes the offsets)."""
    w, v = np.linalg.eigh(a)
    keep = w > 1e-10 * max(float(w.max()), 1e-300)
    return np.asarray((v[:, keep] / w[keep]) @ v[:, keep].T)


def project(gram: Gram) -> Projected:
    """Integrate the calibration's 12 parameters out (flat prior)."""
    inv = _pinv_psd(gram.cc)
    g = gram.ee - gram.ce.T @ inv @ gram.ce
    b = gram.ey - gram.ce.T @ inv @ gram.cy
    q = gram.yy - float(gram.cy @ inv @ gram.cy)
    return Projected(inv, 0.5 * (g + g.T), b, q, np.diag(gram.ee).copy())


def log_evidence(
    proj: Projected | Augmented, cols: npt.NDArray[np.intp], mean: FloatArray, sd: FloatArray
) -> tuple[float, FloatArray]:
    """``log m(S)`` up to the constant common to all models, and the posterior mean of
    ``theta`` (the model's parameters, in the order of ``cols``)."""
    if cols.size == 0:
        return -0.5 * proj.q, np.zeros(0)
    g = proj.g[np.ix_(cols, cols)]
    bz = proj.b[cols] - g @ mean
    zz = proj.q - 2.0 * float(mean @ proj.b[cols]) + float(mean @ g @ mean)
    gs = sd[:, None] * g * sd[None, :]
    m = np.eye(cols.size) + gs
    logdet, m_inv_u = _logdet_solve(m, sd * bz)
    log_m = -0.5 * (logdet + zz - float((sd * bz) @ m_inv_u))
    theta = mean + sd * m_inv_u
    return log_m, theta


def _logdet_solve(m: FloatArray, u: FloatArray) -> tuple[float, FloatArray]:
    """``log det m`` and ``m^-1 u`` for ``m = I + S G S``, positive definite in exact arithmetic
    (G is a Gram matrix). With a singular calibration Gram (a dead axis, a constant field) the
    projection leaves G indefinite in floating point: then through the eigenvalues, each held
    at or above 1 (the exact matrix's lower bound)."""
    try:
        chol = np.linalg.cholesky(m)
    except np.linalg.LinAlgError:
        vals, vecs = np.linalg.eigh(0.5 * (m + m.T))
        vals = np.where(np.isfinite(vals), np.maximum(vals, 1.0), 1.0)
        return float(np.sum(np.log(vals))), vecs @ ((vecs.T @ u) / vals)
    w = np.linalg.solve(chol, u)
    return 2.0 * float(np.sum(np.log(np.diag(chol)))), np.linalg.solve(chol.T, w)


def _cols(forms: Sequence[Form]) -> npt.NDArray[np.intp]:
    if not forms:
        return np.zeros(0, dtype=np.intp)
    return np.concatenate([np.arange(f.cols.start, f.cols.stop) for f in forms]).astype(np.intp)


def model_evidence(aug: Augmented, forms: Sequence[Form]) -> tuple[float, FloatArray]:
    """``log m`` of the calibration with ``forms``, and the posterior mean of its parameters
    (the calibration's 12, then each form's)."""
    cols = np.r_[np.arange(12), 12 + _cols(forms)] if forms else np.arange(12)
    mean = np.concatenate([aug.cal_mean, *(f.prior_mean for f in forms)])
    sd = np.concatenate([aug.cal_sd, *(f.prior_sd for f in forms)])
    return log_evidence(aug, cols.astype(np.intp), mean, sd)


@dataclass(frozen=True)
class Posterior:
    """The posterior over models of at most ``max_effects`` of the candidate effects.

    Attributes
    ----------
    effects : tuple of str
        The candidates (their witness in the data), in catalogue order.
    models : list of tuple of int
        Every model, as indices into ``effects``.
    prob : ndarray, shape (n_models,)
        Posterior probability of each model (sums to 1).
    log_evidence : ndarray, shape (n_models,)
        ``log m(S)`` of each model (with the forms' choice paid for).
    thetas : list of ndarray
        Each model's posterior mean of its effect parameters.
    """

    effects: tuple[str, ...]
    models: list[tuple[int, ...]]
    prob: FloatArray
    log_evidence: FloatArray
    thetas: list[FloatArray]

    def inclusion(self) -> dict[str, float]:
        """Each effect's posterior inclusion probability."""
        out = np.zeros(len(self.effects))
        for model, p in zip(self.models, self.prob, strict=True):
            out[list(model)] += p
        return {e: float(min(max(x, 0.0), 1.0)) for e, x in zip(self.effects, out, strict=True)}

    def pair(self, a: str, b: str) -> float:
        """Posterior probability that both ``a`` and ``b`` are present."""
        ia, ib = self.effects.index(a), self.effects.index(b)
        return float(
            sum(p for m, p in zip(self.models, self.prob, strict=True) if ia in m and ib in m)
        )

    def none(self) -> float:
        """Posterior probability that no effect is present."""
        return float(sum(p for m, p in zip(self.models, self.prob, strict=True) if not m))

    def of_model(self, names: Sequence[str]) -> float:
        """Posterior probability of exactly the model ``names``."""
        key = tuple(sorted(self.effects.index(n) for n in names))
        return float(sum(p for m, p in zip(self.models, self.prob, strict=True) if m == key))

    def median_model(self, cutoff: float = 0.5) -> tuple[str, ...]:
        """The effects whose inclusion probability is at least ``cutoff`` (0.5: the median
        probability model, Barbieri & Berger 2004), most probable first. When those are more
        effects than any model holds (four effects at 0.5 or more, each model of at most three
        of them), the most probable model's effects instead: the choice is always a model."""
        inc = self.inclusion()
        chosen = [e for e in self.effects if inc[e] >= cutoff]
        if len(chosen) > max((len(m) for m in self.models), default=0):
            best = self.models[int(np.argmax(self.prob))]
            chosen = [self.effects[i] for i in best]
        return tuple(sorted(chosen, key=lambda e: -inc[e]))


def log_model_prior(size: int, expected_effects: float, n_catalogue: int) -> float:
    """The log prior of one model of ``size`` effects: each of the ``n_catalogue`` effects in
    it independently at the rate ``expected_effects / n_catalogue``."""
    pi = min(max(expected_effects / max(n_catalogue, 1), 1e-9), 1.0 - 1e-9)
    return size * math.log(pi) + (n_catalogue - size) * math.log1p(-pi)


def posterior(
    aug: Augmented,
    forms: Sequence[Form],
    *,
    expected_effects: float,
    max_effects: int,
    n_catalogue: int,
) -> Posterior:
    """The posterior over every model of at most ``max_effects`` of ``forms``' effects (one form
    per effect: the caller has chosen it). ``log_evidence`` holds each model's log prior plus
    log evidence, the Jacobian of whitening included."""
    k = len(forms)
    models: list[tuple[int, ...]] = []
    logs, thetas = [], []
    for size in range(min(max_effects, k) + 1):
        for model in itertools.combinations(range(k), size):
            chosen = [forms[i] for i in model]
            log_m, theta = model_evidence(aug, chosen)
            log_m -= sum(math.log(f.n_forms) for f in chosen) + aug.log_scale
            prior = log_model_prior(size, expected_effects, n_catalogue)
            models.append(model)
            logs.append(log_m + prior)
            thetas.append(theta)
    log_post = np.array(logs)
    prob = np.exp(log_post - log_post.max())
    prob /= prob.sum()
    return Posterior(tuple(f.effect for f in forms), models, prob, log_post, thetas)


def log_sum_exp(terms: Sequence[float] | FloatArray) -> float:
    """``log sum exp`` of the finite ``terms`` (``-inf`` when none is)."""
    values = np.asarray(terms, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return -math.inf
    top = float(values.max())
    return top + math.log(float(np.sum(np.exp(values - top))))


def log_marginal(post: Posterior) -> float:
    """``log p(y)`` under the posterior's noise model: the log-sum of its models' terms."""
    return log_sum_exp(post.log_evidence)


def averaged(posts: Sequence[Posterior]) -> tuple[Posterior, FloatArray]:
    """The posterior averaged over noise models (each weighted by its ``p(y)``, equal prior
    weights), and the noise models' posterior weights. Models are matched by their effects;
    each model's parameters are those under the noise model of greatest weight."""
    marg = np.array([log_marginal(p) for p in posts])
    w = np.exp(marg - marg.max())
    w /= w.sum()
    best = posts[int(np.argmax(w))]
    prob = np.zeros(len(best.models))
    for p, wi in zip(posts, w, strict=True):
        assert p.effects == best.effects and p.models == best.models
        prob += wi * p.prob
    return dataclasses.replace(best, prob=prob / prob.sum()), w
