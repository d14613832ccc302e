"""The promotion decision: does a challenger replace the calibration in service?"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from orbitcal.arrays import FloatArray

__all__ = [
    "PROMOTE_ALPHA",
    "PROMOTE_CHUNKS",
    "PROMOTE_MARGIN",
    "Promotion",
    "PromotionRule",
    "decide_promotion",
    "refuse_undetermined",
]

#: A challenger must beat the champion's held-out RMS by at least this fraction [-] …
PROMOTE_MARGIN = 0.01
#: … and the gain must be significant at this level (one-sided Wilcoxon signed-rank test) [-].
PROMOTE_ALPHA = 0.01
#: Consecutive held-out chunks the paired test compares (samples within a chunk are correlated,
#: chunks nearly independent; 16 chunks give p ≥ 2⁻¹⁶ ≈ 1.5e-5).
PROMOTE_CHUNKS = 16


@dataclass(frozen=True)
class Promotion:
    """Whether a challenger replaces the calibration in service, and which rule decided.

    Attributes
    ----------
    promote : bool
    rule : str
        ``"first calibration"`` / ``"champion cannot be scored"`` (promoted: nothing comparable
        in service, and the challenger beats the uncalibrated readings), ``"identity"`` (refused:
        it does not beat them), ``"undetermined"`` (refused: the data cannot determine it),
        ``"implausible"`` (refused: no magnetometer in nT has it, :mod:`orbitcal.plausibility`),
        ``"margin"`` (the gain is below the margin), ``"significance"`` (above the margin, not
        significant) or ``"margin and significance"`` (both passed: promoted).
    reason : str
        One sentence for operators.
    metric : str
        The compared figure (``rms_nt`` or ``scalar_rms_nt``, :mod:`orbitcal.metrics`).
    challenger_rms_nt, champion_rms_nt : float or None
    gain : float or None
        ``1 − challenger/champion`` [-].
    p_value : float or None
        One-sided Wilcoxon signed-rank p-value that the challenger's per-chunk mean squared
        residual is lower (None when not tested).
    margin, alpha : float
        The rule's parameters.
    n_chunks : int
    """

    promote: bool
    rule: str
    reason: str
    metric: str
    challenger_rms_nt: float
    champion_rms_nt: float | None
    gain: float | None
    p_value: float | None
    margin: float
    alpha: float
    n_chunks: int
    #: The uncalibrated readings' held-out RMS when the challenger was compared with them
    #: (no champion to compare with) [nT].
    identity_rms_nt: float | None = None

    def as_dict(self) -> dict[str, Any]:
        return {
            "promoted": self.promote,
            "rule": self.rule,
            "metric": self.metric,
            "challenger_rms_nt": self.challenger_rms_nt,
            "champion_rms_nt": self.champion_rms_nt,
            "identity_rms_nt": self.identity_rms_nt,
            "gain": self.gain,
            "p_value": self.p_value,
            "margin": self.margin,
            "alpha": self.alpha,
            "test": f"one-sided Wilcoxon signed-rank over {self.n_chunks} consecutive held-out "
            "chunks of the mean squared residual (champion − challenger)",
        }


def _chunk_p_value(sq_challenger: FloatArray, sq_champion: FloatArray, n_chunks: int) -> float:
    """One-sided p-value that the challenger's chunk-mean squared residuals are lower."""
    from scipy.stats import wilcoxon

    chunks = np.array_split(np.arange(sq_challenger.shape[0]), n_chunks)
    d = np.array([sq_champion[c].mean() - sq_challenger[c].mean() for c in chunks if c.size])
    if d.size == 0 or not np.any(d != 0.0):
        return 1.0
    return float(wilcoxon(d, alternative="greater", zero_method="zsplit").pvalue)


@dataclass(frozen=True)
class PromotionRule:
    """The promotion rule's parameters (:func:`decide_promotion`)."""

    #: The challenger must beat the other calibration's held-out RMS by more than this [-] …
    margin: float = PROMOTE_MARGIN
    #: … with a one-sided paired p-value below this [-] …
    alpha: float = PROMOTE_ALPHA
    #: … over this many consecutive held-out chunks.
    n_chunks: int = PROMOTE_CHUNKS


