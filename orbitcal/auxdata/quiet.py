"""Quiet-time selection: which samples fall in storm-time windows by Kp and Dst.

Swarm's vector calibration and the CHAOS models select geomagnetically quiet data (e.g. Kp ≤ 2o to
3o and Dst above about −30 nT, with |dDst/dt| small; Finlay et al. 2020, EPS 72:156, sec. 2.1).
:func:`storm_mask` applies configurable thresholds: a sample is storm-time when the Kp of its
3-hour interval exceeds ``kp_max`` or the Dst of its hour is below ``dst_min_nt``. Without an
installed Dst table the RC index (a Dst-like ring-current index from the same data, DTU) stands in
for Dst, and the result says so.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.auxdata.formats import ParsedTable
from orbitcal.auxdata.tables import active_table

__all__ = ["StormMask", "quiet_selection", "storm_mask"]


def _iso(t: float) -> str:
    return datetime.fromtimestamp(float(t), tz=UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


@dataclass
class StormMask:
    """Per-sample storm flags and the windows they form.

    Attributes
    ----------
    storm : ndarray of bool, shape (N,)
        True where Kp or Dst (or the RC stand-in) crosses its threshold.
    unknown : ndarray of bool, shape (N,)
        True where no index covers the sample (kept, and counted).
    windows : list of dict
        Contiguous storm-time runs: ``{"start", "end", "n", "kp_max", "dst_min_nt"}``.
    sources : dict
        Which table served each criterion (``kp``, ``dst``), or ``None``.
    """

    storm: BoolArray
    unknown: BoolArray
    windows: list[dict[str, Any]] = field(default_factory=list)
    sources: dict[str, str | None] = field(default_factory=dict)
    thresholds: dict[str, float | None] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """JSON-ready record of what was left out and why."""
        return {
            "thresholds": self.thresholds,
            "sources": self.sources,
            "n_storm": int(self.storm.sum()),
            "n_unknown": int(self.unknown.sum()),
            "n": int(self.storm.size),
            "windows": self.windows,
        }


def _step_lookup(
    t: FloatArray, starts: FloatArray, values: FloatArray, width_s: float
) -> FloatArray:
    """Value of the interval [start, start + width) holding each t; NaN outside every interval."""
    idx = np.searchsorted(starts, t, side="right") - 1
    ok = (idx >= 0) & (t < starts[np.clip(idx, 0, None)] + width_s)
    out = np.full(t.shape, np.nan)
    out[ok] = values[idx[ok]]
    return out


def _parsed(tables: dict[str, Any] | None, kind: str) -> tuple[ParsedTable | None, str | None]:
    if tables is not None and kind in tables:
        value = tables[kind]
        if value is None:
            return None, None
        parsed = value if isinstance(value, ParsedTable) else value.parsed
        return parsed, parsed.format
    if tables is not None:
        return None, None
    table = active_table(kind)
    if table is None:
        return None, None
    return table.parsed, f"{table.parsed.format} ({table.origin} {table.path.rsplit('/', 1)[-1]})"


def storm_mask(
    t_utc_s: npt.ArrayLike,
    *,
    kp_max: float | None = 3.0,
    dst_min_nt: float | None = -30.0,
    tables: dict[str, Any] | None = None,
) -> StormMask:
    """Flag storm-time samples by Kp and Dst thresholds.

    Parameters
    ----------
    t_utc_s : array_like, shape (N,)
        POSIX seconds of UTC [s].
    kp_max : float or None
        Samples whose 3-hour Kp exceeds this are storm-time (None: no Kp criterion).
    dst_min_nt : float or None
        Samples whose hourly Dst is below this [nT] are storm-time (None: no Dst criterion).
    tables : dict, optional
        ``{"kp": ..., "dst": ..., "rc_index": ...}`` as :class:`ParsedTable` or active tables
        (tests, or a caller's pinned copies); default the active tables. Given, only these are
        used.

    Returns
    -------
    StormMask
    """
    t = np.asarray(t_utc_s, dtype=np.float64).ravel()
    storm = np.zeros(t.shape, dtype=bool)
    known = np.zeros(t.shape, dtype=bool)
    sources: dict[str, str | None] = {"kp": None, "dst": None}
    if kp_max is not None:
        kp_t, src = _parsed(tables, "kp")
        if kp_t is not None:
            kp = _step_lookup(t, kp_t.data["t_start_utc_s"], kp_t.data["kp"], 3 * 3600.0)
            storm |= np.isfinite(kp) & (kp > kp_max)
            known |= np.isfinite(kp)
            sources["kp"] = src
    if dst_min_nt is not None:
        dst_t, src = _parsed(tables, "dst")
        if dst_t is not None:
            dst = _step_lookup(t, dst_t.data["t_start_utc_s"], dst_t.data["dst_nt"], 3600.0)
            sources["dst"] = src
        else:
            rc_t, src = _parsed(tables, "rc_index")
            dst = np.full(t.shape, np.nan)
            if rc_t is not None:
                mjd = (t - 946_684_800.0) / 86_400.0
                tm = rc_t.data["time_mjd2000"]
                inside = (mjd >= tm[0]) & (mjd <= tm[-1])
                rc = rc_t.data["rc_e_nt"] + rc_t.data["rc_i_nt"]
                dst[inside] = np.interp(mjd[inside], tm, rc)
                sources["dst"] = f"RC index as a Dst-like stand-in: {src}"
        storm |= np.isfinite(dst) & (dst < dst_min_nt)
        known |= np.isfinite(dst)
    windows: list[dict[str, Any]] = []
    if storm.any():
        order = np.argsort(t, kind="stable")
        s = storm[order]
        edges = np.flatnonzero(np.diff(np.concatenate([[0], s.astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            windows.append(
                {"start": _iso(t[order[a]]), "end": _iso(t[order[b - 1]]), "n": int(b - a)}
            )
    return StormMask(
        storm=storm,
        unknown=~known,
        windows=windows,
        sources=sources,
        thresholds={"kp_max": kp_max, "dst_min_nt": dst_min_nt},
    )


def quiet_selection(
    t_utc_s: npt.ArrayLike,
    *,
    kp_max: float | None,
    dst_min_nt: float | None,
    min_keep_fraction: float = 0.2,
) -> tuple[BoolArray, dict[str, Any] | None]:
    """Rows a retraining keeps under quiet-time selection, and the record of what it left out.

    Parameters
    ----------
    t_utc_s : array_like, shape (N,)
        Row times, POSIX seconds of UTC [s].
    kp_max, dst_min_nt : float or None
        Thresholds of :func:`storm_mask`; both None switches the selection off.
    min_keep_fraction : float
        When fewer rows than this share would remain (a retraining window inside a long storm),
        nothing is left out and the record says so: a storm-time fit beats no fit.

    Returns
    -------
    keep : ndarray of bool, shape (N,)
    record : dict or None
        None when the selection is off; else :meth:`StormMask.summary` plus ``"left_out"`` (rows)
        and ``"applied"`` (False when ``min_keep_fraction`` kept everything).
    """
    t = np.asarray(t_utc_s, dtype=np.float64).ravel()
    if kp_max is None and dst_min_nt is None:
        return np.ones(t.shape, dtype=bool), None
    mask = storm_mask(t, kp_max=kp_max, dst_min_nt=dst_min_nt)
    record = mask.summary()
    keep = ~mask.storm
    applied = bool(t.size == 0 or keep.mean() >= min_keep_fraction)
    if not applied:
        keep = np.ones(t.shape, dtype=bool)
    record["applied"] = applied
    record["left_out"] = int((~keep).sum())
    return keep, record
