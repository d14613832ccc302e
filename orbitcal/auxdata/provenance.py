"""Which tables a result used, until when they hold, and whether the data lie past their end.

The reference field model's own validity is :func:`orbitcal.field.reference_field_provenance`;
:func:`orbitcal.provenance.result_provenance` joins the two (auxdata sits below the field models:
``orbitcal.field`` reads the RC index from here, never the reverse).
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

import numpy as np
import numpy.typing as npt

from orbitcal.auxdata.tables import active_table

__all__ = ["table_status", "tables_provenance"]


def _iso(t: float | None) -> str | None:
    if t is None or not np.isfinite(t):
        return None
    return datetime.fromtimestamp(float(t), tz=UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def table_status(kind: str, t_start_utc_s: float, t_end_utc_s: float) -> dict[str, Any]:
    """The active table of ``kind`` described, with a ``status`` for the span [start, end].

    ``status``: ``leap_seconds`` → ``valid`` | ``past_expiry``; ``eop`` → ``observed`` |
    ``predicted`` | ``past_end`` (UT1 − UTC extrapolated); ``rc_index``, ``kp``, ``dst`` →
    ``covered`` | ``past_end`` | ``before_start``; every kind → ``not_installed`` without a table.
    """
    table = active_table(kind)
    if table is None:
        return {"status": "not_installed"}
    p = table.parsed
    out = table.describe()
    if kind == "leap_seconds":
        out["status"] = "valid" if t_end_utc_s <= p.valid_until_utc_s else "past_expiry"
    elif kind == "eop":
        if t_end_utc_s > p.coverage_end_utc_s:
            out["status"] = "past_end"
        elif p.predictions_from_utc_s is not None and t_end_utc_s >= p.predictions_from_utc_s:
            out["status"] = "predicted"
        else:
            out["status"] = "observed"
        has_pm = bool(np.any(np.isfinite(p.data["x_arcsec"])))
        out["polar_motion"] = "from the table" if has_pm else "zero (not in the table)"
    elif t_start_utc_s < p.coverage_start_utc_s:
        out["status"] = "before_start"
    else:
        out["status"] = "covered" if t_end_utc_s <= p.coverage_end_utc_s else "past_end"
    return out


def tables_provenance(
    t_utc_s: npt.ArrayLike,
    *,
    kinds: tuple[str, ...] = ("leap_seconds", "eop", "rc_index"),
    rc_index_used: bool | None = None,
    external_field_variant: str | None = None,
) -> dict[str, Any]:
    """The provenance block of a result over the sample times ``t_utc_s``.

    Returns
    -------
    dict
        ``{"span": {"start", "end"}, "tables": {kind: {file, origin,
        source, retrieved_at, sha256, coverage_end, valid_until, status, ...}},
        "warnings": [...]}``;
        ``warnings`` names every table the span runs past (never silently).
    """
    t = np.asarray(t_utc_s, dtype=np.float64).ravel()
    t = t[np.isfinite(t)]
    start = float(t.min()) if t.size else float("nan")
    end = float(t.max()) if t.size else float("nan")
    tables: dict[str, Any] = {}
    warnings: list[str] = []
    for kind in kinds:
        entry = table_status(kind, start, end)
        tables[kind] = entry
        st = entry["status"]
        if kind == "leap_seconds" and st == "past_expiry":
            warnings.append(
                f"data run past the leap-second table's expiry ({entry['valid_until']}): "
                "TAI - UTC after it is assumed unchanged; run 'orbitcal data update'"
            )
        elif kind == "eop" and st == "predicted":
            warnings.append(
                f"UT1 - UTC is a prediction from {entry['predictions_from']} on (no observed EOP "
                "yet for these dates)"
            )
        elif kind == "eop" and st == "past_end":
            warnings.append(
                f"data run past the EOP table ({entry['coverage_end']}): UT1 - UTC is "
                "extrapolated; run 'orbitcal data update'"
            )
        elif kind == "rc_index" and st in ("past_end", "before_start"):
            warnings.append(
                f"data lie outside the RC index ({entry.get('coverage_start')} to "
                f"{entry['coverage_end']}): the RC-driven external field was not used"
            )
        if kind == "eop" and entry.get("polar_motion", "").startswith("zero"):
            warnings.append("polar motion taken as zero: the EOP table in use has none")
    if "rc_index" in tables:
        if rc_index_used is not None:
            tables["rc_index"]["used"] = bool(rc_index_used)
        if external_field_variant is not None:
            tables["rc_index"]["external_field_variant"] = external_field_variant
    out: dict[str, Any] = {
        "span": {"start": _iso(start), "end": _iso(end)},
        "tables": tables,
        "warnings": warnings,
    }
    return out
