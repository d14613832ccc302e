"""Held-out data are later time blocks (docs/design.md): fit on the earlier part, score on the rest.

Random rows would leak slowly varying effects (temperature, drifts, orbit-periodic fields) between
the fit and the score.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from orbitcal.errors import BadInputError

__all__ = ["later_block_split", "rms_nt"]


def later_block_split(
    t_utc_s: NDArray[np.float64], holdout_fraction: float
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Boolean masks ``(train, holdout)``: the last ``holdout_fraction`` of samples in time.

    Parameters
    ----------
    t_utc_s
        Sample times ``(N,)`` [s]; need not be sorted.
    holdout_fraction
        In ``[0, 1)``; 0 gives an empty hold-out.

    Raises
    ------
    ValueError
        If ``holdout_fraction`` is outside ``[0, 1)``.
    """
    if not 0.0 <= holdout_fraction < 1.0:
        raise BadInputError(f"holdout_fraction must be in [0, 1), got {holdout_fraction}")
    t = np.asarray(t_utc_s, dtype=np.float64)
    n = t.size
    n_hold = round(holdout_fraction * n)
    holdout = np.zeros(n, dtype=bool)
    if n_hold:
        order = np.argsort(t, kind="stable")
        holdout[order[n - n_hold :]] = True
    return ~holdout, holdout


def rms_nt(residual_nt: NDArray[np.float64]) -> float:
    """Root mean square over all samples and components [nT] (:func:`orbitcal.metrics.rms_nt`)."""
    from orbitcal.metrics import rms_nt as rms

    return rms(residual_nt)