@dataclass(frozen=True)
class _Contest:
    """The challenger against one other calibration on the same held-out rows."""

    other_rms_nt: float
    gain: float
    p_value: float | None  # None: the margin already failed, not tested
    n_chunks: int
    alpha: float

    @property
    def won(self) -> bool:
        return self.p_value is not None and self.p_value < self.alpha


def _contest(ch_sq: FloatArray, other_sq: FloatArray, rule: PromotionRule) -> _Contest:
    ch_rms = float(np.sqrt(np.mean(ch_sq)))
    other_rms = float(np.sqrt(np.mean(other_sq)))
    gain = 1.0 - ch_rms / other_rms if other_rms > 0 else 0.0
    n = min(rule.n_chunks, len(ch_sq))
    if not gain > rule.margin:
        return _Contest(other_rms, gain, None, n, rule.alpha)
    return _Contest(other_rms, gain, _chunk_p_value(ch_sq, other_sq, n), n, rule.alpha)


def decide_promotion(
    challenger_sq_nt2: FloatArray,
    champion_sq_nt2: FloatArray | None,
    *,
    metric: str,
    champion_version: int | None = None,
    span: str = "",
    rule: PromotionRule | None = None,
    champion_problem: str | None = None,
    identity_sq_nt2: FloatArray | None = None,
) -> Promotion:
    """Promote a challenger only for a real improvement on the same held-out rows.

    Both calibrations are judged by ``metric`` on the same time-ordered held-out rows. The
    challenger is promoted when its RMS is below ``(1 − margin) ×`` the champion's **and** the
    paired one-sided Wilcoxon signed-rank test over ``n_chunks`` consecutive chunks of the
    per-row squared residuals gives ``p < alpha`` (chunks, not rows, because neighbouring
    samples share their errors). 1.947 against 1.948 nT therefore stays rejected.

    Without a champion to compare with (the first calibration, or one that cannot be scored on
    these rows), the challenger must beat the **identity** — the raw readings taken as they are —
    by the same rule: a calibration worse than none is never put in service (issue 24: a stuck
    sensor's first calibration was 1,072,798 nT held out against 29,936 nT uncalibrated).

    Parameters
    ----------
    challenger_sq_nt2, champion_sq_nt2 : ndarray, shape (N,)
        Per held-out row, the squared residual whose mean is ``metric``² [nT²] (time order);
        ``champion_sq_nt2`` None when nothing is in service.
    metric
        Name of the compared figure (for the reason).
    champion_version
        Version in service (for the reason).
    span
        The held-out time span, for the reason.
    rule
        Margin, significance level and chunk count (default :class:`PromotionRule`).
    champion_problem
        Why the champion could not be scored on these rows.
    identity_sq_nt2 : ndarray, shape (N,), optional
        The same squared residual of the uncalibrated readings; compared with when no champion
        is; None skips that comparison (the challenger is promoted, as before issue 24).
    """
    judge = _Judge(
        metric=metric,
        challenger_sq_nt2=challenger_sq_nt2,
        rule=rule or PromotionRule(),
        where=f" on {span}" if span else "",
    )
    if champion_sq_nt2 is not None:
        return judge.versus_champion(champion_sq_nt2, champion_version)
    if champion_problem is None:
        name, said = "first calibration", "first calibration of this spacecraft"
    else:
        name = "champion cannot be scored"
        said = (
            f"version {champion_version} in service cannot be scored on the new data "
            f"({champion_problem})"
        )
    if identity_sq_nt2 is None:  # callers without the identity's residuals: promoted
        held_out = f"; held-out {metric} {judge.ch_rms:.3f} nT" if champion_problem else ""
        return judge.decided(True, name, said + held_out)
    return judge.versus_identity(identity_sq_nt2, name, said)


