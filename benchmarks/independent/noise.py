"""Sensor noise of the independent generator: coloured, and different from axis to axis.

Kinds (``NOISE_KINDS``): ``white``; ``pink`` (1/f); ``random_walk`` (a wandering offset beside
white noise); ``ar1`` (a first-order autoregressive part, time constant 30-600 s, beside white
noise); ``per_axis`` (each axis its own kind among the four above and its own level, up to 3x
apart); and, on white noise, ``quantised``, ``spikes`` and ``gaps``.
"""

from __future__ import annotations

import numpy as np

COLOURED = ("white", "pink", "random_walk", "ar1")
NOISE_KINDS = (*COLOURED, "per_axis", "quantised", "spikes", "gaps")


def _one_axis(rng: np.random.Generator, t_s: np.ndarray, kind: str, sigma: float) -> np.ndarray:
    n = len(t_s)
    if kind == "pink":
        spec = np.fft.rfft(rng.normal(size=n))
        f = np.fft.rfftfreq(n)
        f[0] = f[1]
        x = np.fft.irfft(spec / np.sqrt(f), n=n)
        return sigma * x / x.std()
    if kind == "random_walk":
        walk = np.cumsum(rng.normal(size=n))
        walk -= walk.mean()
        return 0.5 * sigma * rng.normal(size=n) + sigma * walk / walk.std()
    if kind == "ar1":
        tau_s = rng.uniform(30.0, 600.0)
        a = np.exp(-np.r_[0.0, np.diff(t_s)] / tau_s)
        e = rng.normal(size=n) * np.sqrt(1.0 - a**2)
        x = np.empty(n)
        x[0] = rng.normal()
        for k in range(1, n):
            x[k] = a[k] * x[k - 1] + e[k]
        return 0.5 * sigma * rng.normal(size=n) + sigma * x
    return sigma * rng.normal(size=n)


def sensor_noise(
    rng: np.random.Generator, t_s: np.ndarray, kind: str, sigma: float
) -> tuple[np.ndarray, dict]:
    """(N, 3) noise of about ``sigma`` per axis, and what was drawn (kind and level per axis)."""
    if kind == "per_axis":
        kinds = [str(k) for k in rng.choice(COLOURED, size=3)]
        sigmas = [float(sigma * rng.uniform(1.0, 3.0) ** rng.choice([-0.5, 0.5])) for _ in kinds]
    else:
        base = kind if kind in COLOURED else "white"
        kinds, sigmas = [base] * 3, [sigma] * 3
    out = np.column_stack([_one_axis(rng, t_s, k, s) for k, s in zip(kinds, sigmas, strict=True)])
    return out, {"kind": kind, "axis_kinds": kinds, "axis_sigma_nt": sigmas}


def damage(
    rng: np.random.Generator, raw: np.ndarray, kind: str, sigma: float
) -> tuple[np.ndarray, np.ndarray]:
    """Quantisation or spikes applied to ``raw``; the samples kept (gaps dropped)."""
    n = len(raw)
    raw = raw.copy()
    if kind == "quantised":
        raw = np.round(raw / (2.0 * sigma)) * (2.0 * sigma)
    if kind == "spikes":
        hit = rng.random(n) < 0.005
        raw[hit] += rng.normal(scale=300.0, size=(int(hit.sum()), 3))
    keep = np.ones(n, dtype=bool)
    if kind == "gaps":
        for _ in range(int(rng.integers(3, 7))):
            a = int(rng.integers(0, max(n - 60, 1)))
            keep[a : a + int(rng.integers(10, 60))] = False
    return raw, keep
