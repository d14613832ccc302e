"""Exact marginal likelihoods of every model of up to ``max_effects`` effects, and the posterior.

In whitened space (unit innovations) a model ``S`` is the Gaussian linear model

    y = X_cal beta + X_S theta + e,    e ~ N(0, I),  theta ~ N(mu, diag(s^2)),

with a flat prior on the 12 calibration parameters ``beta`` (common to every model, so its
improper constant cancels in the posterior). Integrating ``beta`` out projects ``y`` and ``X_S``
on the complement of the calibration's columns (``P = I - X_cal X_cal^+``); integrating
``theta``, with ``z = P (y - X_S mu)``, ``G = X_S' P X_S`` and ``u = diag(s) X_S' z``:

    -2 log m(S) = log det(I + diag(s) G diag(s)) + z'z - u' (I + diag(s) G diag(s))^-1 u + const

(Woodbury's identity on ``z ~ N(0, I + P X_S diag(s^2) X_S' P)``). Every term is a block of the one
Gram matrix (:class:`~orbitcal.diagnose.model.gram.Gram`), so ~230 models cost ~230 Cholesky
factorisations of at most a few tens of rows. An effect whose columns the calibration absorbs has
``G`` near zero: its evidence equals the null's, and its inclusion probability stays at the prior,
which is how "cannot be separated from the calibration" is read.

The prior on models: each of the ``K`` candidate effects present independently with probability
``pi = expected_effects / K`` (so that a larger catalogue does not make more effects likely: Scott
& Berger 2010), truncated to models of at most ``max_effects``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray
from orbitcal.diagnose.model.gram import Form, Gram

__all__ = ["Posterior", "Projected", "log_evidence", "posterior", "project"]


@dataclass(frozen=True)
class Projected:
    """The Gram matrix with the calibration's columns integrated out."""

    cc_pinv: FloatArray
    g: FloatArray  # X_E' P X_E
    b: FloatArray  # X_E' P y
    q: float  # y' P y
    g_raw_diag: FloatArray  # diag(X_E' X_E)


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
    proj: Projected, cols: npt.NDArray[np.intp], mean: FloatArray, sd: FloatArray
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
    chol = np.linalg.cholesky(m)
    u = sd * bz
    w = np.linalg.solve(chol, u)
    logdet = 2.0 * float(np.sum(np.log(np.diag(chol))))
    log_m = -0.5 * (logdet + zz - float(w @ w))
    theta = mean + sd * np.linalg.solve(chol.T, w)
    return log_m, theta


def _cols(forms: Sequence[Form]) -> npt.NDArray[np.intp]:
    return np.concatenate([np.arange(f.cols.start, f.cols.stop) for f in forms]).astype(np.intp)


def form_evidence(proj: Projected, form: Form) -> float:
    """``log m`` of the model with this form alone."""
    return log_evidence(proj, _cols([form]), form.prior_mean, form.prior_sd)[0]


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
        probability model, Barbieri & Berger 2004), most probable first."""
        inc = self.inclusion()
        return tuple(sorted((e for e in self.effects if inc[e] >= cutoff), key=lambda e: -inc[e]))


def posterior(
    proj: Projected,
    forms: Sequence[Form],
    *,
    expected_effects: float,
    max_effects: int,
    n_catalogue: int,
) -> Posterior:
    """The posterior over every model of at most ``max_effects`` of ``forms``' effects (one form
    per effect: the caller has chosen it)."""
    k = len(forms)
    pi = min(max(expected_effects / max(n_catalogue, 1), 1e-9), 1.0 - 1e-9)
    models: list[tuple[int, ...]] = []
    logs, thetas = [], []
    for size in range(min(max_effects, k) + 1):
        for model in itertools.combinations(range(k), size):
            chosen = [forms[i] for i in model]
            cols = _cols(chosen) if chosen else np.zeros(0, dtype=np.intp)
            mean = np.concatenate([f.prior_mean for f in chosen]) if chosen else np.zeros(0)
            sd = np.concatenate([f.prior_sd for f in chosen]) if chosen else np.zeros(0)
            log_m, theta = log_evidence(proj, cols, mean, sd)
            log_m -= sum(math.log(f.n_forms) for f in chosen)
            prior = size * math.log(pi) + (n_catalogue - size) * math.log1p(-pi)
            models.append(model)
            logs.append(log_m + prior)
            thetas.append(theta)
    log_post = np.array(logs)
    prob = np.exp(log_post - log_post.max())
    prob /= prob.sum()
    return Posterior(tuple(f.effect for f in forms), models, prob, np.array(logs), thetas)
