"""Seed 003: a learned model of the reference field's own error as a function of position.

CN109855623A (Southeast University, Wang Lihui and Liu Qingya, 2019): "Online approximation of a
geomagnetic model by Legendre polynomials and a BP network". Step 2: a regional model of each field
component as Legendre polynomials of latitude and longitude, truncation order ``N_off = 3``,
fitted by least squares; step 3: a BP network (one hidden layer of 6 sigmoid nodes, linear
outputs) learns the measured minus modelled field from the position and auxiliary state;
step 4: the model plus the network corrects the field.

Here the "measured minus modelled field" is the calibrated residual (NEC components, so that a
static field in Earth-fixed coordinates is a fixed function of position), the region is the box
covered by the training blocks, and the patent's eight navigation-error inputs (not available on a
spacecraft) are replaced by the magnetic local time (sin, cos) and the RC index, which organise the
magnetospheric part. It is validated on the held-out later blocks, as every candidate is: a data-
driven stand-in for crustal and external fields when no model explains them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.polynomial import legendre
from scipy.optimize import least_squares

from orbitcal.diagnose.effects import DiagnosisData

__all__ = ["LEGENDRE_ORDER", "N_HIDDEN", "learned_field_error", "legendre_design"]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

#: Truncation order of the regional Legendre model (CN109855623A: N_off = 3).
LEGENDRE_ORDER = 3
#: Hidden sigmoid nodes of the BP network (CN109855623A: 6).
N_HIDDEN = 6


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


def _net(theta: FloatArray, x: FloatArray, n_in: int) -> FloatArray:
    h = N_HIDDEN
    w1 = theta[: n_in * h].reshape(n_in, h)
    b1 = theta[n_in * h : n_in * h + h]
    w2 = theta[n_in * h + h : n_in * h + h + 3 * h].reshape(h, 3)
    b2 = theta[n_in * h + h + 3 * h :]
    hidden = 1.0 / (1.0 + np.exp(-np.clip(x @ w1 + b1, -50.0, 50.0)))
    return np.asarray(hidden @ w2 + b2)


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
        ``legendre_order``, ``hidden_nodes``, ``inputs``, ``holdout_rms_before_nt``,
        ``holdout_rms_legendre_nt``, ``holdout_rms_after_nt``, ``shrink``,
        ``legendre_coefficients_nt`` (per N, E, C).
    """
    rng = rng if rng is not None else np.random.default_rng(0)
    r = data.r_itrs_km
    basis = _nec_basis(r)
    r_itrs = np.einsum("nji,nj->ni", data.rot_itrs_to_body, residual_body_nt)
    r_nec = np.einsum("nij,nj->ni", basis, r_itrs)
    lat = np.degrees(np.arcsin(r[:, 2] / np.linalg.norm(r, axis=1)))
    lon = np.degrees(np.arctan2(r[:, 1], r[:, 0]))
    lo_lat, hi_lat = float(lat[train].min()), float(lat[train].max())
    lo_lon, hi_lon = float(lon[train].min()), float(lon[train].max())

    def scale(v: FloatArray, lo: float, hi: float) -> FloatArray:
        return np.clip(2.0 * (v - lo) / max(hi - lo, 1e-9) - 1.0, -1.0, 1.0)

    xl = scale(lat, lo_lat, hi_lat)
    yl = scale(lon, lo_lon, hi_lon)
    design = legendre_design(xl, yl)
    coef = np.linalg.lstsq(design[train], r_nec[train], rcond=None)[0]
    leg = design @ coef
    rest = r_nec - leg

    inputs = [xl, yl]
    names = ["latitude", "longitude"]
    alt = np.linalg.norm(r, axis=1)
    if float(np.ptp(alt[train])) > 1.0:
        inputs.append(scale(alt, float(alt[train].min()), float(alt[train].max())))
        names.append("radius")
    phi = data.mlt_angle_rad
    if phi is not None:
        inputs += [np.sin(phi), np.cos(phi)]
        names += ["sin_mlt", "cos_mlt"]
    if data.rc_index_nt is not None and float(np.std(data.rc_index_nt[train])) > 1.0:
        rc = data.rc_index_nt
        inputs.append((rc - float(np.mean(rc[train]))) / float(np.std(rc[train])))
        names.append("rc_index")
    x = np.column_stack(inputs)
    n_in = x.shape[1]
    y_scale = max(float(np.std(rest[train])), 1e-9)
    n_par = n_in * N_HIDDEN + N_HIDDEN + 3 * N_HIDDEN + 3
    theta0 = rng.normal(scale=0.5, size=n_par)
    xt = x[train]
    yt = rest[train] / y_scale

    def fun(theta: FloatArray) -> FloatArray:
        return (_net(theta, xt, n_in) - yt).ravel()

    sol = least_squares(fun, theta0, method="lm", max_nfev=max_nfev)
    net = _net(sol.x, x, n_in) * y_scale
    # A regional model (the patent's region S): no correction outside the training box of
    # position and inputs -- it does not extrapolate.
    lo_in = xt.min(axis=0)
    hi_in = xt.max(axis=0)
    pad = 0.02 * (hi_in - lo_in)
    inside = np.all((x >= lo_in - pad) & (x <= hi_in + pad), axis=1)
    inside &= (lat >= lo_lat) & (lat <= hi_lat) & (lon >= lo_lon) & (lon <= hi_lon)
    net[~inside] = 0.0
    leg[~inside] = 0.0

    def body(v_nec: FloatArray) -> FloatArray:
        v_itrs = np.einsum("nji,nj->ni", basis, v_nec)
        return np.einsum("nij,nj->ni", data.rot_itrs_to_body, v_itrs)

    def rms(v: FloatArray) -> float:
        return float(np.sqrt(np.mean(np.sum(v**2, axis=1)))) if v.size else float("nan")

    before = rms(residual_body_nt[holdout])
    after_leg = rms((residual_body_nt - body(leg))[holdout])
    after = rms((residual_body_nt - body(leg + net))[holdout])
    return {
        "method": "CN109855623A: regional Legendre polynomials + BP network",
        "legendre_order": LEGENDRE_ORDER,
        "hidden_nodes": N_HIDDEN,
        "inputs": names,
        "region_deg": {"lat": [lo_lat, hi_lat], "lon": [lo_lon, hi_lon]},
        "holdout_rms_before_nt": before,
        "holdout_rms_legendre_nt": after_leg,
        "holdout_rms_after_nt": after,
        "shrink": before / max(after, 1e-12),
        "holdout_fraction_inside_region": float(np.mean(inside[holdout])) if holdout.any() else 0.0,
        "legendre_coefficients_nt": {
            comp: coef[:, k].round(4).tolist() for k, comp in enumerate(("N", "E", "C"))
        },
    }
