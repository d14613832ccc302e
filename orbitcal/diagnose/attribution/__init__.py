"""Attribution: which effect explains the calibrated residual, judged on held-out later blocks.

Every candidate of the catalogue (:mod:`orbitcal.diagnose.effects`) is fitted *jointly* with the
12-parameter calibration (``b_raw = A b_ref + o + G c``) on the training time blocks and judged by
how much it shrinks the residual on the later, held-out blocks that no fit saw (``docs/design.md``:
held-out data are always later time blocks, never random rows).

Stepwise selection (:class:`Selection`, :func:`attribute`). A *forward step* adds the candidate
with the lowest held-out RMS among those that beat the current model *significantly*: the held-out
span (or, for a localised effect, the part where it acts) is cut into consecutive chunks, the
per-chunk log ratio of the mean squared residual is tested with a one-sided Wilcoxon signed-rank
test (Bonferroni over the candidates of the step), and the RMS -- or the geometric mean of the
per-chunk RMS -- must shrink by at least ``min_gain``. Candidates the held-out chunks cannot tell
from the best are tied and the training BIC names one (the others within 10 of its BIC are listed
as indistinguishable from it). When no single candidate passes, a *pair* that passes together
(each significant on top of the other) may be added. A *swap* pass then chooses every selected
effect again given all the others, and a *backward* step re-tests each conditional on all the
others and drops the weakest that fails; forward steps resume without it. A candidate whose fit
leaves its physical range at one step (``implausible``) is tried again at the next. When nothing
passes, no effect is named (verdict ``"none"``). The selected set is then scored step by step
(joint refits) and drop-one (each effect's unique contribution).

Split-fit tests expose effects the 12 parameters absorb so that the residual alone hides them:
the calibration is fitted separately on sunlit and eclipse samples, on attitude regimes and on
consecutive time blocks, and the biases and scale factors are compared against their uncertainty.

All fits are iteratively reweighted least squares (Huber, then Tukey's bisquare; sigma from the
median absolute deviation), so a localised disturbance such as an auroral crossing cannot drag the
calibration of the rest of the orbit.

The package, by concept: :mod:`.joint_fit` (the joint fit, time blocks, variants by training
BIC), :mod:`.significance` (the held-out chunk test), :mod:`.uncertainty` (intervals, shrink
intervals, verdict confidence, absorbed fractions), :mod:`.selection` (one candidate beside the
selected effects, ties, near twins, the backward step), :mod:`.groups` (pairs and triples),
:mod:`.stepwise` (forward, swap, backward, release), :mod:`.regional` (the currents' regional
test), :mod:`.split_fits` (split-fit tests) and :mod:`.engine` (:func:`attribute`, the driver).
"""

from __future__ import annotations

from orbitcal.diagnose.attribution.engine import attribute
from orbitcal.diagnose.attribution.groups import GroupSelection
from orbitcal.diagnose.attribution.joint_fit import JointFit, fit_joint, time_blocks
from orbitcal.diagnose.attribution.regional import fac_legs
from orbitcal.diagnose.attribution.scores import Attribution, EffectScore, SplitFit
from orbitcal.diagnose.attribution.selection import Candidate, Selection
from orbitcal.diagnose.attribution.split_fits import split_fit_tests
from orbitcal.diagnose.options import HOLDOUT_BLOCKS, N_BLOCKS

__all__ = [
    "HOLDOUT_BLOCKS",
    "N_BLOCKS",
    "Attribution",
    "Candidate",
    "EffectScore",
    "GroupSelection",
    "JointFit",
    "Selection",
    "SplitFit",
    "attribute",
    "fac_legs",
    "fit_joint",
    "split_fit_tests",
    "time_blocks",
]
