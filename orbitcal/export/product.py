"""The calibration product: what every export is generated from and says about itself.

The section-4 document (CONTRACT) stays the source. From it this module derives

* :class:`ProductInfo`: spacecraft, version, method, validity start, reference field, units, frame
  and the SHA-256 of the document (:func:`document_sha256`), which every export writes down;
* the document's calibration in one of two numpy forms the generated code mirrors:
  :class:`AffineForm` (``b_cal = M @ (b_raw - o - K @ x_hk)``, every non-network method, exact)
  and :class:`NetworkForm` (the LM-BP networks, exact);
* :func:`affine_part`: the affine form of a network, for the formats that cannot carry one.

No torch here: the network weights are read from the document's ``model`` block as numbers.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.calibrate.errors import DocumentError
from orbitcal.export.names import default_hk_name

__all__ = [
    "NETWORK_METHODS",
    "SCALAR_METHODS",
    "AffineForm",
    "NetworkForm",
    "ProductInfo",
    "affine_part",
    "calibration_form",
    "document_sha256",
    "is_exact_affine",
    "layout",
    "product_info",
]

#: Methods whose ``model`` block is a network (``orbitcal.calibrate.lmbp``).
NETWORK_METHODS = frozenset({"lmbp", "lmbp-hk"})

#: Methods that fit the magnitude only: their output is in sensor axes (docs/design.md).
SCALAR_METHODS = frozenset({"twostep", "flann", "online"})


def document_sha256(doc: dict[str, Any]) -> str:
    """SHA-256 (hex) of a section-4 document in its canonical JSON form.

    Canonical form: ``json.dumps(doc, sort_keys=True, separators=(",", ":"), ensure_ascii=False,
    allow_nan=False)`` encoded as UTF-8, so the digest does not depend on indentation or key order
    and a consumer can recompute it from the document it was given (``docs/export/README.md``).
    """
    try:
        text = json.dumps(
            doc, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False
        )
    except (TypeError, ValueError) as exc:
        raise DocumentError(f"the calibration document is not plain JSON: {exc}") from exc
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


@dataclass(frozen=True)
class ProductInfo:
    """What every export names about the calibration it carries."""

    spacecraft: str
    version: int
    method: str
    created_at: str
    #: The calibration applies to data from this time on (its ``created_at``: the moment it was
    #: fitted or, in the service, stored; a version in service is superseded by the next one).
    validity_start: str
    data_start: str
    data_end: str
    reference_field: str
    holdout_rms_nt: float | None
    units: str
    frame: str
    sha256: str

    def lines(self) -> list[str]:
        """``key: value`` lines for a file header."""
        rms = "n/a" if self.holdout_rms_nt is None else f"{self.holdout_rms_nt:.6g} nT"
        return [
            f"spacecraft: {self.spacecraft}",
            f"calibration version: {self.version}",
            f"method: {self.method}",
            f"created at: {self.created_at}",
            f"validity start: {self.validity_start}",
            f"fitted on data: {self.data_start} .. {self.data_end}",
            f"reference field: {self.reference_field}",
            f"held-out RMS of the full calibration: {rms}",
            f"units: {self.units}",
            f"frame: {self.frame}",
            f"document SHA-256: {self.sha256}",
        ]

    def to_json(self) -> dict[str, Any]:
        return {
            "spacecraft": self.spacecraft,
            "version": self.version,
            "method": self.method,
            "created_at": self.created_at,
            "validity_start": self.validity_start,
            "data": {"start": self.data_start, "end": self.data_end},
            "reference_field": self.reference_field,
            "holdout_rms_nt": self.holdout_rms_nt,
            "units": self.units,
            "frame": self.frame,
            "document_sha256": self.sha256,
        }


def product_info(doc: dict[str, Any]) -> ProductInfo:
    """The product metadata of a section-4 document.

    Raises
    ------
    DocumentError
        A key the exports need is missing or malformed.
    """
    try:
        method = str(doc["method"])
        data = doc.get("data") or {}
        rms = (doc.get("metrics") or {}).get("holdout_rms_nt")
        model = doc.get("model") or {}
        attitude_frame = str(model.get("attitude_frame", "GCRS"))
        if method in SCALAR_METHODS:
            frame = "sensor axes (scalar method: the axes are not rotated to the body frame)"
        else:
            frame = f"body frame (reference field rotated from {attitude_frame} by the attitude)"
        return ProductInfo(
            spacecraft=str(doc["spacecraft"]),
            version=int(doc["version"]),
            method=method,
            created_at=str(doc["created_at"]),
            validity_start=str(doc["created_at"]),
            data_start=str(data.get("start", "")),
            data_end=str(data.get("end", "")),
            reference_field=str(doc["reference_field"]),
            holdout_rms_nt=None if rms is None else float(rms),
            units="nT (magnetometer in and out); housekeeping in its table unit "
            "(temperature degC, mtq_* A m2)",
            frame=frame,
            sha256=document_sha256(doc),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise DocumentError(f"calibration document: cannot read {exc}") from exc


@dataclass(frozen=True)
class AffineForm:
    """``b_cal = M @ (b_raw - o - K @ x_hk)`` [nT]; ``K`` is ``(3, k)`` for ``hk_names``."""

    M: FloatArray
    o: FloatArray
    K: FloatArray
    hk_names: tuple[str, ...]

    def coefficients(self) -> dict[str, float]:
        """Named coefficients (the names of the local parameters / variables / C fields)."""
        out: dict[str, float] = {}
        for i in range(3):
            for j in range(3):
                out[f"M_{i}_{j}"] = float(self.M[i, j])
        for i in range(3):
            out[f"O_{i}"] = float(self.o[i])
        for i in range(3):
            for j in range(len(self.hk_names)):
                out[f"K_{i}_{j}"] = float(self.K[i, j])
        return out


@dataclass(frozen=True)
class NetworkForm:
    """The LM-BP network of :mod:`orbitcal.calibrate.lmbp` in plain arrays.

    ``u = (x - in_lo) * in_gain - [in_gain > 0]`` for ``x = [b_raw, x_hk]``;
    ``y = W2 @ phi(W1 @ u + b1) + b2 + L @ u`` (``phi`` tanh or logistic);
    ``b_cal = (y + 1) / out_gain + out_lo`` per axis, ``out_lo`` where ``out_gain == 0``.
    """

    in_lo: FloatArray
    in_gain: FloatArray
    W1: FloatArray
    b1: FloatArray
    W2: FloatArray
    b2: FloatArray
    L: FloatArray
    out_lo: FloatArray
    out_gain: FloatArray
    activation: str
    hk_names: tuple[str, ...]

    @property
    def n_hidden(self) -> int:
        return int(self.W1.shape[0])

    @property
    def n_in(self) -> int:
        return int(self.W1.shape[1])

    def coefficients(self) -> dict[str, float]:
        """Named coefficients, row-major (``W1_j_i`` is hidden unit ``j``, input ``i``)."""
        out: dict[str, float] = {}

        def put(prefix: str, a: FloatArray) -> None:
            if a.ndim == 1:
                for i, v in enumerate(a):
                    out[f"{prefix}_{i}"] = float(v)
            else:
                for i in range(a.shape[0]):
                    for j in range(a.shape[1]):
                        out[f"{prefix}_{i}_{j}"] = float(a[i, j])

        put("IN_LO", self.in_lo)
        put("IN_GAIN", self.in_gain)
        put("W1", self.W1)
        put("B1", self.b1)
        put("W2", self.W2)
        put("B2", self.b2)
        put("L", self.L)
        put("OUT_LO", self.out_lo)
        put("OUT_GAIN", self.out_gain)
        return out


def _gain(lo: list[float], hi: list[float]) -> tuple[FloatArray, FloatArray]:
    lo_a = np.asarray(lo, dtype=np.float64)
    span = np.asarray(hi, dtype=np.float64) - lo_a
    gain = np.where(span > 0, 2.0 / np.where(span > 0, span, 1.0), 0.0)
    return lo_a, gain


def calibration_form(doc: dict[str, Any]) -> AffineForm | NetworkForm:
    """The document's full calibration as an :class:`AffineForm` or a :class:`NetworkForm`.

    Raises
    ------
    DocumentError
        A malformed model block or a method no export knows.
    """
    method = str(doc.get("method", ""))
    model = doc.get("model")
    if not isinstance(model, dict):
        raise DocumentError("calibration document: model is not an object")
    try:
        hk = tuple(str(h) for h in model.get("hk_names", []))
        if method in NETWORK_METHODS:
            n_in = 3 + len(hk)
            w = model["weights"]
            H = int(model["n_hidden"])
            in_lo, in_gain = _gain(model["input_scaler"]["min"], model["input_scaler"]["max"])
            out_lo, out_gain = _gain(model["output_scaler"]["min"], model["output_scaler"]["max"])
            L = (
                np.asarray(w["L"], dtype=np.float64).reshape(3, n_in)
                if model.get("linear_path")
                else np.zeros((3, n_in))
            )
            activation = str(model["activation"])
            if activation not in ("tanh", "sigmoid"):
                raise ValueError(f"unknown activation {activation!r}")
            return NetworkForm(
                in_lo=in_lo.reshape(n_in),
                in_gain=in_gain.reshape(n_in),
                W1=np.asarray(w["W1"], dtype=np.float64).reshape(H, n_in),
                b1=np.asarray(w["b1"], dtype=np.float64).reshape(H),
                W2=np.asarray(w["W2"], dtype=np.float64).reshape(3, H),
                b2=np.asarray(w["b2"], dtype=np.float64).reshape(3),
                L=L,
                out_lo=out_lo.reshape(3),
                out_gain=out_gain.reshape(3),
                activation=activation,
                hk_names=hk,
            )
        K = np.asarray(model.get("K", [[], [], []]), dtype=np.float64).reshape(3, len(hk))
        return AffineForm(
            M=np.asarray(model["M"], dtype=np.float64).reshape(3, 3),
            o=np.asarray(model["o"], dtype=np.float64).reshape(3),
            K=K,
            hk_names=hk,
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise DocumentError(f"malformed {method or '?'} model block: {exc}") from exc


def affine_part(form: AffineForm | NetworkForm) -> AffineForm:
    """The affine form of a calibration: itself when affine; for a network its first-order
    expansion about the centre of the training inputs' range (``u = 0``).

    ``y ≈ c + J u`` with ``J = L + W2 diag(phi'(b1)) W1`` and ``c = W2 phi(b1) + b2``; exact
    when the hidden layer is off (``W2 = 0``, the validation guard of ``lmbp-hk``), the linear
    path alone otherwise plus the hidden layer's tangent. Housekeeping terms are kept (``K``).
    """
    if isinstance(form, AffineForm):
        return form
    z = form.b1
    if form.activation == "tanh":
        h = np.tanh(z)
        dh = 1.0 - h * h
    else:
        h = 1.0 / (1.0 + np.exp(-z))
        dh = h * (1.0 - h)
    J = form.L + form.W2 @ (dh[:, None] * form.W1)  # (3, n_in)
    c = form.W2 @ h + form.b2
    s_out = np.where(form.out_gain > 0, 1.0 / np.where(form.out_gain > 0, form.out_gain, 1.0), 0.0)
    e_in = (form.in_gain > 0).astype(np.float64)
    A = s_out[:, None] * (J * form.in_gain[None, :])  # d b_cal / d x
    d = form.out_lo + s_out * (c + 1.0 - J @ (form.in_gain * form.in_lo + e_in))
    M = A[:, :3]
    cond = float(np.linalg.cond(M))
    if not cond < 1e10:
        raise DocumentError(
            f"the network's affine part is singular (condition number {cond:.3g}): it cannot be "
            "written as b_cal = M (b_raw - o - K hk), which the xtce MathAlgorithms, c-header "
            "and polynomial carry; cosmos carries the whole network"
        )
    Minv = np.linalg.inv(M)
    return AffineForm(M=M, o=-Minv @ d, K=-Minv @ A[:, 3:], hk_names=form.hk_names)


def layout(form: AffineForm | NetworkForm) -> str:
    """The shape of a form's coefficient set (``affine:hk=5:...``,
    ``network:tanh:in=8:hidden=3:...``):
    a generated algorithm or conversion takes new values for the same layout only.

    The housekeeping columns enter as their default parameter names (plain ASCII, the export's
    name policy) and a digest of the exact column names, so the layout is safe in any target's
    text and still tells two sets of columns apart."""
    names = ",".join(default_hk_name(c) for c in form.hk_names)
    digest = hashlib.sha256(json.dumps(list(form.hk_names)).encode()).hexdigest()[:8]
    tail = f"{names}:{digest}" if form.hk_names else ""
    if isinstance(form, AffineForm):
        return f"affine:hk={len(form.hk_names)}:{tail}"
    return f"network:{form.activation}:in={form.n_in}:hidden={form.n_hidden}:{tail}"


def is_exact_affine(form: AffineForm | NetworkForm) -> bool:
    """True when the affine part is the whole calibration (affine methods, or a network whose
    hidden layer is off)."""
    return isinstance(form, AffineForm) or not bool(np.any(form.W2))
