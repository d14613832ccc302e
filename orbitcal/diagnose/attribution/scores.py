"""What the attribution returns: :class:`Attribution`, its :class:`EffectScore` per effect and the
split-fit :class:`SplitFit`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.attribution.joint_fit import JointFit


@dataclass(frozen=True)
class EffectScore:
    """One candidate's verdict.

    Attributes
    ----------
    name : str
    significant : bool
        Selected by the greedy forward selection.
    holdout_rms_before_nt, holdout_rms_after_nt : float
        Held-out vector RMS without and with the effect [nT]. For a selected effect "before" is the
        model of the previous selection step; for the others it is the baseline.
    p_value : float
        One-sided Wilcoxon signed-rank test of the per-chunk log ratio of the held-out mean
        square.
    params : dict
        Fitted parameters (units in the names) and the model variant.
    unique_rms_increase_nt : float
        Drop-one: how much the held-out RMS grows when this effect alone is removed from the
        selected set [nT] (0 for effects not selected).
    step : int
        1-based selection step, 0 when not selected.
    implausible : str or None
        Why the candidate is ``implausible`` (it would only win with a parameter outside its
        physical range, or with parameters that contradict each other); None otherwise.
    intervals : dict
        90 % confidence interval ``[low, high]`` of every parameter (fit covariance, inflated for
        the autocorrelation of the training residual, clipped to the physical range).
    shrink_interval : (float, float) or None
        90 % interval of the held-out shrink (block bootstrap over the held-out chunks).
    absorbed_fraction : float or None
        Fraction of the fitted effect's field (training blocks, energy) that a change of the 12
        calibration parameters reproduces: near 1, the span cannot separate the effect from the
        calibration.
    """

    name: str
    significant: bool
    holdout_rms_before_nt: float
    holdout_rms_after_nt: float
    p_value: float
    params: dict[str, Any]
    unique_rms_increase_nt: float = 0.0
    step: int = 0
    implausible: str | None = None
    intervals: dict[str, list[float]] = field(default_factory=dict)
    shrink_interval: tuple[float, float] | None = None
    absorbed_fraction: float | None = None

    @property
    def shrink(self) -> float:
        """before / after on held-out data [-]."""
        return float(self.holdout_rms_before_nt / max(self.holdout_rms_after_nt, 1e-12))


@dataclass(frozen=True)
class SplitFit:
    """A split-fit test: the calibration fitted separately on two or more subsets.

    Attributes
    ----------
    name : str
        ``"sunlit_vs_eclipse"``, ``"attitude_regimes"`` or ``"time_blocks"``.
    labels : list of str
        Subset labels.
    offsets_nt : list of list of float
        Fitted offsets ``o`` per subset [nT].
    scales : list of list of float
        Diagonal of ``A`` per subset [-].
    max_offset_difference_nt : float
        Largest per-axis offset difference between subsets [nT].
    z : float
        That difference over its standard error (inflated for correlated residuals).
    flagged : bool
        The subsets disagree beyond ``z_threshold`` and ``min_difference_nt``.
    """

    name: str
    labels: list[str]
    offsets_nt: list[list[float]]
    scales: list[list[float]]
    max_offset_difference_nt: float
    z: float
    flagged: bool


@dataclass(frozen=True)
class Attribution:
    """Result of :func:`attribute`.

    Attributes
    ----------
    baseline_rms_nt : float
        Held-out vector RMS of the 12-parameter calibration alone [nT].
    baseline_train_rms_nt : float
        The same on the training blocks [nT].
    verdict : str
        The first selected effect, or ``"none"``.
    effects : list of EffectScore
        Ranked: selected effects in selection order, then the others by held-out shrink.
    selected : list of str
    final_rms_nt : float
        Held-out RMS of the calibration plus every selected effect [nT].
    train, holdout : ndarray of bool
    baseline_residual_nt, final_residual_nt : ndarray, shape (N, 3)
        Residuals of the baseline and of the final model at every sample [nT].
    split_fits : list of SplitFit
    fits : dict
        ``"baseline"`` and ``"final"`` JointFit objects.
    verdict_confidence : float or None
        Fraction of block-bootstrap resamples of the held-out chunks in which the verdict (or a
        model listed as indistinguishable from it) still wins the first selection step; None
        when the verdict came from a split fit or the regional test.
    implausible : dict
        Candidates reported ``implausible``, with the reason.
    has_prior : bool
        Whether a calibration prior held the 12 parameters.
    dropped : list of str
        Effects a forward step selected and the backward step removed again (each re-tested
        conditional on all the others no longer shrank the held-out residual significantly).
    span_s : float
        Time span of the data [s].
    fit_mask : ndarray of bool or None
        The samples every fit was restricted to (None: all), as given to :func:`attribute`.
    final_block_names : list of str or None
        The effect of every block of ``fits["final"]``, in order (None: not recorded).
    beside_final : dict of str to dict
        The candidates left out, each fitted beside the selected effects at the selection's
        last step: ``holdout_rms_nt`` (vector) and ``p_value`` of the held-out chunk test
        against the selected effects alone, the step's ``level``, whether it ``gains`` the
        minimum shrink, ``implausible`` (the reason, or None) and ``contained`` (for the
        closest few, the share of their field the selected effects take up beyond the
        calibration; else None). Empty when the selection's last step was not beside the
        effects finally selected.
    beside_final_of : list of str
        The selected effects the candidates of ``beside_final`` were fitted beside.
    """

    baseline_rms_nt: float
    baseline_train_rms_nt: float
    verdict: str
    effects: list[EffectScore]
    selected: list[str]
    final_rms_nt: float
    train: BoolArray
    holdout: BoolArray
    baseline_residual_nt: FloatArray
    final_residual_nt: FloatArray
    split_fits: list[SplitFit] = field(default_factory=list)
    fits: dict[str, JointFit] = field(default_factory=dict)
    verdict_confidence: float | None = None
    implausible: dict[str, str] = field(default_factory=dict)
    has_prior: bool = False
    span_s: float = 0.0
    dropped: list[str] = field(default_factory=list)
    fit_mask: BoolArray | None = None
    final_block_names: list[str] | None = None
    beside_final: dict[str, dict[str, Any]] = field(default_factory=dict)
    beside_final_of: list[str] = field(default_factory=list)


def _params(fit: JointFit, k: int) -> dict[str, Any]:
    bl = fit.blocks[k]
    out: dict[str, Any] = {n: float(v) for n, v in zip(bl.names, fit.coef[k], strict=True)}
    if bl.variant:
        out["variant"] = bl.variant
    return out
