"""The reference evaluator: a calibration document applied in numpy alone (no torch).

It is the specification every generated consumer (JavaScript, Python conversion, C, XTCE
postfix) is tested against, and it equals ``orbitcal apply`` (:func:`orbitcal.pipeline.
apply_document`) to 1e-6 nT for every method (``tests/test_export_evaluate.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.errors import BadInputError
from orbitcal.export.product import AffineForm, NetworkForm, calibration_form

__all__ = ["evaluate", "evaluate_document"]


def _inputs(b_raw_nt: FloatArray, x_hk: FloatArray | None, hk_names: tuple[str, ...]) -> FloatArray:
    b = np.asarray(b_raw_nt, dtype=np.float64).reshape(-1, 3)
    if not hk_names:
        return b
    if x_hk is None:
        raise BadInputError(
            f"this calibration needs housekeeping columns {', '.join(hk_names)}",
            field=hk_names[0],
        )
    x = np.asarray(x_hk, dtype=np.float64).reshape(b.shape[0], -1)
    if x.shape[1] != len(hk_names):
        raise BadInputError(
            f"this calibration needs {len(hk_names)} housekeeping columns "
            f"({', '.join(hk_names)}), got {x.shape[1]}",
            field=hk_names[0],
        )
    return np.hstack([b, x])


def evaluate(
    form: AffineForm | NetworkForm, b_raw_nt: FloatArray, x_hk: FloatArray | None = None
) -> FloatArray:
    """Calibrated field ``(N, 3)`` [nT] from raw ``(N, 3)`` [nT, sensor axes] and the
    housekeeping columns ``(N, k)`` in the order of ``form.hk_names``."""
    x = _inputs(b_raw_nt, x_hk, form.hk_names)
    if isinstance(form, AffineForm):
        b = x[:, :3] - form.o
        if form.hk_names:
            b = b - x[:, 3:] @ form.K.T
        out: FloatArray = b @ form.M.T
        return out
    u = (x - form.in_lo) * form.in_gain - np.where(form.in_gain > 0, 1.0, 0.0)
    z = u @ form.W1.T + form.b1
    h = np.tanh(z) if form.activation == "tanh" else 1.0 / (1.0 + np.exp(-z))
    y = h @ form.W2.T + form.b2 + u @ form.L.T
    safe = np.where(form.out_gain > 0, form.out_gain, 1.0)
    res: FloatArray = np.where(form.out_gain > 0, (y + 1.0) / safe + form.out_lo, form.out_lo)
    return res


def evaluate_document(
    doc: dict[str, Any], b_raw_nt: FloatArray, x_hk: FloatArray | None = None
) -> FloatArray:
    """:func:`evaluate` of the document's full calibration."""
    return evaluate(calibration_form(doc), b_raw_nt, x_hk)
