"""Designs of effects whose amplitudes change from event to event (the catalogue's side of
:mod:`orbitcal.diagnose.model.within_event`).

An auroral crossing's field-aligned currents change in strength from crossing to crossing and
in sign from dawn to dusk: no set of coefficients fitted on the training span forecasts the next
crossing, so neither a forecast on the final block nor orbit-long cross-validation can confirm
them. Their *form* can be confirmed instead: each event's own amplitudes, fitted on part of the
event, predict the rest of it. An :class:`EventDesign` gives, for the samples of a block, each
event's samples and columns, and how an event is cut for that within-event prediction.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from orbitcal.arrays import FloatArray, IntArray
from orbitcal.diagnose.data import DiagnosisData

__all__ = ["FAC_EVENTS", "Event", "EventDesign", "fac_events", "fac_legs"]

#: Chunk length [s] and folds of the within-event prediction of the auroral currents: a chunk
#: about a latitude bump's crossing time (1.5 deg at 7.6 km/s: ~22 s), five folds (the rules
#: engine's regional test, :mod:`orbitcal.diagnose.attribution.regional`, cuts the same way).
FAC_CHUNK_S = 20.0
FAC_FOLDS = 5
#: The least RMS per component [nT] of the large-scale field-aligned currents' field over the
#: auroral samples (|magnetic latitude| > 55 deg): the region-1/2 systems peak at 100-500 nT at
#: LEO (Iijima & Potemra 1976; ``docs/diagnosis_priors.md``), a sheet a few degrees wide in a
#: band of ~30 degrees of latitude and across one of three components: ~10 nT at least; half
#: that leaves a factor two for a weaker or narrower system. A sheet of a few nT (RMS ~1 nT) is
#: small-scale structure, not the system the catalogue's effect is.
FAC_MATERIAL_NT = 5.0


@dataclass(frozen=True)
class Event:
    """One event of an :class:`EventDesign` on a block of samples.

    Attributes
    ----------
    rows : ndarray of int
        Its samples, as positions in the block's sample index.
    columns : ndarray, shape (len(rows), 3, k)
        Its regressors in the body frame [nT per unit amplitude].
    names : list of str
        Its amplitudes' names (their prior is the effect's ``param_ranges``).
    """

    rows: IntArray
    columns: FloatArray
    names: list[str]


@dataclass(frozen=True)
class EventDesign:
    """How an effect's events are found and cut.

    Attributes
    ----------
    events : callable
        ``events(data, index) -> list[Event]``: the events among the samples ``index`` (an
        ascending array of sample numbers).
    chunk_s : float
        Consecutive chunks of this length [s] within an event are dealt round-robin to
        :attr:`folds` folds; each fold is predicted from the others.
    folds : int
        The within-event folds.
    material_nt : float
        The least RMS [nT, per component] of the effect's field over its events' samples: a
        field whose events are smaller is not this effect
        (:func:`orbitcal.diagnose.model.within_event.event_evidence`).
    """

    events: Callable[[DiagnosisData, IntArray], list[Event]]
    chunk_s: float
    folds: int
    material_nt: float


def fac_legs(t_s: FloatArray, amlat_deg: FloatArray, idx: IntArray) -> list[IntArray]:
    """The legs of the auroral crossings of the samples ``idx``: runs of consecutive samples
    (gaps under a minute) split at their highest magnetic latitude, each leg at least 3 samples
    (a shorter one joins the other leg of its run)."""
    if idx.size == 0:
        return []
    breaks = np.flatnonzero((np.diff(idx) > 1) | (np.diff(t_s[idx]) > 60.0)) + 1
    legs: list[IntArray] = []
    for run in np.split(idx, breaks):
        apex = int(np.argmax(amlat_deg[run]))
        parts = [run[: apex + 1], run[apex + 1 :]]
        if min(p.size for p in parts) < 3:
            parts = [run]
        legs.extend(p for p in parts if p.size)
    return legs


def fac_events(data: DiagnosisData, index: IntArray) -> list[Event]:
    """The field-aligned currents' events among the samples ``index``: each leg of each auroral
    crossing (|magnetic latitude| above ``AURORAL_MLAT_DEG``, :func:`fac_legs`), with latitude
    bumps (the catalogue's basis, those reaching 5 % on the leg) in both directions across B."""
    from orbitcal.diagnose.design import AURORAL_MLAT_DEG, FAC_CENTRES_DEG, _fac_bumps

    index = np.asarray(index, dtype=np.intp)
    amlat = np.abs(data.mlat_deg[index])
    hi = np.flatnonzero(amlat > AURORAL_MLAT_DEG)
    out = []
    # legs over positions in ``index`` (a gap in ``index`` is a gap in time: a minute's test)
    for k, leg in enumerate(fac_legs(data.t_utc_s[index], amlat, hi)):
        bumps = _fac_bumps(amlat[leg], 1.0, FAC_CENTRES_DEG)
        keep = bumps.max(axis=0) >= 0.05
        bumps = bumps[:, keep]
        if bumps.shape[1] == 0:
            continue
        centres = [c for c, kept in zip(FAC_CENTRES_DEG, keep, strict=True) if kept]
        transverse = data.transverse_body[index[leg]]  # (m, 2, 3)
        cols = transverse[:, :, :, None] * bumps[:, None, None, :]  # (m, 2, 3, b)
        cols = np.moveaxis(cols, 1, 2).reshape(leg.size, 3, -1)  # (m, 3, 2 b), direction first
        names = [f"{d}_leg{k}_{c:.0f}_nt" for d in ("east", "across") for c in centres]
        out.append(Event(leg, np.ascontiguousarray(cols), names))
    return out


#: The field-aligned currents' events (:attr:`orbitcal.diagnose.effects.Effect.event_design`).
FAC_EVENTS = EventDesign(fac_events, FAC_CHUNK_S, FAC_FOLDS, FAC_MATERIAL_NT)
