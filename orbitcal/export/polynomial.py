"""``polynomial``: per-axis polynomials for one-input tools (CONTRACT section 7, diagonal only).

Tools whose calibrator sees one parameter (a Yamcs ``PolynomialCalibrator``, a COSMOS
``POLY_READ_CONVERSION``, an MDB override) can carry ``b_cal_i = c0_i + c1_i * raw_i``, i.e. the
diagonal of the affine form: ``c1_i = M_ii``, ``c0_i = -M_ii * o_i``. Cross-axis terms and
housekeeping terms are dropped; the file states what that costs on held-out data when measured.
The output is JSON with ready-to-paste snippets for XTCE/Yamcs and COSMOS (XTCE's
``<Term exponent="1" coefficient="..."/>``: coefficient and exponent as named).
"""

from __future__ import annotations

import json

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.export._text import f64, loss_lines
from orbitcal.export.options import ExportOptions
from orbitcal.export.product import AffineForm, NetworkForm, ProductInfo, affine_part

__all__ = ["diagonal_coefficients", "evaluate_diagonal", "render_polynomial"]


def diagonal_coefficients(form: AffineForm | NetworkForm) -> list[tuple[float, float]]:
    """``[(c0, c1)]`` per axis of the affine part's diagonal."""
    aff = affine_part(form)
    return [(float(-aff.M[i, i] * aff.o[i]), float(aff.M[i, i])) for i in range(3)]


def evaluate_diagonal(form: AffineForm | NetworkForm, b_raw_nt: FloatArray) -> FloatArray:
    """``c0 + c1 * raw`` per axis [nT]."""
    c = np.asarray(diagonal_coefficients(form))
    out: FloatArray = c[:, 0] + c[:, 1] * np.asarray(b_raw_nt, dtype=np.float64).reshape(-1, 3)
    return out


#: The largest field a LEO magnetometer sees [nT] (|B| at the surface near the poles is ~66,000
#: nT; at 300 km and above less): the scale of the bound of :func:`dropped_terms_bound`.
LEO_FIELD_MAX_NT = 65_000.0


def dropped_terms_bound(form: AffineForm | NetworkForm) -> str:
    """What the coefficients alone say of the diagonal polynomials' loss: the dropped
    off-diagonal terms change a component by at most ``sum_j≠i |M_ij| · 65,000 nT``; dropped
    housekeeping terms and a network's nonlinear part cannot be bounded without telemetry."""
    aff = affine_part(form)
    off = np.abs(aff.M - np.diag(np.diag(aff.M))).sum(axis=1) * LEO_FIELD_MAX_NT
    text = (
        "without telemetry, from the coefficients alone: the dropped cross-axis terms change "
        f"x, y, z by at most {', '.join(f'{v:.3g}' for v in off)} nT at a field of "
        f"{LEO_FIELD_MAX_NT:,.0f} nT (the worst case; an orbit's RMS is smaller)"
    )
    unbounded = []
    if aff.hk_names:
        unbounded.append(f"the housekeeping terms ({', '.join(aff.hk_names)})")
    if isinstance(form, NetworkForm):
        unbounded.append("the network's nonlinear part")
    if unbounded:
        text += f"; {' and '.join(unbounded)} cannot be bounded without telemetry"
    return text


def render_polynomial(
    form: AffineForm | NetworkForm, info: ProductInfo, options: ExportOptions
) -> bytes:
    """The JSON file as bytes."""
    aff = affine_part(form)
    off_diag = float(np.max(np.abs(aff.M - np.diag(np.diag(aff.M)))))
    exact = off_diag == 0.0 and not aff.hk_names and isinstance(form, AffineForm)
    carries = (
        "the diagonal of the affine form only (off-diagonal terms up to "
        f"{off_diag:.3g} dropped"
        + (f", housekeeping terms {', '.join(aff.hk_names)} dropped" if aff.hk_names else "")
        + ")"
    )
    axes = []
    for axis, (c0, c1) in enumerate(diagonal_coefficients(form)):
        raw, cal = options.raw_names[axis], options.cal_names[axis]
        axes.append(
            {
                "axis": axis,
                "input": raw,
                "output": cal,
                "coefficients": [c0, c1],
                "formula": f"{cal} = {f64(c0)} + {f64(c1)} * {raw}  [nT]",
                "xtce": (
                    "<xtce:PolynomialCalibrator>"
                    f'<xtce:Term exponent="0" coefficient="{f64(c0)}"/>'
                    f'<xtce:Term exponent="1" coefficient="{f64(c1)}"/>'
                    "</xtce:PolynomialCalibrator>"
                ),
                "cosmos": f"POLY_READ_CONVERSION {f64(c0)} {f64(c1)}",
            }
        )
    body = {
        "orbitcal_export": "polynomial",
        "product": info.to_json(),
        "notes": loss_lines(
            info,
            carries=carries,
            exact=exact,
            loss=options.loss,
            which="diagonal",
            bound=dropped_terms_bound(form),
        ),
        "held_out": None if options.loss is None else options.loss.to_json(),
        "axes": axes,
    }
    return (json.dumps(body, indent=2) + "\n").encode()
