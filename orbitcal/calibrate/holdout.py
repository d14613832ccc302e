"""Held-out data are later time blocks (docs/design.md): fit on the earlier part, score on the rest.

Random rows would leak slowly varying effects (temperature, drifts, orbit-periodic fields) between
the fit and the score.

**The held-out RMS, defined once** (a calibration document's ``metrics.holdout_rms_nt``, what
``orbitcal calibrate`` prints, the service's versions and dashboard): the calibration is fitted
on the earlier samples of the table (after the service's row selection: window, quarantine,
quiet time, gross outliers) and scored on the latest :data:`HOLDOUT_FRACTION` of them in time
(:func:`later_block_split`) with :func:`orbitcal.metrics.rms_nt` (the N × 3 RMS of CONTRACT
"Definitions"; scalar methods: ``scalar_rms_nt``). Every surface holds out this share unless told
otherwise, so the same table and method give the same number everywhere; a surface that holds
out otherwise (the diagnosis: its last 3 of 10 equal-duration blocks) names its figure as its own.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from orbitcal.errors import BadInputError

__all__ = ["HOLDOUT_FRACTION", "later_block_split", "rms_nt"]

#: The share of the latest samples held out by default on every surface (CLI, library, service).
HOLDOUT_FRACTION = 0.25


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
