"""Can the data determine a calibration? The rank and condition of the raw readings.

Every method fits at least the 12 linear parameters of ``b_cal = M (b_raw − o)``: per output axis
a regression on ``[b_raw, 1]``, which has full rank only when the raw readings vary in all three
directions. A stuck sensor (every sample the same), a sensor with a dead axis, or readings that lie
on a line or a plane leave ``M`` undetermined: least squares still returns *a* solution (the
minimum-norm one), but it is fixed by the solver, not the data, and on other data it can be
worse than no calibration at all (issue 24: 400 identical samples gave 1,072,798 nT held out
against 29,936 nT uncalibrated). Such a fit is refused before it can serve.
"""

from __future__ import annotations

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.errors import NotEnoughDataError

__all__ = ["MAX_CONDITION", "MIN_SPREAD_FRACTION", "UndeterminedError", "undetermined_reason"]

#: Readings whose principal spreads differ by more than this factor (largest / smallest) leave
#: one direction numerically undetermined [-]. A nadir-pointing LEO spacecraft's field varies
#: by tens of per cent in its least-varying body axis over an orbit (condition ~10–100).
MAX_CONDITION = 1e6
#: Readings whose largest RMS spread about their mean is below this fraction of their RMS
#: magnitude do not vary at all (a stuck sensor) [-].
MIN_SPREAD_FRACTION = 1e-9


class UndeterminedError(NotEnoughDataError):
    """The raw readings cannot determine a calibration (no variation, or not in 3 directions);
    collect data over more of the orbit, or check the sensor (exit 3, HTTP 422)."""


def undetermined_reason(b_raw_nt: FloatArray) -> str | None:
    """Why the raw readings ``(N, 3)`` [nT, sensor axes] cannot determine a linear calibration,
    or None when they can.

    The readings determine ``M`` and ``o`` when ``N ≥ 4`` and their centred values span three
    directions: the singular values ``s₁ ≥ s₂ ≥ s₃`` of ``b_raw − mean(b_raw)`` must satisfy
    ``s₁/√N > MIN_SPREAD_FRACTION · rms(‖b_raw‖)`` (they vary) and ``s₁/s₃ ≤ MAX_CONDITION``
    (in every direction).
    """
    b = np.asarray(b_raw_nt, dtype=np.float64)
    n = int(b.shape[0])
    if n < 4:
        return f"{n} samples cannot determine the 12 linear parameters; at least 4 are needed"
    centred = b - b.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)
    level_nt = float(np.sqrt(np.mean(np.sum(b**2, axis=1))))
    spread_nt = s / np.sqrt(n)
    if not spread_nt[0] > MIN_SPREAD_FRACTION * max(level_nt, 1.0):
        return (
            f"the {n} raw readings do not vary (spread {spread_nt[0]:.3g} nT about "
            f"{level_nt:.6g} nT): a stuck sensor or a constant field"
        )
    condition = float(s[0] / s[2]) if s[2] > 0 else float("inf")
    if not condition <= MAX_CONDITION:
        n_dirs = int(np.count_nonzero(s > s[0] / MAX_CONDITION))
        spreads = ", ".join(f"{v:.3g}" for v in spread_nt)
        return (
            f"the raw readings vary in only {n_dirs} of 3 directions (condition number "
            f"{condition:.3g} > {MAX_CONDITION:g}; spreads {spreads} nT): an axis is dead or "
            "the field did not rotate enough"
        )
    return None
