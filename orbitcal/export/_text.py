"""Helpers shared by the generators: exact float literals and the loss sentence."""

from __future__ import annotations

from orbitcal.export.options import HeldOutLoss
from orbitcal.export.product import ProductInfo

__all__ = ["f64", "loss_lines"]


def f64(value: float) -> str:
    """The shortest literal that reads back as the same float64 (``repr``), valid in JS, C,
    Python and ``xs:double``."""
    text = repr(float(value))
    if text in ("inf", "-inf", "nan"):
        raise ValueError(f"non-finite coefficient {text}")
    return text


def loss_lines(
    info: ProductInfo,
    *,
    carries: str,
    exact: bool,
    loss: HeldOutLoss | None,
    which: str,
    bound: str | None = None,
) -> list[str]:
    """Sentences saying what a reduced form carries and what it gives on held-out data.

    ``which`` is ``"affine"`` or ``"diagonal"``; ``bound``: what the coefficients alone say of
    the loss, stated when no telemetry measured it.
    """
    full = "n/a" if info.holdout_rms_nt is None else f"{info.holdout_rms_nt:.6g} nT"
    lines = [f"carries: {carries}"]
    if exact:
        lines.append("this is the whole calibration: its output equals orbitcal apply (to 1e-6 nT)")
        return lines
    lines.append(f"this is less than the whole {info.method} model (held-out RMS {full})")
    if loss is None:
        lines.append(
            "held-out RMS of this form: not measured (export with --telemetry TABLE, and --tle "
            "when the table has no positions, to state it)"
        )
        if bound:
            lines.append(bound)
    else:
        reduced = loss.affine_rms_nt if which == "affine" else loss.diagonal_rms_nt
        worst = loss.affine_max_abs_diff_nt if which == "affine" else loss.diagonal_max_abs_diff_nt
        lines.append(
            f"held-out RMS of this form: {reduced:.6g} nT vs {loss.full_rms_nt:.6g} nT for the "
            f"whole model on the same {loss.n_samples} samples ({loss.source}); it differs from "
            f"orbitcal apply by up to {worst:.6g} nT per component"
        )
    return lines