@dataclass(frozen=True)
class _Judge:
    """One challenger's held-out residuals, judged against a champion or the identity."""

    metric: str
    challenger_sq_nt2: FloatArray
    rule: PromotionRule
    where: str

    @property
    def ch_rms(self) -> float:
        return float(np.sqrt(np.mean(self.challenger_sq_nt2)))

    def decided(
        self,
        promote: bool,
        rule_name: str,
        reason: str,
        contest: _Contest | None = None,
        *,
        identity: bool = False,
    ) -> Promotion:
        return Promotion(
            promote=promote,
            rule=rule_name,
            reason=reason,
            metric=self.metric,
            challenger_rms_nt=self.ch_rms,
            champion_rms_nt=None if contest is None or identity else contest.other_rms_nt,
            gain=None if contest is None else contest.gain,
            p_value=None if contest is None else contest.p_value,
            margin=self.rule.margin,
            alpha=self.rule.alpha,
            n_chunks=self.rule.n_chunks,
            identity_rms_nt=contest.other_rms_nt if contest is not None and identity else None,
        )

    def versus_champion(self, champion_sq_nt2: FloatArray, version: int | None) -> Promotion:
        c = _contest(self.challenger_sq_nt2, champion_sq_nt2, self.rule)
        margin, alpha, ch = self.rule.margin, self.rule.alpha, self.ch_rms
        head = f"held-out {self.metric} {ch:.3f} nT"
        versus = f"version {version}'s {c.other_rms_nt:.3f} nT"
        if c.p_value is None:
            return self.decided(
                False,
                "margin",
                f"{head} does not beat {versus} in service{self.where} "
                f"(gain {100 * c.gain:.2f} %, needs > {100 * margin:g} %)",
                c,
            )
        if c.won:
            return self.decided(
                True,
                "margin and significance",
                f"{head} beats {versus}{self.where} (gain {100 * c.gain:.2f} % > "
                f"{100 * margin:g} %, p = {c.p_value:.2g} < {alpha:g})",
                c,
            )
        return self.decided(
            False,
            "significance",
            f"{head} does not beat {versus} in service{self.where} significantly (gain "
            f"{100 * c.gain:.2f} %, p = {c.p_value:.2g} >= {alpha:g} over {c.n_chunks} chunks)",
            c,
        )

    def versus_identity(self, identity_sq_nt2: FloatArray, name: str, said: str) -> Promotion:
        c = _contest(self.challenger_sq_nt2, identity_sq_nt2, self.rule)
        margin, alpha = self.rule.margin, self.rule.alpha
        head = f"held-out {self.metric} {self.ch_rms:.3f} nT"
        versus = f"the uncalibrated readings' {c.other_rms_nt:.3f} nT"
        if c.won:
            return self.decided(
                True,
                name,
                f"{said}: {head} beats {versus}{self.where} "
                f"(gain {100 * c.gain:.2f} %, p = {c.p_value:.2g} < {alpha:g})",
                c,
                identity=True,
            )
        how = (
            f"(gain {100 * c.gain:.2f} %, needs > {100 * margin:g} %)"
            if c.p_value is None
            else f"significantly (gain {100 * c.gain:.2f} %, p = {c.p_value:.2g} >= {alpha:g} "
            f"over {c.n_chunks} chunks)"
        )
        return self.decided(
            False,
            "identity",
            f"{head} does not beat {versus}{self.where} {how}: "
            "a calibration no better than none is not put in service",
            c,
            identity=True,
        )


def refuse_undetermined(
    challenger_sq_nt2: FloatArray,
    *,
    metric: str,
    why: str,
    rule: PromotionRule | None = None,
    identity_sq_nt2: FloatArray | None = None,
    implausible: bool = False,
) -> Promotion:
    """The refusal of a challenger the data cannot determine (:mod:`.determination`), or
    (``implausible``) one no magnetometer in nT can have (:mod:`orbitcal.plausibility`: gain,
    reflection, held-out error, elements of another spacecraft), with the uncalibrated
    readings' RMS on the same rows when given (for the record)."""
    rule = rule or PromotionRule()
    identity = None if identity_sq_nt2 is None else float(np.sqrt(np.mean(identity_sq_nt2)))
    ch_rms = float(np.sqrt(np.mean(challenger_sq_nt2)))
    versus = "" if identity is None else f" against the uncalibrated readings' {identity:.3f} nT"
    return Promotion(
        promote=False,
        rule="implausible" if implausible else "undetermined",
        reason=(
            "the calibration is implausible for a magnetometer in nT: "
            if implausible
            else "the data cannot determine a calibration: "
        )
        + f"{why}; held-out {metric} "
        f"{ch_rms:.3f} nT{versus}; it is not put in service",
        metric=metric,
        challenger_rms_nt=ch_rms,
        champion_rms_nt=None,
        gain=None,
        p_value=None,
        margin=rule.margin,
        alpha=rule.alpha,
        n_chunks=rule.n_chunks,
        identity_rms_nt=identity,
    )
