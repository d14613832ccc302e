"""Templates that draw the same field on a span (issue 25): a candidate that reproduces the
verdict's own part of the field and explains the held-out residual nearly as well is named beside
the verdict (``report["confounded_with"]``), with what would decide.

Under a spin about one axis a field fixed in space (a ring current) is a Sun-driven field's matrix
times the Sun direction; on a span shorter than an orbit with no eclipse (the real Swarm storm pass
is lit throughout) a Sun-driven field is a field fixed in space for every attitude, and the review
withdraws it (``status: "unlit"``, :func:`sun_driven_without_eclipse`).
:mod:`orbitcal.diagnose.honesty` calls :func:`confounding_words` on the reviewed report.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from orbitcal.arrays import BoolArray
from orbitcal.diagnose.gap import deciders
from orbitcal.diagnose.span_options import ORBIT_S

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.diagnose.attribution import Attribution
    from orbitcal.diagnose.design import DesignBlock
    from orbitcal.diagnose.effects import DiagnosisData

__all__ = [
    "CONFOUND_RATIO",
    "CONFOUND_SHARE",
    "confounded_with",
    "confounding_words",
    "sun_driven_without_eclipse",
]

#: A candidate whose design (with the calibration's) reproduces at least this share of the
#: verdict's fitted field beyond the calibration, and leaves at most :data:`CONFOUND_RATIO` times
#: the verdict's held-out residual, cannot be told from the verdict on this span
#: (:func:`confounded_with`).
CONFOUND_SHARE = 0.9
CONFOUND_RATIO = 1.5


def _variant_block(
    data: DiagnosisData, train: BoolArray, name: str, variant: str | None
) -> DesignBlock | None:
    """The design of ``name`` in its reported variant (else its first form)."""
    from orbitcal.diagnose.effects import get_effect

    block = get_effect(name).design(data, train)
    if block is None:
        return None
    for b in (block, *block.alternatives):
        if variant and b.variant == variant:
            return b
    return block


def confounded_with(
    data: DiagnosisData,
    att: Attribution,
    verdict: str,
    fit_names: Sequence[str],
    *,
    own_test: frozenset[str] = frozenset({"field_aligned_currents"}),
) -> list[tuple[str, float]]:
    """Candidates the span cannot tell from the verdict, with the share of the verdict's fitted
    field beyond the calibration that each reproduces (least squares on the training samples,
    the 12 parameters and the candidate's design free), best first.

    Under a spin about one axis, a field fixed in space (a ring current) is a Sun-driven field's
    matrix times the Sun direction, and a time shift is a change of the body rates' projection:
    two templates can draw the same field on a short span. Such a candidate explains the held-out
    residual nearly as well (within :data:`CONFOUND_RATIO`) and reproduces at least
    :data:`CONFOUND_SHARE` of the verdict's own part; the report then names it."""
    from orbitcal.diagnose.attribution import fit_joint

    fit = att.fits.get("final")
    by_name = {e.name: e for e in att.effects}
    if fit is None or verdict not in fit_names or verdict not in by_name:
        return []
    f = fit.effect_nt(list(fit_names).index(verdict))
    a = float(by_name[verdict].absorbed_fraction or 0.0)
    beyond = (1.0 - a) * float(np.sum(f[att.train] ** 2))
    if beyond <= 0.0:
        return []
    probe = dataclasses.replace(data, b_raw_nt=data.b_ref_body_nt + f)
    out = []
    for e in att.effects:
        if (
            e.name == verdict
            or e.name in att.selected
            or e.name in own_test
            or e.holdout_rms_after_nt > CONFOUND_RATIO * by_name[verdict].holdout_rms_after_nt
        ):
            continue
        block = _variant_block(data, att.train, e.name, e.params.get("variant"))
        if block is None:
            continue
        rival = fit_joint(probe, att.train, [block], robust=False, bounded=False, use_prior=False)
        orth = (probe.b_raw_nt - rival.predict_nt(probe))[att.train]
        share = 1.0 - float(np.sum(orth**2)) / beyond
        if share >= CONFOUND_SHARE:
            out.append((e.name, min(share, 1.0)))
    return sorted(out, key=lambda x: -x[1])


def confounding_words(
    report: dict[str, Any],
    data: DiagnosisData,
    att: Attribution,
    fit_names: Sequence[str],
    *,
    verdict_stands: bool,
    own_test: frozenset[str],
) -> None:
    """``confounded_with`` and the verdict status's words for candidates the span cannot tell
    from the verdict (:func:`confounded_with`); ``verdict_stands``: the review kept the
    attribution's verdict (its final fit is then the verdict's)."""
    verdict = report["verdict"]
    found = (
        confounded_with(data, att, verdict, fit_names, own_test=own_test) if verdict_stands else []
    )
    report["confounded_with"] = [
        {"name": n, "share_of_field_beyond_calibration": round(share, 4)} for n, share in found
    ]
    unlit = sun_driven_without_eclipse(data, att, verdict)
    if unlit:
        report["confounded_with"].append(
            {"name": "external_field", "reason": "no eclipse on a span shorter than an orbit"}
        )
    if not found and not unlit:
        return
    by_name = {e.name: e for e in att.effects}
    names = [n for n, _ in found]
    status = report.get("verdict_status") or "firm"
    if unlit and status == "firm":
        status = "tentative"
    report["verdict_status"] = (
        status
        + (
            f"; on this span {verdict} cannot be told apart from "
            + ", ".join(
                f"{n} ({share:.0%} of {verdict}'s field beyond the calibration is {n}'s; "
                f"held-out {by_name[n].holdout_rms_after_nt / np.sqrt(3.0):.3g} nT against "
                f"{by_name[verdict].holdout_rms_after_nt / np.sqrt(3.0):.3g} nT)"
                for n, share in found
            )
            if found
            else ""
        )
        + (
            "; the span has no eclipse and is shorter than an orbit: a field that is a linear "
            "map of the Sun direction is then any field fixed in space (the ring current's, "
            "external_field, among them), so nothing here says it comes from the Sun"
            if unlit
            else ""
        )
        + "; what would decide: "
        + deciders([verdict, *names, *(["external_field"] if unlit else [])])
    )


def sun_driven_without_eclipse(data: DiagnosisData, att: Attribution, verdict: str) -> bool:
    """``verdict`` (an effect's name) is a Sun-driven field on a span shorter than an orbit
    without a sample in eclipse: the Sun direction is fixed in space over it, and the template's
    one signature of the Sun (on when lit, off in eclipse) is absent from the data."""
    if verdict != "sun_driven" or att.span_s >= ORBIT_S:
        return False
    lit = (
        np.asarray(data.illumination) > 0.5
        if data.illumination is not None
        else (np.asarray(data.sunlit, dtype=bool) if data.sunlit is not None else None)
    )
    return lit is not None and bool(np.all(lit))
