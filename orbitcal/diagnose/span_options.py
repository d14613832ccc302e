"""Attribution options chosen from the data itself (issue 25: the path users take is the path
tested).

Two choices that a short storm pass needs and a user running ``orbitcal diagnose`` with its
defaults cannot be expected to make:

* **Fitting on quiet magnetic latitudes.** When the residual of the calibration fitted on the
  quiet latitudes of the training blocks is more than 3x larger at |magnetic latitude| > 55 deg
  than below 50 deg (a disturbance at auroral latitudes, whatever its shape), every fit -- the
  12 parameters included -- uses only samples at |magnetic latitude| < 50 deg, as Swarm
  processing does. A crossing's hundreds of nT would otherwise drag the 12 parameters, and the
  baseline's held-out residual at low latitude would be the currents' imprint on the calibration
  rather than anything the data hold there.
* **Two held-out blocks of ten on a span shorter than an orbit.** Three of ten (30 %) leave the
  training blocks without a whole revolution's geometry on a 30-minute pass; two (20 %) keep the
  held-out span long enough for the chunked significance test while the fits see more of the
  orbit.

Both apply to spans shorter than an orbit only: on longer spans the attribution's own quiet-
latitude selection (judged on quiet latitudes, reported on all) already keeps the currents out of
the other effects' tests, and the project's benchmarks there are unchanged. Options the caller
passes explicitly are never overridden.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from orbitcal.diagnose.data import ORBIT_S

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.diagnose.effects import DiagnosisData

__all__ = ["ORBIT_S", "QUIET_MLAT_DEG", "SHORT_SPAN_HOLDOUT_BLOCKS", "choose_options"]

#: Held-out blocks (of :data:`orbitcal.diagnose.attribution.N_BLOCKS`) on a short span.
SHORT_SPAN_HOLDOUT_BLOCKS = 2
#: Fits use |magnetic latitude| below this when auroral currents are found [deg].
QUIET_MLAT_DEG = 50.0
#: Auroral latitudes, and how much larger the residual must be there than at quiet ones [deg, -].
AURORAL_MLAT_DEG = 55.0
AURORAL_EXCESS = 3.0
#: Least number of quiet training samples for a quiet-latitude fit.
MIN_QUIET_TRAIN = 200


def choose_options(data: DiagnosisData, given: dict[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """Options for :func:`orbitcal.diagnose.attribution.attribute` chosen from ``data``.

    Returns the options (``given`` updated; a key in ``given`` wins) and one sentence per choice
    made, for the report.
    """
    from orbitcal.diagnose.attribution import HOLDOUT_BLOCKS, N_BLOCKS, fit_joint, time_blocks
    from orbitcal.metrics import norm_rms_nt

    out = dict(given)
    why: list[str] = []
    span_s = float(data.t_utc_s[-1] - data.t_utc_s[0]) if data.n else 0.0
    if "holdout_blocks" not in given and 0.0 < span_s < ORBIT_S:
        out["holdout_blocks"] = SHORT_SPAN_HOLDOUT_BLOCKS
        why.append(
            f"span {span_s / 60.0:.0f} min, shorter than an orbit: the last "
            f"{SHORT_SPAN_HOLDOUT_BLOCKS} of {N_BLOCKS} time blocks are held out (not "
            f"{HOLDOUT_BLOCKS}), so the fits see more of the orbit"
        )
    if "fit_mask" not in given and 0.0 < span_s < ORBIT_S:
        train, _, _ = time_blocks(
            data.t_utc_s,
            n_blocks=int(out.get("n_blocks", N_BLOCKS)),
            holdout_blocks=int(out.get("holdout_blocks", HOLDOUT_BLOCKS)),
        )
        quiet = np.abs(data.mlat_deg) < QUIET_MLAT_DEG
        if int(train.sum()) >= 30 and int((train & quiet).sum()) >= MIN_QUIET_TRAIN:
            # The calibration fitted on quiet latitudes: one fitted on all would be dragged by
            # the crossings and leave a residual everywhere, hiding where it comes from.
            base = fit_joint(data, train & quiet)
            r_base = data.b_raw_nt - base.predict_nt(data)
            high = np.abs(data.mlat_deg) > AURORAL_MLAT_DEG
            if int(high.sum()) >= 30:
                rms_high = norm_rms_nt(r_base[high])
                rms_quiet = norm_rms_nt(r_base[quiet])
                if rms_high > AURORAL_EXCESS * rms_quiet:
                    out["fit_mask"] = quiet
                    why.append(
                        "a disturbance at auroral latitudes: the calibration fitted on quiet "
                        f"latitudes leaves {rms_high:.0f} nT (norm rms) at |magnetic latitude| > "
                        f"{AURORAL_MLAT_DEG:.0f} deg against {rms_quiet:.0f} nT below "
                        f"{QUIET_MLAT_DEG:.0f} deg: every fit uses |magnetic latitude| < "
                        f"{QUIET_MLAT_DEG:.0f} deg only"
                    )
    return out, why
