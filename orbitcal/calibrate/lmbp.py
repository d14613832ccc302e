"""The Levenberg–Marquardt-trained BP network calibrator (Wang et al. 2020), on-orbit variant.

Network (Wang et al. 2020, section 2: one hidden layer, 3-H-3):

    u = scale_in([b_raw, x_hk])                       inputs mapped to [-1, 1] (min-max)
    y = W2 · φ(W1 u + b1) + b2 (+ L u)                φ = tanh or logistic sigmoid
    b_cal = unscale_out(y)                            outputs mapped back from [-1, 1]

``"lmbp"`` is the paper's network: raw magnetometer inputs only, no linear path, random
(Nguyen–Widrow-style) initialisation. ``"lmbp-hk"`` is the on-orbit variant: housekeeping inputs
(temperature, magnetorquer dipoles, any ``hk_*``) and a linear path ``L u`` beside the hidden layer,
initialised from the linear least-squares solution, so an affine sensor model is exact from the
first epoch and the hidden layer learns only what is left (NOTES: restarts and a linear-path
initialisation matter more than speed at H ≥ 6).

Training is :func:`orbitcal.calibrate.lm.levenberg_marquardt` (Wang et al. 2020, eq. 14) with the
analytic Jacobian below, on the residual ``y − scale_out(b_ref)`` in scaled units (so the reported
MSE is the paper's/MATLAB's normalised MSE).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import torch

from orbitcal.arrays import FloatArray
from orbitcal.calibrate.base import Calibration, FitData, best_linear_approximation
from orbitcal.calibrate.errors import (
    DocumentError,
    MissingAttitudeError,
    PoorCoverageError,
    TooFewSamplesError,
)
from orbitcal.calibrate.linear import CONDITION_LIMIT, equilibrated_condition_number
from orbitcal.calibrate.lm import LMOptions, LMResult, levenberg_marquardt, torch_threads
from orbitcal.errors import BadInputError

__all__ = [
    "STOPPING",
    "Activation",
    "BPNetwork",
    "LMBPCalibration",
    "MinMaxScaler",
    "NetworkProblem",
    "fit_lmbp",
]

Activation = Literal["tanh", "sigmoid"]

#: The calibrator's stopping rule. The fit stops when the last 5 epochs together lowered the
#: error by less than 1e-4 of itself, when every Jacobian column is within 1e-6 (cosine) of
#: orthogonal to the residual, or when a step changes the weights by less than 1e-8 of their
#: norm. On a one-day 1 Hz Swarm A world (86,400 samples) the error was within 0.2 % of its
#: 200-epoch value after 10 epochs; the old tolerances (ftol 1e-12 per epoch, an absolute
#: gradient test that scaled units never met) ran all 200 epochs every time.
STOPPING = LMOptions(max_epochs=200, ftol=1e-4, ftol_epochs=5, gtol=1e-6, xtol=1e-8)

#: Fits with at most this many samples run on one torch thread (see :func:`torch_threads`):
#: their operations are too small to share, and one thread makes the weights reproducible.
SMALL_FIT_SAMPLES = 250_000


@dataclass(frozen=True)
class MinMaxScaler:
    """Maps each column linearly from ``[lo, hi]`` to ``[-1, 1]`` (MATLAB ``mapminmax``).

    Constant columns (``hi == lo``) map to 0.
    """

    lo: tuple[float, ...]
    hi: tuple[float, ...]

    @classmethod
    def fit(cls, x: FloatArray) -> MinMaxScaler:
        x = np.asarray(x, dtype=np.float64)
        return cls(tuple(float(v) for v in x.min(axis=0)), tuple(float(v) for v in x.max(axis=0)))

    def _gain(self) -> tuple[FloatArray, FloatArray]:
        lo = np.asarray(self.lo)
        span = np.asarray(self.hi) - lo
        gain = np.where(span > 0, 2.0 / np.where(span > 0, span, 1.0), 0.0)
        return lo, gain

    def forward(self, x: FloatArray) -> FloatArray:
        lo, gain = self._gain()
        out: FloatArray = (np.asarray(x, dtype=np.float64) - lo) * gain - np.where(
            gain > 0, 1.0, 0.0
        )
        return out

    def inverse(self, y: FloatArray) -> FloatArray:
        lo, gain = self._gain()
        safe = np.where(gain > 0, gain, 1.0)
        out: FloatArray = np.where(gain > 0, (np.asarray(y) + 1.0) / safe + lo, lo)
        return out

    def to_json(self) -> dict[str, list[float]]:
        return {"min": list(self.lo), "max": list(self.hi)}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> MinMaxScaler:
        return cls(tuple(float(v) for v in d["min"]), tuple(float(v) for v in d["max"]))


@dataclass(frozen=True)
class BPNetwork:
    """Shape of a one-hidden-layer network; parameters live in a flat float64 vector.

    Layout of the flat vector: ``W1 (H, n_in)``, ``b1 (H)``, ``W2 (3, H)``, ``b2 (3)`` and, with a
    linear path, ``L (3, n_in)``; all row-major.
    """

    n_in: int
    n_hidden: int
    activation: Activation = "tanh"
    linear_path: bool = False
    n_out: int = 3

    @property
    def n_params(self) -> int:
        h, i, o = self.n_hidden, self.n_in, self.n_out
        return h * i + h + o * h + o + (o * i if self.linear_path else 0)

    def unpack(self, w: torch.Tensor) -> dict[str, torch.Tensor]:
        h, i, o = self.n_hidden, self.n_in, self.n_out
        k = 0
        out: dict[str, torch.Tensor] = {}
        for name, shape in (("W1", (h, i)), ("b1", (h,)), ("W2", (o, h)), ("b2", (o,))):
            size = math.prod(shape)
            out[name] = w[k : k + size].reshape(shape)
            k += size
        if self.linear_path:
            out["L"] = w[k : k + o * i].reshape(o, i)
        return out

    def pack(self, parts: dict[str, torch.Tensor]) -> torch.Tensor:
        names = ["W1", "b1", "W2", "b2"] + (["L"] if self.linear_path else [])
        return torch.cat([parts[n].reshape(-1).to(torch.float64) for n in names])

    def _phi(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        if self.activation == "tanh":
            h = torch.tanh(z)
            return h, 1.0 - h * h
        h = torch.sigmoid(z)
        return h, h * (1.0 - h)

    def forward(self, w: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        """Scaled outputs ``(N, 3)`` for scaled inputs ``u (N, n_in)``."""
        p = self.unpack(w)
        h, _ = self._phi(u @ p["W1"].T + p["b1"])
        y = h @ p["W2"].T + p["b2"]
        if self.linear_path:
            y = y + u @ p["L"].T
        return y

    def forward_and_jacobian(
        self, w: torch.Tensor, u: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Outputs ``(N, 3)`` and the analytic Jacobian ``(N·3, n_params)`` (row = sample·3 + k)."""
        p = self.unpack(w)
        N = u.shape[0]
        H, Ni, No = self.n_hidden, self.n_in, self.n_out
        h, dh = self._phi(u @ p["W1"].T + p["b1"])
        y = h @ p["W2"].T + p["b2"]
        if self.linear_path:
            y = y + u @ p["L"].T
        G = p["W2"].unsqueeze(0) * dh.unsqueeze(1)  # (N, No, H): ∂y_k/∂z_j
        blocks = [
            (G.unsqueeze(3) * u.view(N, 1, 1, Ni)).reshape(N, No, H * Ni),  # W1
            G,  # b1
            _block_diag_rows(h, No),  # W2
            torch.eye(No, dtype=u.dtype).expand(N, No, No),  # b2
        ]
        if self.linear_path:
            blocks.append(_block_diag_rows(u, No))
        J = torch.cat(blocks, dim=2).reshape(N * No, self.n_params)
        return y, J

    def init_params(
        self,
        generator: torch.Generator,
        *,
        linear_init: tuple[torch.Tensor, torch.Tensor] | None = None,
    ) -> torch.Tensor:
        """Nguyen–Widrow-style random start; with ``linear_init=(L, b2)`` the linear path starts at
        the least-squares solution and the output weights near zero."""
        H, Ni, No = self.n_hidden, self.n_in, self.n_out
        beta = 0.7 * H ** (1.0 / max(Ni, 1))
        W1 = torch.rand(H, Ni, generator=generator, dtype=torch.float64) * 2 - 1
        W1 = beta * W1 / W1.norm(dim=1, keepdim=True).clamp_min(1e-12)
        b1 = beta * (torch.rand(H, generator=generator, dtype=torch.float64) * 2 - 1)
        W2 = torch.rand(No, H, generator=generator, dtype=torch.float64) * 2 - 1
        b2 = torch.zeros(No, dtype=torch.float64)
        parts = {"W1": W1, "b1": b1, "W2": W2, "b2": b2}
        if self.linear_path:
            if linear_init is None:
                parts["L"] = torch.zeros(No, Ni, dtype=torch.float64)
            else:
                parts["L"], parts["b2"] = linear_init
                parts["W2"] = 1e-3 * W2
        return self.pack(parts)


