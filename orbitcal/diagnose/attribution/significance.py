"""The held-out chunk test: consecutive chunks of the held-out span, a one-sided Wilcoxon
signed-rank test of the per-chunk log ratio of the mean squared residual, and the support of a
localised effect.
"""

from __future__ import annotations

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.attribution.joint_fit import JointFit
from orbitcal.diagnose.signed_rank import signed_rank_greater_p


def _chunk_test(r_before: FloatArray, r_after: FloatArray, n_chunks: int) -> tuple[float, float]:
    """One-sided test that the held-out squared residual drops; returns (p, mean log ratio).

    The held-out samples (those in the candidate's support) are cut into ``n_chunks`` consecutive
    chunks; in each, ``log(mean |r_before|^2 / mean |r_after|^2)`` is taken, and a one-sided
    Wilcoxon signed-rank test asks whether these are centred above zero. Chunks span several
    correlation times, so they are close to independent; the log ratio and the rank test keep
    chunks of very different disturbance level (a patchy crust, auroral crossings) comparable.
    """
    e_b = np.sum(r_before**2, axis=1)
    e_a = np.sum(r_after**2, axis=1)
    chunks = [c for c in np.array_split(np.arange(e_b.size), n_chunks) if c.size]
    d = np.array(
        [np.log(max(np.mean(e_b[c]), 1e-300) / max(np.mean(e_a[c]), 1e-300)) for c in chunks]
    )
    if d.size < 5:
        return 1.0, float(np.mean(d)) if d.size else 0.0
    mean = float(np.mean(d))
    if np.all(d == 0.0):
        return 1.0, mean
    return signed_rank_greater_p(d), mean


#: Fewest chunks (of >= 3 samples) a localised effect's support is tested on.
MIN_LOCAL_CHUNKS = 8


def _support(
    fit: JointFit,
    train: BoolArray,
    holdout: BoolArray,
    n_chunks: int,
    n_chunks_local: int,
    *,
    k: int = -1,
) -> tuple[BoolArray, int]:
    """Held-out samples where the candidate's fitted field matters (> 10 % of its training peak).

    Block ``k`` of the fit (default the last). Localised effects (field-aligned currents, a
    patchy crust) are tested where they act; the
    support depends on positions and the training fit only, never on held-out residuals. Returns
    the support and the number of chunks to cut it into (``n_chunks_local`` when it covers less
    than half of the held-out samples).
    """
    mag = np.linalg.norm(fit.effect_nt(k % len(fit.blocks)), axis=1)
    peak = float(np.percentile(mag[train], 99)) if np.any(train) else 0.0
    sup = holdout & (mag > 0.1 * peak)
    n_sup = int(sup.sum())
    if n_sup < 3 * n_chunks_local:
        # A support too small for n_chunks_local chunks of 3 samples is still tested where the
        # effect acts when it holds 8 such chunks (diluted over the whole held-out span, a
        # field confined to one crossing would pass or fail by a sample or two).
        if n_sup >= 3 * MIN_LOCAL_CHUNKS:
            return sup, n_sup // 3
        return holdout, n_chunks
    if int(sup.sum()) > 0.5 * int(holdout.sum()):
        return sup, n_chunks
    # An effect confined to less than half of the held-out span (a few auroral crossings) is
    # tested on fewer, longer chunks, each spanning whole parts of a crossing.
    return sup, n_chunks_local
