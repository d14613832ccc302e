"""What the report may say of an effect's size: measured, or not separable from the calibration.

An effect most of whose fitted field is also a change of the 12 calibration parameters (its
``absorbed_by_calibration_fraction`` near 1) is not for that reason unmeasured: the rest of its
field, which no change of the calibration produces, can fix its size. The joint fit's interval
says whether it did (the fit carries the 12 parameters beside the effect's, so their
collinearity widens the interval). A time-tag error of a tumbling spacecraft had 99.6 % of its
field absorbed, yet dt = −0.498 s with a 90 % interval of −0.499 … −0.496 s and a held-out drop
from 16.0 to 2.08 nT: its size is measured, and the report says so.

The rule, one place for the report's JSON (:mod:`orbitcal.diagnose.report`,
:mod:`orbitcal.diagnose.honesty_report`) and its page (:mod:`orbitcal.diagnose.html_report`):
an effect's size is **measured** when it shrinks the held-out residual and at least one of its
parameters has a 90 % interval that does not reach the parameter's physical range, excludes zero
and is no wider than :data:`MEASURED_RELATIVE_HALF_WIDTH` of the value each side.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = [
    "MEASURED_RELATIVE_HALF_WIDTH",
    "measured_parameters",
    "resample_words",
    "size_measured",
]

#: Largest half-width of a 90 % interval relative to the parameter's value for a measured size.
MEASURED_RELATIVE_HALF_WIDTH = 0.5


def _number(x: Any) -> float | None:
    if isinstance(x, bool) or not isinstance(x, int | float):
        return None
    v = float(x)
    return v if math.isfinite(v) else None


def _touches(x: float, edge: float) -> bool:
    return math.isfinite(edge) and abs(x - edge) <= 1e-3 * max(abs(edge), 1.0)


def measured_parameters(
    effect: str,
    params: Mapping[str, Any],
    intervals: Mapping[str, Sequence[Any] | None],
    *,
    age_days: float | None = None,
) -> list[str]:
    """The parameters of ``effect`` whose 90 % interval measures them (see the module's rule),
    in the order of ``intervals``."""
    from orbitcal.diagnose.effects import effect_param_range

    out = []
    for name, iv in intervals.items():
        value = _number(params.get(name))
        if value is None or iv is None or len(iv) != 2:
            continue
        lo, hi = _number(iv[0]), _number(iv[1])
        if lo is None or hi is None or lo <= 0.0 <= hi:
            continue
        rng = effect_param_range(effect, name, age_days)
        if _touches(lo, rng.lower) or _touches(hi, rng.upper):
            continue
        if 0.5 * (hi - lo) > MEASURED_RELATIVE_HALF_WIDTH * abs(value):
            continue
        out.append(name)
    return out


def size_measured(entry: Mapping[str, Any], *, age_days: float | None = None) -> bool:
    """Whether the report's effect ``entry`` (its JSON) has a measured size: it shrinks the
    held-out residual and one of its parameters is measured."""
    before = _number(entry.get("holdout_rms_before_nt"))
    after = _number(entry.get("holdout_rms_after_nt"))
    if before is None or after is None or not after < before:
        return False
    return bool(
        measured_parameters(
            str(entry.get("name")),
            entry.get("params") or {},
            entry.get("param_intervals_90") or {},
            age_days=age_days,
        )
    )


def resample_words(share: float) -> str:
    """A verdict's resampling frequency (``verdict_confidence``) as a count of the block-bootstrap
    resamples of the held-out blocks in which it wins: a frequency, not a probability, so no
    percentage (``"every resample"``, ``"312 of 400 resamples"``)."""
    from orbitcal.diagnose.attribution.uncertainty import N_BOOTSTRAP

    wins = round(float(share) * N_BOOTSTRAP)
    if wins >= N_BOOTSTRAP:
        return "every resample"
    if wins <= 0:
        return "no resample"
    return f"{wins} of {N_BOOTSTRAP} resamples"
