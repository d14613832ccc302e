"""Which stored rows a retraining uses: the robust time window, usable rows, quiet time, and
gross outliers."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.calibrate import METHODS
from orbitcal.errors import NotEnoughDataError

__all__ = [
    "EXCLUSION_REASONS",
    "FUTURE_TOLERANCE_S",
    "OUTLIER_FRACTION",
    "OUTLIER_SIGMAS",
    "RowRules",
    "RowSelection",
    "TrainingRows",
    "Window",
    "describe_exclusions",
    "gross_outlier_free",
    "training_rows",
    "training_window",
    "usable_rows",
]

#: Samples dated later than this after "now" (the retraining's clock, never earlier than their
#: ingest) are in the future and never define a window [s].
FUTURE_TOLERANCE_S = 300.0


@dataclass(frozen=True)
class Window:
    """The time window a retraining (or a recent-data view) reads, and why.

    ``start_utc_s``/``end_utc_s`` are None when no sample qualifies. ``excluded`` counts the
    samples left out by reason (``"future"``: dated after now; ``"after_window"``: isolated samples
    later than the latest dense stretch).
    """

    start_utc_s: float | None
    end_utc_s: float | None
    n: int
    excluded: dict[str, int] = field(default_factory=dict)


def training_window(
    t_utc_s: NDArray[np.float64],
    *,
    window_s: float,
    min_samples: int,
    now_utc_s: float,
    future_tolerance_s: float = FUTURE_TOLERANCE_S,
) -> Window:
    """The window ``[end − window_s, end]`` a retraining fits, robust to outliers in time.

    The window ends at the latest sample time ``t`` at which ``(t − window_s, t]`` holds at least
    ``min_samples`` samples (the latest time with dense data) among the samples not in the
    future (``t ≤ now_utc_s + future_tolerance_s``). So one valid row dated 2149, or a few stray
    rows days after the rest, neither empty the window nor block retraining: they are counted in
    ``excluded``. When no window holds ``min_samples``, the one holding the most samples is
    returned (its ``n`` says how many).

    Parameters
    ----------
    t_utc_s : ndarray, shape (N,)
        Stored sample times, POSIX seconds of UTC [s], any order.
    window_s
        Window length [s].
    min_samples
        Samples a window needs to count as dense.
    now_utc_s
        The current time [s] (never earlier than the samples' ingest).
    future_tolerance_s
        Clock skew allowed before a sample counts as being in the future [s].
    """
    t = np.sort(np.asarray(t_utc_s, dtype=np.float64))
    limit = now_utc_s + future_tolerance_s
    n_future = int(t.size - np.searchsorted(t, limit, side="right"))
    t = t[: t.size - n_future]
    excluded = {"future": n_future} if n_future else {}
    if t.size == 0:
        return Window(None, None, 0, excluded)
    # samples in (t_i - window_s, t_i] for every candidate end t_i
    counts = np.arange(1, t.size + 1) - np.searchsorted(t, t - window_s, side="left")
    dense = np.flatnonzero(counts >= max(1, min_samples))
    i_end = int(dense[-1]) if dense.size else int(t.size - 1 - np.argmax(counts[::-1]))
    end = float(t[i_end])
    after = t.size - 1 - i_end
    if after:
        excluded["after_window"] = int(after)
    start = end - window_s
    return Window(start, end, int(counts[i_end]), excluded)


@dataclass(frozen=True)
class RowSelection:
    """Rows a fit may use (``mask``) and how many were left out, by reason."""

    mask: BoolArray
    excluded: dict[str, int]


def usable_rows(
    *,
    has_attitude: BoolArray,
    has_position: BoolArray,
    vector: bool,
    have_orbit: bool,
) -> RowSelection:
    """Rows usable for a fit: with attitude for vector methods, with a position without an orbit.

    Parameters
    ----------
    has_attitude, has_position : ndarray of bool, shape (N,)
        Whether each row carries all four quaternion components / all three position components.
    vector
        The method needs the body-frame reference (attitude).
    have_orbit
        A TLE/OMM gives positions for rows without their own.
    """
    mask = np.ones(has_attitude.shape, dtype=bool)
    excluded: dict[str, int] = {}
    if vector:
        n = int(np.count_nonzero(~has_attitude))
        if n:
            excluded["no_attitude"] = n
        mask &= has_attitude
    if not have_orbit:
        n = int(np.count_nonzero(mask & ~has_position))
        if n:
            excluded["no_position"] = n
        mask &= has_position
    return RowSelection(mask, excluded)


#: Why rows were left out of a retraining, in words (the keys of ``excluded`` counts).
EXCLUSION_REASONS: dict[str, str] = {
    "future": "dated in the future",
    "after_window": "isolated after the latest dense stretch of data",
    "quarantined": "quarantined",
    "no_attitude": "without attitude (q_w..q_z) for a vector method",
    "no_position": "without position (r_x..r_z) and no orbit set",
    "storm": "storm time (Kp or Dst beyond the quiet-time thresholds)",
    "outlier": "gross outliers (raw |B| far from the reference |B|)",
    "before_change": "before the change the health check found (orbitcal.health)",
}


def describe_exclusions(excluded: dict[str, int]) -> str:
    """``"3 dated in the future, 12 quarantined"``: the counts in words."""
    return ", ".join(f"{n} {EXCLUSION_REASONS.get(k, k)}" for k, n in excluded.items())


@dataclass(frozen=True)
class TrainingRows:
    """The rows of a window a retraining fits, and what it left out (counts by reason)."""

    mask: BoolArray
    excluded: dict[str, int]
    #: The quiet-time record (:func:`orbitcal.auxdata.quiet_selection`), None when off.
    quiet_time: dict[str, Any] | None

    def summary(self, *, extra: dict[str, int] | None = None) -> dict[str, Any]:
        """JSON-ready ``rows`` block of a job result: used, excluded (by reason, in words)."""
        excluded = {**self.excluded, **(extra or {})}
        return {
            "used": int(np.count_nonzero(self.mask)) - sum((extra or {}).values()),
            "excluded": excluded,
            "excluded_total": sum(excluded.values()),
            "reasons": {k: EXCLUSION_REASONS.get(k, k) for k in excluded},
            "quiet_time": self.quiet_time,
        }


@dataclass(frozen=True)
class RowRules:
    """What a retraining's rows must satisfy (:func:`training_rows`)."""

    #: The calibration method (vector methods need attitude).
    method: str
    #: Rows without positions take them from a TLE/OMM.
    have_orbit: bool
    #: Fewer usable rows fail the retraining.
    min_samples: int
    #: Quiet-time thresholds (:func:`orbitcal.auxdata.quiet_selection`) [-, nT]; None: off.
    quiet_kp_max: float | None = None
    quiet_dst_min_nt: float | None = None


def training_rows(
    window: Window,
    t_utc_s: NDArray[np.float64],
    *,
    has_attitude: BoolArray,
    has_position: BoolArray,
    rules: RowRules,
    spacecraft: str = "",
) -> TrainingRows:
    """Which rows of a window a retraining fits: :func:`usable_rows`, then quiet time.

    Parameters
    ----------
    window
        The window (:func:`training_window`), whose exclusions are carried over.
    t_utc_s, has_attitude, has_position : ndarray, shape (N,)
        The window's rows.
    rules
        Method, orbit, minimum count and quiet-time thresholds.
    spacecraft
        Named in the error.

    Raises
    ------
    NotEnoughDataError
        No usable window, or fewer than ``rules.min_samples`` usable rows; the message counts the
        rows left out and says why.
    """
    method, min_samples = rules.method, rules.min_samples
    quiet_kp_max, quiet_dst_min_nt = rules.quiet_kp_max, rules.quiet_dst_min_nt
    if window.end_utc_s is None:
        detail = f" ({describe_exclusions(window.excluded)})" if window.excluded else ""
        raise NotEnoughDataError(f"spacecraft {spacecraft} has no usable telemetry yet{detail}")
    rows = usable_rows(
        has_attitude=has_attitude,
        has_position=has_position,
        vector=METHODS[method].vector if method in METHODS else True,
        have_orbit=rules.have_orbit,
    )
    mask, excluded = rows.mask, {**window.excluded, **rows.excluded}
    quiet = None
    if quiet_kp_max is not None or quiet_dst_min_nt is not None:
        from orbitcal.auxdata import quiet_selection

        keep, quiet = quiet_selection(
            np.asarray(t_utc_s)[mask], kp_max=quiet_kp_max, dst_min_nt=quiet_dst_min_nt
        )
        if not keep.all():
            excluded["storm"] = int(np.count_nonzero(~keep))
            mask = mask.copy()
            mask[np.flatnonzero(mask)[~keep]] = False
    n = int(np.count_nonzero(mask))
    if n < min_samples:
        from orbitcal.timescales import utc_s_to_iso

        end = utc_s_to_iso([window.end_utc_s])[0]
        span = window.end_utc_s - (window.start_utc_s or window.end_utc_s)
        left_out = f"; left out: {describe_exclusions(excluded)}" if excluded else ""
        raise NotEnoughDataError(
            f"only {n} usable samples in the {span:g} s window ending {end}; "
            f"a retraining needs at least {min_samples}{left_out}"
        )
    return TrainingRows(mask, excluded, quiet)


#: A row whose raw field magnitude departs from the reference magnitude by more than this many
#: robust standard deviations (1.4826 × MAD) of that departure …
OUTLIER_SIGMAS = 10.0
#: … and by more than this fraction of the reference magnitude is no sensor state [-].
OUTLIER_FRACTION = 0.05


def gross_outlier_free(b_raw_nt: FloatArray, b_ref_mag_nt: FloatArray) -> BoolArray:
    """``(N,)`` bool: rows whose raw magnitude is a plausible sensor reading of the reference.

    ``d = ‖b_raw‖ − |B_ref|`` varies smoothly with a real sensor's gains and offsets (a few
    percent of the field); a row is a gross outlier when ``|d − median(d)|`` exceeds both
    ``OUTLIER_SIGMAS`` robust standard deviations and ``OUTLIER_FRACTION × |B_ref|`` — a
    telemetry glitch (a field three times too large, a bit flip), which a least-squares fit would
    otherwise follow (one such row in 3000 took a linear fit from 2 to 11 nT held out).
    """
    d = np.linalg.norm(np.asarray(b_raw_nt, dtype=np.float64), axis=1) - np.asarray(
        b_ref_mag_nt, dtype=np.float64
    )
    if d.size < 3:
        return np.ones(d.size, dtype=bool)
    dev = np.abs(d - np.median(d))
    sigma = 1.4826 * float(np.median(dev))
    out: BoolArray = ~(
        (dev > OUTLIER_SIGMAS * sigma) & (dev > OUTLIER_FRACTION * np.abs(b_ref_mag_nt))
    )
    return out
