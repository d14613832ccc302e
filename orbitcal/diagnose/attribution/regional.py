"""The regional test of field-aligned currents: localised at high magnetic latitude,
perpendicular to B, predicted leg by leg of each auroral crossing.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.diagnose.attribution.scores import EffectScore
from orbitcal.diagnose.design import AURORAL_MLAT_DEG, QUIET_MLAT_DEG
from orbitcal.diagnose.effects import (
    DiagnosisData,
)
from orbitcal.diagnose.event_design import FAC_CHUNK_S, FAC_FOLDS, fac_legs
from orbitcal.diagnose.noise import despiked
from orbitcal.metrics import norm_rms_nt

#: Chunk length [s] and folds of the regional test's cross-validation within auroral crossings.
FAC_CV_CHUNK_S = FAC_CHUNK_S
FAC_CV_FOLDS = FAC_FOLDS
#: Ridge of the regional test's per-leg fits, relative to the mean diagonal of their normal
#: matrix: a bump the fitting folds hardly reach stays bounded. On the real Swarm storm pass
#: (two legs, 137 and 549 s at 1 Hz) the unregularised fit predicted the held-out folds with
#: 2.5x the RMS of the currents themselves; with 1e-3 they shrink by a third (1e-6 to 1e-1 tried).
FAC_CV_RIDGE = 1e-3


def regional_fac(
    data: DiagnosisData, r_now: FloatArray, selected: Sequence[str]
) -> EffectScore | None:
    """Field-aligned currents when the held-out test cannot judge them.

    A single pass may cross the auroral oval only in its training part, or the currents change
    from crossing to crossing so that no model predicts the next one (the held-out test fails
    them even beside other effects it finds). ``r_now`` is the residual of the selected model
    (the calibration alone when nothing is selected). The regional test asks instead whether the
    residual is localised where field-aligned currents flow and shaped as they are: at
    |magnetic latitude| > 55 deg its RMS exceeds 3x that of quiet latitudes (< 50 deg), its part
    perpendicular to B exceeds 2x the part along B, and latitude bumps perpendicular to B, fitted
    to each leg of each crossing on four fifths of it (20 s chunks dealt round-robin), predict
    the remaining fifth with at least a quarter less RMS. Reported with ``judged_on`` saying so.
    """
    if "field_aligned_currents" in selected:
        return None
    # Spikes are not currents: 0.5 % of the samples hit by 300 nT made 3-8 nT sheets pass
    # (independent world 13700 no. 33).
    r_now = despiked(r_now, data.t_utc_s)
    amlat = np.abs(data.mlat_deg)
    hi = amlat > AURORAL_MLAT_DEG
    lo = amlat < QUIET_MLAT_DEG
    if int(hi.sum()) < 30 or int(lo.sum()) < 30:
        return None
    from orbitcal.diagnose.design import FAC_CENTRES_DEG, _fac_bumps

    # Both directions perpendicular to B, latitude bumps as the catalogue model, fitted to each
    # leg of each crossing on its own (poleward or equatorward of its highest latitude): the
    # currents' strength changes from crossing to crossing and their sign from dawn to dusk, so
    # one set of coefficients for every crossing would predict none. Cross-validated within
    # each leg: consecutive FAC_CV_CHUNK_S chunks are dealt round-robin to FAC_CV_FOLDS folds;
    # the bumps fitted on the other folds predict each fold.
    idx = np.flatnonzero(hi)
    b_hat = data.b_hat_body
    par = np.sum(r_now * b_hat, axis=1)
    perp = r_now - par[:, None] * b_hat
    rms_hi = norm_rms_nt(r_now[hi])
    rms_lo = norm_rms_nt(r_now[lo])
    perp_hi = norm_rms_nt(perp[hi])
    par_hi = float(np.sqrt(np.mean(par[hi] ** 2)))
    pred = np.zeros((data.n, 3))
    for leg in fac_legs(data.t_utc_s, amlat, idx):
        bumps = _fac_bumps(amlat[leg], 1.0, FAC_CENTRES_DEG)
        bumps = bumps[:, bumps.max(axis=0) >= 0.05]
        if bumps.shape[1] == 0:
            continue
        transverse = data.transverse_body[leg]
        g = np.empty((leg.size, 3, 2 * bumps.shape[1]))
        for j in range(bumps.shape[1]):
            for k in range(2):
                np.multiply(transverse[:, k, :], bumps[:, j, None], out=g[:, :, 2 * j + k])
        chunk = ((data.t_utc_s[leg] - data.t_utc_s[leg[0]]) // FAC_CV_CHUNK_S).astype(int)
        fold = chunk % FAC_CV_FOLDS
        r_leg = r_now[leg]
        for f in range(FAC_CV_FOLDS):
            test_rows = fold == f
            fit_rows = ~test_rows
            if not np.any(test_rows) or not np.any(fit_rows):
                continue
            x = g[fit_rows].reshape(-1, g.shape[2])
            gram = x.T @ x
            ridge = FAC_CV_RIDGE * np.trace(gram) / gram.shape[0]
            coef = np.linalg.solve(
                gram + ridge * np.eye(gram.shape[0]), x.T @ r_leg[fit_rows].reshape(-1)
            )
            pred[leg[test_rows]] = g[test_rows] @ coef
    pred = pred[idx]
    rms_after = norm_rms_nt(r_now[hi] - pred)
    significant = bool(
        rms_hi > 3.0 * rms_lo and perp_hi > 2.0 * par_hi and rms_after < 0.75 * rms_hi
    )
    params: dict[str, Any] = {
        "judged_on": f"|magnetic latitude| > {AURORAL_MLAT_DEG:.0f} deg, each leg of each crossing "
        f"fitted alone, cross-validated within it ({FAC_CV_FOLDS} folds of {FAC_CV_CHUNK_S:.0f} s "
        "chunks): the held-out "
        "blocks cannot judge currents that change from crossing to crossing or lie outside them",
        "rms_high_latitude_nt": rms_hi,
        "rms_quiet_latitude_nt": rms_lo,
        "perpendicular_rms_high_latitude_nt": perp_hi,
        "parallel_rms_high_latitude_nt": par_hi,
    }
    return EffectScore(
        "field_aligned_currents", significant, rms_hi, rms_after, float("nan"), params
    )