def _block_diag_rows(x: torch.Tensor, n_out: int) -> torch.Tensor:
    """``(N, n_out, n_out·d)`` with ``x`` (N, d) on the k-th block of row k (∂(Wx)_k/∂W)."""
    N, d = x.shape
    out = x.new_zeros(N, n_out, n_out * d)
    for k in range(n_out):
        out[:, k, k * d : (k + 1) * d] = x
    return out


class NetworkProblem:
    """Least-squares problem ``r(w) = net(w, u) − t`` (scaled units) for the LM optimiser.

    Everything that does not depend on the weights (index maps, the output-selection pattern) is
    built once here; the hidden activations of the last :meth:`residuals` call are kept, so the
    normal equations at an accepted step (the same tensor) do not run the network again.
    """

    def __init__(self, net: BPNetwork, u: torch.Tensor, t: torch.Tensor) -> None:
        self.net = net
        self.u = u
        self.t = t
        H, Ni, No = net.n_hidden, net.n_in, net.n_out
        nq = H + 1 + (Ni if net.linear_path else 0)
        ns = H * Ni + H
        self._ns, self._nq = ns, nq
        # hidden unit j of each shared parameter, in flat order [W1 (j, i)…, b1 (j)…]
        self._rep = torch.tensor([j for j in range(H) for _ in range(Ni)] + list(range(H)))
        # column of A = [V, Q] (see normal_equations) and output k of every flat parameter
        col = list(range(ns))
        out_k = [-1] * ns
        col += [ns + j for _ in range(No) for j in range(H)]  # W2[k, j]
        out_k += [k for k in range(No) for _ in range(H)]
        col += [ns + H] * No  # b2[k]
        out_k += list(range(No))
        if net.linear_path:
            col += [ns + H + 1 + i for _ in range(No) for i in range(Ni)]  # L[k, i]
            out_k += [k for k in range(No) for _ in range(Ni)]
        n = len(col)
        assert n == net.n_params
        self._col = torch.tensor(col)
        width = ns + nq
        self._flat_col = (self._col.unsqueeze(1) * width + self._col.unsqueeze(0)).reshape(-1)
        c0 = torch.zeros(No, n, dtype=u.dtype)
        for p_idx, k in enumerate(out_k):
            if k >= 0:
                c0[k, p_idx] = 1.0
        self._c0 = c0
        w2_start = ns
        self._w2_slice = slice(w2_start, w2_start + No * H)
        self._last: tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None = None

    def _hidden_and_residual(self, params: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        last = self._last
        if last is not None and last[0] is params:
            return last[1], last[2]
        net = self.net
        p = net.unpack(params)
        z = torch.addmm(p["b1"], self.u, p["W1"].T)
        h = torch.tanh(z) if net.activation == "tanh" else torch.sigmoid(z)
        y = torch.addmm(p["b2"], h, p["W2"].T)
        if net.linear_path:
            y = torch.addmm(y, self.u, p["L"].T)
        r = y - self.t
        self._last = (params, h, r)
        return h, r

    def residuals(self, params: torch.Tensor) -> torch.Tensor:
        return self._hidden_and_residual(params)[1].reshape(-1)

    def residuals_and_jacobian(self, params: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        y, J = self.net.forward_and_jacobian(params, self.u)
        return (y - self.t).reshape(-1), J

    def normal_equations(
        self, params: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(r, JᵀJ, Jᵀr)`` of the analytic Jacobian, assembled from its block structure.

        Every Jacobian column is one column of ``A = [V, Q]`` times a per-output coefficient:
        ``∂y_nk/∂w_p = C[k, p]·A[n, a(p)]``, with ``V_n = [φ'(z_n) ⊗ u_n, φ'(z_n)]`` for the
        hidden-layer weights (``C[k, p] = W2[k, j(p)]``) and ``Q_n = [h_n, 1, u_n]`` for the
        output-``k`` weights ``W2[k], b2[k], L[k]`` (``C[k, p] = 1`` for that ``k``, else 0).
        Hence ``JᵀJ = (AᵀA)[a, a] ⊙ CᵀC`` and ``Jᵀr = Σ_k C[k] ⊙ (Aᵀr)[a, k]``: one ``N × 16``
        product for the 3-3-3 network, never the dense ``3N × 24`` Jacobian and its zero blocks.
        """
        net = self.net
        u = self.u
        N = u.shape[0]
        H, Ni = net.n_hidden, net.n_in
        ns, nq = self._ns, self._nq
        h, r = self._hidden_and_residual(params)
        dh = 1.0 - h * h if net.activation == "tanh" else h * (1.0 - h)
        A = torch.empty(N, ns + nq, dtype=u.dtype)
        torch.mul(dh.unsqueeze(2), u.unsqueeze(1), out=A[:, : H * Ni].view(N, H, Ni))
        A[:, H * Ni : ns] = dh
        A[:, ns : ns + H] = h
        A[:, ns + H] = 1.0
        if net.linear_path:
            A[:, ns + H + 1 :] = u
        C = self._c0.clone()
        C[:, :ns] = params[self._w2_slice].view(net.n_out, H)[:, self._rep]
        n = C.shape[1]
        JtJ = (A.T @ A).reshape(-1)[self._flat_col].view(n, n) * (C.T @ C)
        Jtr = ((A.T @ r)[self._col] * C.T).sum(1)
        return r.reshape(-1), JtJ, Jtr


class LMBPCalibration(Calibration):
    """A trained network with its scalers; ``apply`` runs it in float64 (bit-for-bit after a
    JSON round trip)."""

    def __init__(
        self,
        method: str,
        net: BPNetwork,
        params: FloatArray,
        in_scaler: MinMaxScaler,
        out_scaler: MinMaxScaler,
        *,
        hk_names: list[str] | None = None,
        linear_approx: tuple[FloatArray, FloatArray] | None = None,
        training: dict[str, Any] | None = None,
    ) -> None:
        self.method = method
        self.net = net
        self.params = np.asarray(params, dtype=np.float64)
        self.in_scaler = in_scaler
        self.out_scaler = out_scaler
        self.hk_names = list(hk_names or [])
        self._linear = linear_approx
        self.training = dict(training or {})

    def _inputs(self, b_raw_nt: FloatArray, x_hk: FloatArray | None) -> FloatArray:
        b = np.asarray(b_raw_nt, dtype=np.float64).reshape(-1, 3)
        if self.hk_names:
            if x_hk is None:
                raise BadInputError(f"{self.method} needs housekeeping columns {self.hk_names}")
            x = np.asarray(x_hk, dtype=np.float64).reshape(b.shape[0], -1)
            if x.shape[1] != len(self.hk_names):
                raise BadInputError(
                    f"{self.method} needs housekeeping columns {self.hk_names}, "
                    f"got {x.shape[1]} columns"
                )
            b = np.hstack([b, x])
        return b

    def apply(self, b_raw_nt: FloatArray, x_hk: FloatArray | None = None) -> FloatArray:
        u = torch.from_numpy(self.in_scaler.forward(self._inputs(b_raw_nt, x_hk)))
        with torch.no_grad():
            y = self.net.forward(torch.from_numpy(self.params), u).numpy()
        return self.out_scaler.inverse(y)

    def linear(self) -> tuple[FloatArray, FloatArray]:
        if self._linear is None:
            raise ValueError("no linear approximation stored; fit or load one")
        return self._linear[0].copy(), self._linear[1].copy()

    def set_linear(self, M: FloatArray, o: FloatArray) -> None:
        """Store a given ``(M, o)`` (e.g. read back from a document's ``linear`` block)."""
        self._linear = (np.asarray(M, dtype=np.float64), np.asarray(o, dtype=np.float64))

    def set_linear_approximation(
        self, b_raw_nt: FloatArray, x_hk: FloatArray | None = None
    ) -> None:
        """Store the least-squares affine approximation over these samples."""
        self._linear = best_linear_approximation(self, b_raw_nt, x_hk)

    def to_model(self) -> dict[str, Any]:
        parts = self.net.unpack(torch.from_numpy(self.params))
        return {
            "architecture": f"{self.net.n_in}-{self.net.n_hidden}-{self.net.n_out}"
            + ("+linear" if self.net.linear_path else ""),
            "n_hidden": self.net.n_hidden,
            "activation": self.net.activation,
            "linear_path": self.net.linear_path,
            "inputs": ["b_x", "b_y", "b_z", *self.hk_names],
            "hk_names": list(self.hk_names),
            "input_scaler": self.in_scaler.to_json(),
            "output_scaler": self.out_scaler.to_json(),
            "weights": {k: v.tolist() for k, v in parts.items()},
            "training": dict(self.training),
        }

    @classmethod
    def from_model(cls, method: str, model: dict[str, Any]) -> LMBPCalibration:
        try:
            hk = [str(h) for h in model.get("hk_names", [])]
            net = BPNetwork(
                n_in=3 + len(hk),
                n_hidden=int(model["n_hidden"]),
                activation=model["activation"],
                linear_path=bool(model["linear_path"]),
            )
            parts = {k: torch.tensor(v, dtype=torch.float64) for k, v in model["weights"].items()}
            params = net.pack(parts).numpy()
            return cls(
                method,
                net,
                params,
                MinMaxScaler.from_json(model["input_scaler"]),
                MinMaxScaler.from_json(model["output_scaler"]),
                hk_names=hk,
                training=model.get("training", {}),
            )
        except (KeyError, ValueError, TypeError, RuntimeError) as exc:
            raise DocumentError(f"malformed {method} model block: {exc}") from exc


def fit_lmbp(
    data: FitData,
    *,
    n_hidden: int = 3,
    activation: Activation = "tanh",
    use_hk: bool = False,
    linear_path: bool | None = None,
    restarts: int = 1,
    generator: torch.Generator,
    options: LMOptions | None = None,
    warm_start: LMBPCalibration | None = None,
    callback: Callable[[int, float], None] | None = None,
) -> LMBPCalibration:
    """Train the BP network by Levenberg–Marquardt on raw readings → reference field.

    Parameters
    ----------
    data
        Raw readings ``(N, 3)`` [nT] with the body-frame reference field (attitude needed) and,
        for ``use_hk``, the housekeeping regressors.
    n_hidden
        Hidden nodes ``H`` (the paper uses 3).
    activation
        ``"tanh"`` (MATLAB ``tansig``) or ``"sigmoid"`` (``logsig``).
    use_hk
        Feed the housekeeping regressors as extra inputs (method ``"lmbp-hk"``).
    linear_path
        Linear path beside the hidden layer, initialised by least squares; default ``use_hk``.
    restarts
        Independent random starts; the lowest training loss wins.
    generator
        Seeded ``torch.Generator`` for the initial weights.
    options
        LM stopping rules (default :data:`STOPPING`).
    warm_start
        Continue from this calibration's weights and scalers (periodic retraining); its
        architecture must match.
    callback
        ``callback(epoch, mse)`` after each LM epoch.

    Returns
    -------
    LMBPCalibration
        With ``training`` = epochs, final normalised MSE, stop reason, restarts. Up to
        :data:`SMALL_FIT_SAMPLES` samples the fit runs on one torch thread, so a given
        ``generator`` seed gives the same weights run after run.
    """
    threads = 1 if data.n <= SMALL_FIT_SAMPLES else None
    with torch_threads(threads):
        return _fit_lmbp(
            data,
            n_hidden=n_hidden,
            activation=activation,
            use_hk=use_hk,
            linear_path=linear_path,
            restarts=restarts,
            generator=generator,
            options=options or STOPPING,
            warm_start=warm_start,
            callback=callback,
        )


def _fit_lmbp(
    data: FitData,
    *,
    n_hidden: int,
    activation: Activation,
    use_hk: bool,
    linear_path: bool | None,
    restarts: int,
    generator: torch.Generator,
    options: LMOptions,
    warm_start: LMBPCalibration | None,
    callback: Callable[[int, float], None] | None,
) -> LMBPCalibration:
    method = "lmbp-hk" if use_hk else "lmbp"
    if data.b_ref_body_nt is None:
        raise MissingAttitudeError(method)
    b_ref: FloatArray = data.b_ref_body_nt
    if use_hk:
        data = data.without_constant_hk()
        if warm_start is not None and warm_start.hk_names != data.hk_names:
            raise BadInputError(
                f"warm start uses housekeeping {warm_start.hk_names}, the data {data.hk_names}"
            )
    hk_names = list(data.hk_names) if use_hk else []
    x_in = (
        np.hstack([data.b_raw_nt, data.x_hk])
        if use_hk and data.x_hk is not None
        else (data.b_raw_nt)
    )
    lin = use_hk if linear_path is None else linear_path
    net = BPNetwork(x_in.shape[1], n_hidden, activation, lin)
    if data.n * 3 < 2 * net.n_params:
        raise TooFewSamplesError(method, data.n, math.ceil(2 * net.n_params / 3))

    if warm_start is not None:
        if warm_start.net != net:
            raise BadInputError(f"warm start architecture {warm_start.net} differs from {net}")
        in_scaler, out_scaler = warm_start.in_scaler, warm_start.out_scaler
    else:
        in_scaler, out_scaler = MinMaxScaler.fit(x_in), MinMaxScaler.fit(b_ref)
    u = torch.from_numpy(in_scaler.forward(x_in))
    t = torch.from_numpy(out_scaler.forward(b_ref))
    problem = NetworkProblem(net, u, t)

    linear_init = None
    if lin:
        U = torch.cat([u, torch.ones(u.shape[0], 1, dtype=torch.float64)], dim=1)
        # the linear path must be identifiable: the same coverage test as the 12-parameter fit
        cond = equilibrated_condition_number(U.numpy())
        if not cond < CONDITION_LIMIT:
            raise PoorCoverageError(method, cond, CONDITION_LIMIT)
        # gelsd (SVD): torch's default gelsy gave answers 1e-16 apart from call to call (MKL)
        coef = torch.linalg.lstsq(U, t, driver="gelsd").solution  # (n_in + 1, 3)
        linear_init = (coef[:-1].T.contiguous(), coef[-1].clone())

    starts: list[torch.Tensor] = []
    if warm_start is not None:
        starts.append(torch.from_numpy(warm_start.params.copy()))
    else:
        starts = [net.init_params(generator, linear_init=linear_init) for _ in range(restarts)]
    hidden_layer = "kept"
    if linear_init is not None and warm_start is None:
        best, hidden_layer = _fit_with_validation_guard(
            net, u, t, starts, linear_init, options=options, callback=callback
        )
    else:
        best = _best_of(problem, starts, options=options, callback=callback)
    cal = LMBPCalibration(
        method,
        net,
        best.params.numpy(),
        in_scaler,
        out_scaler,
        hk_names=hk_names,
        training={
            "epochs": best.epochs,
            "mse_normalised": best.mse,
            "stop_reason": best.stop_reason,
            "restarts": len(starts),
            "warm_start": warm_start is not None,
            "hidden_layer": hidden_layer,
        },
    )
    cal.set_linear_approximation(data.b_raw_nt, data.x_hk if use_hk else None)
    return cal


#: Share of the training samples (the latest, in time order) that judges the hidden layer.
VALIDATION_FRACTION = 0.2

#: The hidden layer is judged every this many epochs while it trains on the earlier samples ...
GUARD_EVERY = 5

#: ... and switched off at once when it has lowered the training MSE by less than this share of
#: the linear path's (and is no better on the later samples).
GUARD_MIN_GAIN = 1e-3


def _best_of(
    problem: NetworkProblem,
    starts: list[torch.Tensor],
    *,
    options: LMOptions | None,
    callback: Callable[[int, float], None] | None,
    monitor: Callable[[int, torch.Tensor, float], bool] | None = None,
) -> LMResult:
    """LM from every start; the lowest training loss wins."""
    best: LMResult | None = None
    for w0 in starts:
        result = levenberg_marquardt(
            problem, w0, options=options, callback=callback, monitor=monitor
        )
        if best is None or result.loss < best.loss:
            best = result
    assert best is not None
    return best


def _fit_with_validation_guard(
    net: BPNetwork,
    u: torch.Tensor,
    t: torch.Tensor,
    starts: list[torch.Tensor],
    linear_init: tuple[torch.Tensor, torch.Tensor],
    *,
    options: LMOptions | None,
    callback: Callable[[int, float], None] | None,
) -> tuple[LMResult, str]:
    """Train with the hidden layer only where it earns its place on later, unseen samples.

    A network with a linear path can fit the training span better than the affine model and
    still extrapolate worse: tanh units saturating on housekeeping inputs (temperature,
    magnetorquer commands) outside their training range added tens of nT on a later block of a
    nadir orbit. So the network is first trained on the earlier ``1 − VALIDATION_FRACTION`` of the
    samples (rows are in time order) and compared with the linear path alone (the least-squares
    start with the hidden outputs off) on the latest ``VALIDATION_FRACTION``. If it is better
    there, it is trained on all samples from where it stood; otherwise the hidden layer is
    switched off (``W2 = 0``) and the calibration is the linear least-squares solution on all
    samples. Returns the result and a sentence saying which happened.
    """
    n = u.shape[0]
    n_val = round(VALIDATION_FRACTION * n)
    n_fit = n - n_val
    if n_val < 10 or n_fit * 3 < 2 * net.n_params:
        return _best_of(NetworkProblem(net, u, t), starts, options=options, callback=callback), (
            "kept (too few samples to validate)"
        )
    # The linear path refitted on the earlier samples, hidden layer off: the yardstick.
    U_fit = torch.cat([u[:n_fit], torch.ones(n_fit, 1, dtype=torch.float64)], dim=1)
    coef = torch.linalg.lstsq(U_fit, t[:n_fit], driver="gelsd").solution
    lin_parts = net.unpack(starts[0].clone())
    lin_parts["W2"] = torch.zeros_like(lin_parts["W2"])
    lin_parts["L"], lin_parts["b2"] = coef[:-1].T.contiguous(), coef[-1].clone()
    w_lin = net.pack(lin_parts)
    mse_lin_fit = float(torch.mean((net.forward(w_lin, u[:n_fit]) - t[:n_fit]) ** 2))

    def val_rms(w: torch.Tensor) -> float:
        return float(torch.sqrt(torch.mean((net.forward(w, u[n_fit:]) - t[n_fit:]) ** 2)))

    rms_lin = val_rms(w_lin)

    def decided_linear(epoch: int, w: torch.Tensor, mse: float) -> bool:
        # Every GUARD_EVERY epochs: a hidden layer that has not yet explained GUARD_MIN_GAIN of
        # what the linear path leaves on the training samples, and that is no better on the
        # later ones, is switched off now instead of after the fit converges.
        if epoch % GUARD_EVERY != 0 or mse < (1.0 - GUARD_MIN_GAIN) * mse_lin_fit:
            return False
        return val_rms(w) > rms_lin

    early = _best_of(
        NetworkProblem(net, u[:n_fit], t[:n_fit]),
        starts,
        options=options,
        callback=callback,
        monitor=decided_linear,
    )
    rms_net = val_rms(early.params)
    if rms_net <= rms_lin:
        full = levenberg_marquardt(
            NetworkProblem(net, u, t), early.params.clone(), options=options, callback=callback
        )
        return full, (
            f"kept: on the latest {VALIDATION_FRACTION:.0%} of the training samples it leaves "
            f"{rms_net / rms_lin:.3f}× the linear path's RMS"
        )
    # Hidden layer off: the least-squares linear solution on every sample.
    off = net.unpack(early.params.clone())
    off["W2"] = torch.zeros_like(off["W2"])
    off["L"], off["b2"] = linear_init[0].clone(), linear_init[1].clone()
    w_off = net.pack(off)
    r_off = NetworkProblem(net, u, t).residuals(w_off)
    result = LMResult(
        params=w_off,
        epochs=early.epochs,
        loss=float(0.5 * torch.sum(r_off**2)),
        mse=float(torch.mean(r_off**2)),
        stop_reason=early.stop_reason,
        n_residuals=r_off.numel(),
    )
    return result, (
        f"off: on the latest {VALIDATION_FRACTION:.0%} of the training samples it left "
        f"{rms_net / rms_lin:.3f}× the linear path's RMS"
        + (
            f" (decided after {early.epochs} epochs: it had lowered the training error by less "
            f"than {GUARD_MIN_GAIN:.1%} of the linear path's)"
            if early.stop_reason == "monitor"
            else ""
        )
        + ", so the calibration is the linear least-squares solution"
    )
