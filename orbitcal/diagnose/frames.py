"""The diagnosis report as pandas DataFrames (:meth:`orbitcal.diagnose.Report.to_frame`).

``effects_frame``: one row per candidate, indexed by its catalogue name. ``time_frame``: the
residual's RMS per time bin before and after the selected effects, indexed by the bin's UTC time
(the report's ``evidence`` curve whose driver is time), as every other ``to_frame`` of orbitcal
is indexed by time.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["effects_frame", "time_frame"]

_EFFECT_COLUMNS = (
    ("status", "status"),
    ("significant", "significant"),
    ("holdout_rms_before_nt", "holdout_rms_before_nt"),
    ("holdout_rms_after_nt", "holdout_rms_after_nt"),
    ("shrink", "shrink"),
    ("p_value", "p_value"),
    ("probability", "probability"),
    ("absorbed_by_calibration_fraction", "absorbed_by_calibration_fraction"),
)


def effects_frame(report: Mapping[str, Any]) -> pd.DataFrame:
    """One row per candidate, ranked, indexed by ``effect``: status, ``significant``, held-out
    RMS before and after [nT], shrink, p-value, ``probability`` (when the report has it) and the
    share of its field the calibration absorbs."""
    import pandas as pd

    rows = [e for e in report.get("effects") or [] if isinstance(e, Mapping)]
    data = {
        column: [e.get(key) for e in rows]
        for key, column in _EFFECT_COLUMNS
        if any(key in e for e in rows)
    }
    index = pd.Index([str(e.get("name")) for e in rows], name="effect")
    return pd.DataFrame(data, index=index)


def time_frame(report: Mapping[str, Any]) -> pd.DataFrame:
    """The residual's RMS per time bin [nT] (``rms_before_nt``: the calibration alone,
    ``rms_after_nt``: with the selected effects), ``n`` samples and ``held_out``, indexed by the
    bin's centre in UTC time. Empty (with those columns) when the report has no time curve."""
    import pandas as pd

    from orbitcal.notebook import time_index
    from orbitcal.timescales import iso_to_utc_s

    curve = next(
        (
            c
            for c in report.get("evidence") or []
            if isinstance(c, Mapping) and c.get("driver") == "time_h"
        ),
        None,
    )
    start = (report.get("data") or {}).get("start")
    if curve is None or not isinstance(start, str):
        return pd.DataFrame(
            {"rms_before_nt": [], "rms_after_nt": [], "n": [], "held_out": []},
            index=time_index(np.zeros(0)),
        )
    hours = np.asarray(curve.get("x") or [], dtype=float)
    t0 = float(iso_to_utc_s([start])[0])
    held = curve.get("held_out_from")
    return pd.DataFrame(
        {
            "rms_before_nt": np.asarray(curve.get("rms_before_nt"), dtype=float),
            "rms_after_nt": np.asarray(curve.get("rms_after_nt"), dtype=float),
            "n": np.asarray(curve.get("n"), dtype=int),
            "held_out": hours >= float(held) if isinstance(held, int | float) else False,
        },
        index=time_index(t0 + 3600.0 * hours),
    )
