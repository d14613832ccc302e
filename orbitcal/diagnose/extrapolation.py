"""The calibration's own extrapolation error (issue 25): on a span shorter than an orbit the
held-out blocks lie beyond the training ones, and a gap of which most goes when the 12 parameters
are fitted with the held-out blocks too cannot be separated from the calibration on that span.
:mod:`orbitcal.diagnose.honesty` calls :func:`extrapolation_words` on the reviewed report
(``gap.calibration_extrapolation``, ``gap.extrapolation_statement``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from orbitcal.diagnose.gap import deciders
from orbitcal.diagnose.span_options import ORBIT_S
from orbitcal.metrics import norm_rms_nt

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.diagnose.attribution import Attribution
    from orbitcal.diagnose.effects import DiagnosisData

__all__ = ["EXTRAPOLATION_SHARE", "calibration_extrapolation", "extrapolation_words"]

#: On a span shorter than an orbit, a held-out residual of which at least this share (of its mean
#: square) goes when the 12 parameters are fitted with the held-out blocks too is mostly the
#: calibration's own extrapolation error (:func:`calibration_extrapolation`).
EXTRAPOLATION_SHARE = 0.5


def calibration_extrapolation(data: DiagnosisData, att: Attribution) -> tuple[float, float]:
    """The held-out RMS [nT] of the calibration alone fitted with the held-out blocks too (the
    same fit mask), and the share of the baseline's held-out mean square that this removes [-]:
    how much of the held-out residual is the calibration's own extrapolation error."""
    from orbitcal.diagnose.attribution import fit_joint

    allowed = att.fit_mask if att.fit_mask is not None else np.ones(data.n, dtype=bool)
    refit = fit_joint(data, att.train | (att.holdout & allowed))
    rms = norm_rms_nt((data.b_raw_nt - refit.predict_nt(data))[att.holdout])
    share = 1.0 - (rms / max(att.baseline_rms_nt, 1e-12)) ** 2
    return float(rms), float(max(share, 0.0))


def extrapolation_words(
    report: dict[str, Any],
    data: DiagnosisData,
    att: Attribution,
    *,
    own_test: frozenset[str] = frozenset({"field_aligned_currents"}),
) -> None:
    """On a span shorter than an orbit, a verdict of none (or of the auroral currents alone)
    beside an unexplained gap that the calibration's own extrapolation error mostly makes
    (:func:`calibration_extrapolation`, :data:`EXTRAPOLATION_SHARE`): the gap cannot be separated
    from the calibration on this span, and the status says so, with the closest candidates."""
    gap = report["gap"]
    if (
        att.span_s >= ORBIT_S
        or att.has_prior
        or not gap["unexplained"]
        or gap["inseparable"]
        or report["verdict"] not in ("none", *own_test)
    ):
        return
    rms_refit, share = calibration_extrapolation(data, att)
    gap["calibration_extrapolation"] = {
        "holdout_rms_refit_nt": round(rms_refit / np.sqrt(3.0), 4),
        "share_of_holdout_mean_square": round(share, 4),
        "refit": "the 12 parameters alone, fitted with the held-out blocks too",
    }
    if share < EXTRAPOLATION_SHARE:
        return
    closest = gap["closest_candidates"]
    statement = (
        f"the held-out residual ({gap['holdout_rms_nt']:.3g} nT per component, "
        f"{gap['times_noise']:.1f} x the noise floor) cannot be separated from the calibration on "
        f"this span: {share:.0%} of its mean square is the calibration's own extrapolation error "
        "(fitted with the held-out blocks too, the 12 parameters alone leave "
        f"{rms_refit / np.sqrt(3.0):.3g} nT there), so no candidate's held-out gain can be told "
        "from a change of the calibration"
        + (
            "; closest: "
            + "; ".join(f"{c['name']} ({str(c['refused_because']).split(':')[0]})" for c in closest)
            if closest
            else ""
        )
        + "; what would decide: "
        + deciders([c["name"] for c in closest])
    )
    gap["extrapolation_statement"] = statement
    report["verdict_confidence"] = None
    if report["verdict"] == "none":
        report["verdict_status"] = "none: " + statement
    else:
        report["verdict_status"] = (
            f"{report['verdict']} on their own latitudes; beside them, " + statement
        )
