"""Seed 003: a learned model of the reference field's own error as a function of position.

CN109855623A (Southeast University, Wang Lihui and Liu Qingya, 2019): "Online approximation of a
geomagnetic model by Legendre polynomials and a BP network". Step 2: a regional model of each field
component as Legendre polynomials of latitude and longitude, truncation order ``N_off = 3``,
fitted by least squares; step 3: a BP network (one hidden layer of 6 sigmoid nodes, linear
outputs) learns the measured minus modelled field from the position and auxiliary state;
step 4: the model plus the network corrects the field.

Here the "measured minus modelled field" is the calibrated residual in NEC components, so that a
static field in Earth-fixed coordinates is a fixed function of position. The patent's step 2 is
regional (an underwater vehicle stays in one box); a spacecraft's held-out later passes lie
*between* its training passes all round the globe, where a regional polynomial of order 3 has
nothing to say. So step 2 has two candidates, fitted on the training blocks only:

* ``legendre``: the patent's regional model, the box covered by the training blocks, no
  correction outside it;
* ``spherical_harmonic``: a global internal potential field ``B = -grad V`` in geocentric NEC
  (Schmidt semi-normalised, reference radius 6371.2 km), the form of the crust (static, internal,
  Earth-fixed). The degree and the damping are chosen by cross-validation over the training time
  blocks (leave one block out); the damping is the mean square of ``B_r`` over the reference
  sphere, ``sum (n+1)^2/(2n+1) (g^2 + h^2)``, the norm crustal modellers use, which suppresses
  the high degrees that the altitude attenuates.

The same cross-validation (plus the no-correction option ``none``) chooses the stage: never the
held-out blocks. The BP network (step 3) is then fitted to what the stage leaves on the training
blocks but the last, and kept only if it lowers the residual on that last training block by more
than 1 %; it is
regional (no correction outside its training box of inputs). The patent's eight navigation-error
inputs (not available on a spacecraft) are replaced by the radius, the magnetic local time (sin,
cos) and the RC index, which organise the magnetospheric part. The chosen stage plus the network
is scored on the held-out later blocks, as every candidate is: a data-driven stand-in for crustal
and external fields when no model explains them.

What it can and cannot do: the spherical-harmonic stage predicts what the training passes sample.
Over a few orbits the tracks are ~24 deg apart in longitude and a crust of degree 16 and above is
not determined between them: the gain is small (a 5-orbit Swarm A world with MF7 and LCS-1 offered:
held-out 2.09 -> 1.73 nT, degree 37). Over days the tracks are a few degrees apart, the held-out
passes interleave with them, and degree 30-40 (most of the crust's signal at 400-500 km) is
determined: 4 days of Swarm A with MF7 and no crust model, 3.47 -> 1.37 nT at degree 40
(tests/test_diagnose_learned.py). The maximum degree is capped by cost (the normal matrix costs
rows x K^2 for K = n(n+2) coefficients), at most :data:`SH_MAX_DEGREE`; beyond
:data:`SH_MAX_SAMPLES` training samples the stage uses every k-th one; a training span shorter
than one orbit gets no global stage (its contiguous folds would only test along-track
interpolation). A whole call takes about 4 s of one core for 10^4 to 4 x 10^4 samples.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.polynomial import legendre
from scipy import linalg
from scipy.optimize import least_squares

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.effects import DiagnosisData
from orbitcal.diagnose.orbit_phase import MU_EARTH_KM3_S2
from orbitcal.field.synthesis import (
    EARTH_REFERENCE_RADIUS_KM,
    synth_internal_nec_nt,
    to_degree_blocks,
)
from orbitcal.metrics import norm_rms_nt

__all__ = [
    "LEARNED_MIN_TIMES_NOISE",
    "LEGENDRE_ORDER",
    "N_HIDDEN",
    "SH_MAX_DEGREE",
    "learned_field_error",
    "learned_field_model",
    "legendre_design",
    "not_fitted_summary",
    "sh_design_nec",
]


#: Truncation order of the regional Legendre model (CN109855623A: N_off = 3).
LEGENDRE_ORDER = 3
#: Hidden sigmoid nodes of the BP network (CN109855623A: 6).
N_HIDDEN = 6
#: Highest degree of the global spherical-harmonic stage (K = 1680 coefficients).
SH_MAX_DEGREE = 40
#: Cost cap of the spherical-harmonic normal matrix: training rows x K^2 (about 1.5 s of one
#: core); with 3 x 8000 training rows it allows degree 40.
SH_COST_BUDGET = 7.0e10
#: Training samples the spherical-harmonic stage uses at most (every k-th beyond): 9000 samples at
#: 30 s are tracks 230 km apart along track, finer than degree 40 (half wavelength 500 km) needs.
SH_MAX_SAMPLES = 9000
#: Leave-one-out folds of the training time span (cross-validation of stage, degree, damping).
N_FOLDS = 5
#: Damping candidates, in units of the training residual's mean square per component (a noise
#: to prior variance ratio: the coefficients are nT at the reference radius, like the data).
SH_DAMPING = (0.03, 0.3, 3.0)
#: Training samples the network is fitted on at most (evenly spaced in time): 63 weights need far
#: fewer than 3 x 2000 residuals, and MINPACK's unblocked QR costs rows x weights^2 per step.
NET_MAX_SAMPLES = 2000
#: Relative drop of the last training fold's RMS the network must bring to be kept.
NET_MIN_GAIN = 0.01
#: The summary of what the final model leaves is fitted only when its held-out residual per
#: component exceeds the white-noise floor by more than this factor [-]: within 10 % of the floor
#: no more than 0.46 sigma of structure can remain (sqrt(1.1^2 - 1)), and on a day at 1 Hz whose
#: effect the final model takes up the fit was a quarter of the diagnosis's time.
LEARNED_MIN_TIMES_NOISE = 1.1
_CHUNK = 1024
_POLE_EPS_RAD = 1e-9


def _nec_basis(r_itrs_km: FloatArray) -> FloatArray:
    from orbitcal.frames import nec_basis_itrs

    return np.asarray(nec_basis_itrs(r_itrs_km))


def legendre_design(x: FloatArray, y: FloatArray, *, order: int = LEGENDRE_ORDER) -> FloatArray:
    """Products ``P_m(x) P_n(y)`` with ``m + n <= order`` for x, y in [-1, 1], shape (N, k)."""
    cols = []
    for m in range(order + 1):
        for n in range(order + 1 - m):
            cm = np.zeros(m + 1)
            cm[m] = 1.0
            cn = np.zeros(n + 1)
            cn[n] = 1.0
            cols.append(legendre.legval(x, cm) * legendre.legval(y, cn))
    return np.column_stack(cols)


# ---- spherical harmonics -----------------------------------------------------------------------


def _sh_design_t(
    radius_km: FloatArray, colat_rad: FloatArray, lon_rad: FloatArray, nmax: int
) -> FloatArray:
    """Design of the internal field, layout (K, 3, N): coefficient, N/E/C, point.

    Schmidt semi-normalised ``P_n^m(cos θ)`` and ``dP_n^m/dθ`` by the three-term recursion in
    degree, vectorised over points and orders (Langel 1987, eqs. 4.7-4.9, as in
    :mod:`orbitcal.field.synthesis`). Coefficients in the flat order ``g10, g11, h11, g20, ..``.
    With ``V = a sum (a/r)^(n+1) P_n^m (g cos mφ + h sin mφ)`` and ``B = -grad V``:
    ``B_N = -B_θ = (a/r)^(n+2) dP (..)``, ``B_E = B_φ = (a/r)^(n+2) m P / sin θ (g sin - h cos)``,
    ``B_C = -B_r = -(n+1) (a/r)^(n+2) P (..)``.
    """
    npts = radius_km.shape[0]
    out = np.empty((nmax * (nmax + 2), 3, npts))
    theta = np.clip(colat_rad, _POLE_EPS_RAD, np.pi - _POLE_EPS_RAD)
    x = np.cos(theta)
    s = np.sin(theta)
    orders = np.arange(nmax + 1, dtype=np.float64)
    mphi = orders[:, None] * lon_rad[None, :]
    cosm = np.cos(mphi)
    sinm = np.sin(mphi)
    m_over_s = orders[:, None] / s[None, :]
    ar = EARTH_REFERENCE_RADIUS_KM / radius_km
    rr = ar * ar
    p_prev = np.zeros((2, npts))
    p_prev[0] = 1.0
    dp_prev = np.zeros((2, npts))
    p_prev2 = np.zeros((1, npts))
    dp_prev2 = np.zeros((1, npts))
    for n in range(1, nmax + 1):
        m = np.arange(n, dtype=np.float64)
        den = np.sqrt(n * n - m * m)
        a_n = ((2 * n - 1) / den)[:, None]
        b_n = (np.sqrt(np.clip((n - 1) ** 2 - m * m, 0.0, None)) / den)[:, None]
        d_n = 1.0 if n == 1 else float(np.sqrt((2 * n - 1) / (2 * n)))
        p = np.zeros((n + 2, npts))
        dp = np.zeros((n + 2, npts))
        p[:n] = a_n * (x * p_prev[:n]) - b_n * p_prev2[:n]
        dp[:n] = a_n * (x * dp_prev[:n] - s * p_prev[:n]) - b_n * dp_prev2[:n]
        p[n] = d_n * s * p_prev[n - 1]
        dp[n] = d_n * (s * dp_prev[n - 1] + x * p_prev[n - 1])
        rr = rr * ar  # (a/r)^(n+2)
        pn = p[: n + 1] * rr
        dpn = dp[: n + 1] * rr
        c = cosm[: n + 1]
        sn = sinm[: n + 1]
        pe = pn * m_over_s[: n + 1]
        col = n * n - 1  # g_n0
        ig = col + np.concatenate([[0], 2 * np.arange(1, n + 1) - 1])
        ih = col + 2 * np.arange(1, n + 1)
        out[ig, 0] = dpn * c
        out[ig, 1] = pe * sn
        out[ig, 2] = -(n + 1) * pn * c
        out[ih, 0] = (dpn * sn)[1:]
        out[ih, 1] = -(pe * c)[1:]
        out[ih, 2] = -(n + 1) * (pn * sn)[1:]
        p_prev2, dp_prev2 = p_prev, dp_prev
        p_prev, dp_prev = p, dp
    return out


def sh_design_nec(
    radius_km: FloatArray, colat_deg: FloatArray, lon_deg: FloatArray, *, nmax: int
) -> FloatArray:
    """Design matrix of an internal potential field in geocentric NEC, shape (N, 3, K).

    ``sh_design_nec(r, θ, φ, nmax=n) @ g`` equals
    ``synth_internal_nec_nt(to_degree_blocks(g, n), r, θ, φ, nmax=n)`` for Gauss coefficients
    ``g`` in the flat order ``g10, g11, h11, g20, g21, h21, g22, h22, ..`` (K = n (n + 2)) [nT].

    Parameters
    ----------
    radius_km, colat_deg, lon_deg : ndarray, shape (N,)
        Geocentric radius [km], colatitude [deg] and east longitude [deg].
    nmax : int
        Maximum degree.
    """
    r = np.asarray(radius_km, dtype=np.float64).reshape(-1)
    th = np.radians(np.asarray(colat_deg, dtype=np.float64)).reshape(-1)
    ph = np.radians(np.asarray(lon_deg, dtype=np.float64)).reshape(-1)
    return np.ascontiguousarray(np.transpose(_sh_design_t(r, th, ph, nmax), (2, 1, 0)))


def _degree_of_column(nmax: int) -> FloatArray:
    return np.concatenate([np.full(2 * n + 1, float(n)) for n in range(1, nmax + 1)])


def _sh_normal_equations(
    radius_km: FloatArray,
    colat_rad: FloatArray,
    lon_rad: FloatArray,
    y_nec: FloatArray,
    nmax: int,
) -> tuple[FloatArray, FloatArray, float]:
    """``A^T A`` (K, K), ``A^T y`` (K,) and ``y^T y`` of the points given, chunk by chunk."""
    k = nmax * (nmax + 2)
    gram = np.zeros((k, k))
    rhs = np.zeros(k)
    for start in range(0, radius_km.shape[0], _CHUNK):
        sl = slice(start, start + _CHUNK)
        d = _sh_design_t(radius_km[sl], colat_rad[sl], lon_rad[sl], nmax).reshape(k, -1)
        # A^T A = d d^T on the upper triangle (half the cost of a product).
        gram = linalg.blas.dsyrk(1.0, d.T, beta=1.0, c=gram, trans=1, lower=0, overwrite_c=1)
        rhs += d @ y_nec[sl].T.reshape(-1)
    gram = np.triu(gram) + np.triu(gram, 1).T
    return gram, rhs, float(np.sum(y_nec**2))


def _sh_fit(
    gram: FloatArray,
    rhs: FloatArray,
    degree: int,
    damping: float,
    weights: FloatArray,
    left_out: tuple[FloatArray, FloatArray] | None = None,
) -> FloatArray:
    """Damped coefficients to ``degree`` from the normal equations (less a left-out fold's)."""
    k = degree * (degree + 2)
    if left_out is None:
        lhs = gram[:k, :k].copy()
    else:  # only the block of the degree asked for, not the whole difference
        lhs = gram[:k, :k] - left_out[0][:k, :k]
        rhs = rhs[:k] - left_out[1][:k]
    lhs += np.diag(damping * weights[:k])
    lhs[np.diag_indices(k)] += 1e-10 * float(np.trace(lhs)) / k + 1e-300
    return np.asarray(
        linalg.cho_solve(linalg.cho_factor(lhs, check_finite=False), rhs[:k], check_finite=False)
    )


def _sh_stage(
    t_utc_s: FloatArray,
    radius_km: FloatArray,
    colat_rad: FloatArray,
    lon_rad: FloatArray,
    y_nec: FloatArray,
    train: BoolArray,
    fold: npt.NDArray[np.intp],
    n_folds: int,
) -> dict[str, Any]:
    """Cross-validated degree and damping on the training folds; the fit on all of them."""
    idx = np.flatnonzero(train)
    if idx.size > SH_MAX_SAMPLES:
        # Every k-th sample: along-track neighbours are redundant at these degrees, and fewer rows
        # buy a higher degree within the cost budget.
        train = np.zeros_like(train)
        train[idx[:: -(-idx.size // SH_MAX_SAMPLES)]] = True
    n_rows = 3 * int(train.sum())
    nmax = 0
    for n in range(1, SH_MAX_DEGREE + 1):
        k = n * (n + 2)
        if n_rows * k * k > SH_COST_BUDGET or k > n_rows // 4:
            break
        nmax = n
    # Contiguous folds of less than one orbit are pieces of the same arcs: their cross-validation
    # measures along-track interpolation, not the prediction of other passes.
    t = t_utc_s[train]
    period_s = 2.0 * np.pi * np.sqrt(float(np.mean(radius_km[train])) ** 3 / MU_EARTH_KM3_S2)
    if nmax < 2 or n_folds < 2 or float(np.ptp(t)) < period_s:
        return {"degree": 0, "cap": nmax}
    ms = max(float(np.mean(y_nec[train] ** 2)), 1e-6)
    weights = _degree_of_column(nmax)
    weights = (weights + 1.0) ** 2 / (2.0 * weights + 1.0)
    parts = []
    for f in range(n_folds):
        sel = np.flatnonzero(train & (fold == f))
        parts.append(
            _sh_normal_equations(radius_km[sel], colat_rad[sel], lon_rad[sel], y_nec[sel], nmax)
        )
    g_all = sum(p[0] for p in parts)
    h_all = sum(p[1] for p in parts)
    yy_all = sum(p[2] for p in parts)
    assert isinstance(g_all, np.ndarray) and isinstance(h_all, np.ndarray)

    def cv_ms(degree: int, beta: float) -> float:
        """Mean square per component over the left-out folds."""
        sse = 0.0
        for g_f, h_f, yy_f in parts:
            c = _sh_fit(g_all, h_all, degree, beta * ms, weights, left_out=(g_f, h_f))
            k = c.shape[0]
            sse += yy_f - 2.0 * float(c @ h_f[:k]) + float(c @ g_f[:k, :k] @ c)
        return sse / n_rows

    degrees = sorted({*range(5, nmax + 1, 5), nmax} - {0, 1})
    beta0 = SH_DAMPING[len(SH_DAMPING) // 2]
    table = {(d, beta0): cv_ms(d, beta0) for d in degrees}
    best_deg = min(degrees, key=lambda d: table[(d, beta0)])
    for beta in SH_DAMPING:
        if (best_deg, beta) not in table:
            table[(best_deg, beta)] = cv_ms(best_deg, beta)
    best_deg, best_beta = min(table, key=lambda key: table[key])
    coef = _sh_fit(g_all, h_all, best_deg, best_beta * ms, weights)
    return {
        "degree": best_deg,
        "cap": nmax,
        "damping": best_beta * ms,
        "coefficients": coef,
        "cv_rms_nt": float(np.sqrt(3.0 * table[(best_deg, best_beta)])),
        "cv_rms_by_degree_nt": {d: float(np.sqrt(3.0 * table[(d, beta0)])) for d in degrees},
        "cv_none_rms_nt": float(np.sqrt(3.0 * yy_all / n_rows)),
    }


def _lowes_spectrum(coef: FloatArray, nmax: int) -> list[float]:
    """Mean square field over the reference sphere per degree, ``(n+1) sum_m g^2 + h^2`` [nT^2]."""
    deg = _degree_of_column(nmax)
    return [float((n + 1) * np.sum(coef[deg == n] ** 2)) for n in range(1, nmax + 1)]


# ---- BP network ----------------------------------------------------------------------------------


def _unpack(theta: FloatArray, n_in: int) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    h = N_HIDDEN
    w1 = theta[: n_in * h].reshape(n_in, h)
    b1 = theta[n_in * h : n_in * h + h]
    w2 = theta[n_in * h + h : n_in * h + h + 3 * h].reshape(h, 3)
    b2 = theta[n_in * h + h + 3 * h :]
    return w1, b1, w2, b2


def _hidden(theta: FloatArray, x: FloatArray, n_in: int) -> FloatArray:
    w1, b1, _, _ = _unpack(theta, n_in)
    return np.asarray(1.0 / (1.0 + np.exp(-np.clip(x @ w1 + b1, -50.0, 50.0))))


def _net(theta: FloatArray, x: FloatArray, n_in: int) -> FloatArray:
    _, _, w2, b2 = _unpack(theta, n_in)
    return np.asarray(_hidden(theta, x, n_in) @ w2 + b2)


def _net_jacobian(theta: FloatArray, x: FloatArray, n_in: int) -> FloatArray:
    """d(net output, raveled (N, 3)) / d theta, analytic (back-propagation), (3N, P)."""
    _, _, w2, _ = _unpack(theta, n_in)
    hid = _hidden(theta, x, n_in)
    slope = hid * (1.0 - hid)
    npts = x.shape[0]
    eye = np.eye(3)
    j_w1 = np.einsum("ni,np,pq->nqip", x, slope, w2).reshape(npts, 3, -1)
    j_b1 = np.einsum("np,pq->nqp", slope, w2)
    j_w2 = np.einsum("np,qr->nqpr", hid, eye).reshape(npts, 3, -1)
    j_b2 = np.broadcast_to(eye, (npts, 3, 3))
    return np.concatenate([j_w1, j_b1, j_w2, j_b2], axis=2).reshape(3 * npts, -1)


def _fit_net(
    x: FloatArray, y: FloatArray, rng: np.random.Generator, max_nfev: int
) -> tuple[FloatArray, float]:
    """Levenberg-Marquardt fit of the network to ``y`` (scaled to unit spread); (theta, scale)."""
    n_in = x.shape[1]
    y_scale = max(float(np.std(y)), 1e-9)
    n_par = n_in * N_HIDDEN + N_HIDDEN + 3 * N_HIDDEN + 3
    theta0 = rng.normal(scale=0.5, size=n_par)
    yt = y / y_scale

    def fun(theta: FloatArray) -> FloatArray:
        return (_net(theta, x, n_in) - yt).ravel()

    def jac(theta: FloatArray) -> FloatArray:
        return _net_jacobian(theta, x, n_in)

    sol = least_squares(fun, theta0, jac=jac, method="lm", max_nfev=max_nfev)
    return np.asarray(sol.x), y_scale


# ---- the model ---------------------------------------------------------------------------------


def _training_folds(t: FloatArray, train: BoolArray) -> tuple[npt.NDArray[np.intp], int]:
    """Equal-duration folds of the training span (-1 outside training); empty folds dropped."""
    fold = np.full(t.shape[0], -1, dtype=np.intp)
    if not train.any():
        return fold, 0
    t0, t1 = float(t[train].min()), float(t[train].max())
    raw = np.minimum(((t - t0) / max(t1 - t0, 1e-9) * N_FOLDS).astype(np.intp), N_FOLDS - 1)
    used = [f for f in range(N_FOLDS) if np.any(train & (raw == f))]
    for new, f in enumerate(used):
        fold[train & (raw == f)] = new
    return fold, len(used)


def not_fitted_summary(reason: str) -> dict[str, Any]:
    """The summary of a learned model not fitted, and why (``fitted`` False, ``not_fitted_reason``),
    with the model's fixed settings."""
    return {
        "method": _METHOD,
        "fitted": False,
        "not_fitted_reason": reason,
        "stage_chosen": "none",
        "legendre_order": LEGENDRE_ORDER,
        "hidden_nodes": N_HIDDEN,
    }


def learned_field_error(
    data: DiagnosisData,
    residual_body_nt: FloatArray,
    *,
    train: BoolArray,
    holdout: BoolArray,
    rng: np.random.Generator | None = None,
    max_nfev: int = 60,
) -> dict[str, Any]:
    """Fit the seed-003 model to a residual on ``train``; score it on ``holdout``.

    The summary of :func:`learned_field_model` (see there).
    """
    return learned_field_model(
        data, residual_body_nt, train=train, holdout=holdout, rng=rng, max_nfev=max_nfev
    )[0]


def learned_field_model(
    data: DiagnosisData,
    residual_body_nt: FloatArray,
    *,
    train: BoolArray,
    holdout: BoolArray,
    rng: np.random.Generator | None = None,
    max_nfev: int = 60,
) -> tuple[dict[str, Any], FloatArray]:
    """Fit the seed-003 model to a residual on ``train``; score it on ``holdout``.

    Returns the summary below and the model's correction at every sample, body axes [nT]
    (zero when the chosen stage is ``none``), fitted on ``train`` only.

    Parameters
    ----------
    data : DiagnosisData
    residual_body_nt : ndarray, shape (N, 3)
        Residual to learn, body axes [nT].
    train, holdout : ndarray of bool
    rng : numpy.random.Generator, optional
        Network initialisation (default seed 0).
    max_nfev : int
        Levenberg-Marquardt evaluations for the network.

    Returns
    -------
    dict
        ``stage_chosen`` (``none``, ``legendre`` or ``spherical_harmonic``, by cross-validation
        over the training blocks), ``cv_rms_nt`` per stage, ``legendre_order``, ``sh_degree``,
        ``sh_damping``, ``sh_lowes_spectrum_nt2``, ``hidden_nodes``, ``inputs``,
        ``network_used`` and ``network_validation_rms_nt``; held-out scores
        ``holdout_rms_before_nt``, ``holdout_rms_legendre_nt`` and ``holdout_rms_sh_nt`` (each
        stage alone), ``holdout_rms_stage_nt`` (the chosen stage), ``holdout_rms_after_nt`` (the
        chosen stage plus the network if used) and ``shrink``; ``legendre_coefficients_nt``.
    """
    rng = rng if rng is not None else np.random.default_rng(0)
    train = np.asarray(train, dtype=bool)
    holdout = np.asarray(holdout, dtype=bool)
    track = _track_of(data, residual_body_nt)
    fold, n_folds = _training_folds(data.t_utc_s, train)
    stages = _fit_stages(data, track, train, fold, n_folds)
    stage_pred = stages.prediction()
    rest = track.r_nec - stage_pred

    # Patent step 3: the BP network on what the stage leaves.
    lo_lat, hi_lat, lo_lon, hi_lon = track.box(train)
    x, names = _network_inputs(
        data,
        _unit_scale(track.lat, lo_lat, hi_lat),
        _unit_scale(track.lon, lo_lon, hi_lon),
        track.radius,
        train,
        _unit_scale,
    )
    net, inside, val_without, val_with, net_used = _network_stage(
        x, rest, train, fold, n_folds, stages.inside_box, rng, max_nfev
    )
    after_nec = stage_pred + (net if net_used else 0.0)

    def body(v_nec: FloatArray) -> FloatArray:
        v_itrs = np.einsum("nji,nj->ni", track.basis, v_nec)
        return np.einsum("nij,nj->ni", data.rot_itrs_to_body, v_itrs)

    def held(v_nec: FloatArray) -> float:
        return norm_rms_nt((residual_body_nt - body(v_nec))[holdout])

    before = norm_rms_nt(residual_body_nt[holdout])
    after = held(after_nec)
    deg = int(stages.sh["degree"])
    summary = {
        **_stage_summary(stages),
        "hidden_nodes": N_HIDDEN,
        "inputs": names,
        "network_used": net_used,
        "network_validation_rms_nt": {"without": val_without, "with": val_with},
        "region_deg": {"lat": [lo_lat, hi_lat], "lon": [lo_lon, hi_lon]},
        "holdout_rms_before_nt": before,
        "holdout_rms_legendre_nt": held(stages.legendre_pred),
        "holdout_rms_sh_nt": held(stages.sh_pred) if deg else before,
        "holdout_rms_stage_nt": held(stage_pred),
        "holdout_rms_after_nt": after,
        "shrink": before / max(after, 1e-12),
        "holdout_fraction_inside_region": float(np.mean(inside[holdout])) if holdout.any() else 0.0,
        "legendre_coefficients_nt": {
            comp: stages.legendre_coef[:, k].round(4).tolist()
            for k, comp in enumerate(("N", "E", "C"))
        },
    }
    return summary, body(after_nec)


@dataclass(frozen=True)
class _Track:
    """The residual in the local NEC frame and where each sample is."""

    basis: FloatArray  # (N, 3, 3): ITRS to NEC
    r_nec: FloatArray  # (N, 3) [nT]
    radius: FloatArray  # [km]
    colat: FloatArray  # [rad]
    lon_rad: FloatArray  # [rad]
    lat: FloatArray  # geocentric latitude [deg]
    lon: FloatArray  # [deg]

    def box(self, mask: BoolArray) -> tuple[float, float, float, float]:
        """The latitude and longitude box of the samples ``mask`` [deg]."""
        return (
            float(self.lat[mask].min()),
            float(self.lat[mask].max()),
            float(self.lon[mask].min()),
            float(self.lon[mask].max()),
        )


def _track_of(data: DiagnosisData, residual_body_nt: FloatArray) -> _Track:
    """The residual ``residual_body_nt`` (body axes) in NEC, and the samples' coordinates."""
    r = data.r_itrs_km
    basis = _nec_basis(r)
    r_itrs = np.einsum("nji,nj->ni", data.rot_itrs_to_body, residual_body_nt)
    radius = np.linalg.norm(r, axis=1)
    colat = np.arccos(np.clip(r[:, 2] / radius, -1.0, 1.0))
    lon_rad = np.arctan2(r[:, 1], r[:, 0])
    return _Track(
        basis=basis,
        r_nec=np.einsum("nij,nj->ni", basis, r_itrs),
        radius=radius,
        colat=colat,
        lon_rad=lon_rad,
        lat=90.0 - np.degrees(colat),
        lon=np.degrees(lon_rad),
    )


def _unit_scale(v: FloatArray, lo: float, hi: float) -> FloatArray:
    """``v`` mapped from ``[lo, hi]`` to ``[-1, 1]`` (clipped)."""
    return np.clip(2.0 * (v - lo) / max(hi - lo, 1e-9) - 1.0, -1.0, 1.0)


def _legendre_fit(track: _Track, mask: BoolArray) -> tuple[FloatArray, FloatArray, BoolArray]:
    """Patent step 2 on ``mask``: (prediction everywhere, zero outside its box; coef; box)."""
    lo_lat, hi_lat, lo_lon, hi_lon = track.box(mask)
    design = legendre_design(
        _unit_scale(track.lat, lo_lat, hi_lat), _unit_scale(track.lon, lo_lon, hi_lon)
    )
    coef = np.asarray(np.linalg.lstsq(design[mask], track.r_nec[mask], rcond=None)[0], float)
    lat, lon = track.lat, track.lon
    inside = (lat >= lo_lat) & (lat <= hi_lat) & (lon >= lo_lon) & (lon <= hi_lon)
    return np.asarray(np.where(inside[:, None], design @ coef, 0.0), float), coef, inside


@dataclass(frozen=True)
class _Stages:
    """Step 2's candidates fitted on the training blocks, and the one cross-validation chose."""

    cv_ms: dict[str, float]  # mean square per stage over the left-out folds [nT^2]
    sh: dict[str, Any]  # :func:`_sh_stage`'s summary
    sh_pred: FloatArray  # NEC [nT]
    legendre_pred: FloatArray  # NEC [nT]
    legendre_coef: FloatArray
    inside_box: BoolArray
    chosen: str

    def prediction(self) -> FloatArray:
        """The chosen stage's prediction, NEC [nT]."""
        return {
            "none": np.zeros_like(self.legendre_pred),
            "legendre": self.legendre_pred,
            "spherical_harmonic": self.sh_pred,
        }[self.chosen]


def _fit_stages(
    data: DiagnosisData,
    track: _Track,
    train: BoolArray,
    fold: npt.NDArray[np.intp],
    n_folds: int,
) -> _Stages:
    """The regional Legendre and the global spherical-harmonic stage, cross-validated over the
    training folds against no stage."""
    r_nec = track.r_nec
    cv_ms: dict[str, float] = {"none": float(np.mean(np.sum(r_nec[train] ** 2, axis=1)))}
    if n_folds >= 2:
        sse = 0.0
        for f in range(n_folds):
            pred, _, _ = _legendre_fit(track, train & (fold != f))
            left = train & (fold == f)
            sse += float(np.sum((r_nec[left] - pred[left]) ** 2))
        cv_ms["legendre"] = sse / int(train.sum())
    sh = _sh_stage(
        data.t_utc_s, track.radius, track.colat, track.lon_rad, r_nec, train, fold, n_folds
    )
    sh_pred = np.zeros_like(r_nec)
    if sh["degree"] > 0:
        deg = int(sh["degree"])
        cv_ms["spherical_harmonic"] = sh["cv_rms_nt"] ** 2
        sh_pred = synth_internal_nec_nt(
            to_degree_blocks(sh["coefficients"], deg),
            track.radius,
            np.degrees(track.colat),
            track.lon,
            nmax=deg,
        )
    leg, coef, inside_box = _legendre_fit(track, train)
    stage = min(cv_ms, key=lambda s: cv_ms[s])
    return _Stages(cv_ms, sh, sh_pred, leg, coef, inside_box, stage)


_METHOD = (
    "CN109855623A: regional Legendre polynomials + BP network, with a global "
    "internal spherical-harmonic stage chosen by cross-validation on the training blocks"
)


def _stage_summary(stages: _Stages) -> dict[str, Any]:
    """The summary's keys about step 2: the method, the chosen stage, the cross-validation and
    the spherical-harmonic stage's degree, damping and spectrum."""
    sh = stages.sh
    deg = int(sh["degree"])
    return {
        "method": _METHOD,
        "fitted": True,
        "stage_chosen": stages.chosen,
        "cv_rms_nt": {k: float(np.sqrt(v)) for k, v in stages.cv_ms.items()},
        "legendre_order": LEGENDRE_ORDER,
        "sh_degree": deg,
        "sh_degree_cap": int(sh["cap"]),
        "sh_damping": float(sh.get("damping", 0.0)),
        "sh_cv_rms_by_degree_nt": {str(d): v for d, v in sh.get("cv_rms_by_degree_nt", {}).items()},
        "sh_lowes_spectrum_nt2": (
            [round(v, 4) for v in _lowes_spectrum(sh["coefficients"], deg)] if deg else []
        ),
    }


def _network_inputs(
    data: DiagnosisData,
    lat_scaled: FloatArray,
    lon_scaled: FloatArray,
    radius: FloatArray,
    train: BoolArray,
    scale: Callable[[FloatArray, float, float], FloatArray],
) -> tuple[FloatArray, list[str]]:
    """The network's inputs (scaled to [-1, 1] on the training samples) and their names."""
    inputs = [lat_scaled, lon_scaled]
    names = ["latitude", "longitude"]
    if float(np.ptp(radius[train])) > 1.0:
        inputs.append(scale(radius, float(radius[train].min()), float(radius[train].max())))
        names.append("radius")
    phi = data.mlt_angle_rad
    if phi is not None:
        inputs += [np.sin(phi), np.cos(phi)]
        names += ["sin_mlt", "cos_mlt"]
    if data.rc_index_nt is not None and float(np.std(data.rc_index_nt[train])) > 1.0:
        rc = data.rc_index_nt
        inputs.append((rc - float(np.mean(rc[train]))) / float(np.std(rc[train])))
        names.append("rc_index")
    return np.column_stack(inputs), names


def _network_stage(
    x: FloatArray,
    rest: FloatArray,
    train: BoolArray,
    fold: npt.NDArray[np.intp],
    n_folds: int,
    inside_box: BoolArray,
    rng: np.random.Generator,
    max_nfev: int,
) -> tuple[FloatArray, BoolArray, float, float, bool]:
    """Patent step 3 on what the stage leaves: the network's correction (zero outside the box of
    its inputs), that box, its validation RMS without and with it, and whether it is used."""
    n_in = x.shape[1]
    # Fitted on the training blocks but the last fold, validated on that last fold (later in
    # time, as the held-out blocks are).
    fit_net = train & (fold < n_folds - 1) if n_folds >= 2 else train
    valid = train & (fold == n_folds - 1) if n_folds >= 2 else train
    idx = np.flatnonzero(fit_net)
    if idx.size > NET_MAX_SAMPLES:
        idx = idx[np.linspace(0, idx.size - 1, NET_MAX_SAMPLES).round().astype(np.intp)]
    theta, y_scale = _fit_net(x[idx], rest[idx], rng, max_nfev)
    net = _net(theta, x, n_in) * y_scale
    # Regional (the patent's region S): no correction outside the box of the network's inputs.
    xt = x[fit_net]
    lo_in = xt.min(axis=0)
    hi_in = xt.max(axis=0)
    pad = 0.02 * (hi_in - lo_in)
    inside = np.all((x >= lo_in - pad) & (x <= hi_in + pad), axis=1) & inside_box
    net[~inside] = 0.0
    val_without = norm_rms_nt(rest[valid])
    val_with = norm_rms_nt((rest - net)[valid])
    net_used = bool(val_with < (1.0 - NET_MIN_GAIN) * val_without)
    return net, inside, val_without, val_with, net_used
