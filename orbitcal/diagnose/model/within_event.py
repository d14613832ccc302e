"""Confirmation, within the final block's events, of effects whose amplitudes change from event
to event (the catalogue's :attr:`~orbitcal.diagnose.effects.Effect.event_design`).

Fitted on the training span, such an effect (the currents of an auroral crossing) forecasts
nothing of the final block's crossings, and orbit-long cross-validation cannot keep it: the
forecast confirmation (:mod:`orbitcal.diagnose.model.confirm`) is blind to it by construction.
Its form is confirmed on the final block instead, once, without any step having seen the block:

* the residual is the final block's forecast error of what the model core names there (the
  chosen model when its forecast is confirmed, else the calibration alone);
* each event's amplitudes (the catalogue's columns, with its Gaussian prior from the effect's
  ``param_ranges`` and rows weighted by the noise model's innovation deviation per axis: a
  posterior mean) are fitted on all but one fold of that event's chunks and predict the fold
  left out (chunks of ``chunk_s`` dealt round-robin to ``folds`` folds): every prediction is of
  samples its fit did not see;
* the residual against the residual less those predictions is the same Clark & West statistic
  with a Newey & West variance, and the same "closer" condition, as the forecast confirmation;
* its p-value is a Monte Carlo one (:data:`EVENT_SHIFTS` circular shifts of the residual against
  the events' columns, :func:`shifted_statistics`): the statistic's rank among the same
  statistic on the block's residual moved to other samples, with its own persistence and
  spikes. Its cost is power: a block of an orbit holds two to four crossings, which bound the
  studentised statistic near 2, and a shift can carry one crossing's field onto another
  (``docs/design.md``: the auroral currents of our simulator named in 11 of 19 blind worlds).
  Read from the normal distribution, as the forecast confirmation's is, the statistic assumed
  that the out-of-fold predictions are independent of the samples they predict. They are not
  where the noise persists from a chunk to the next beyond what the noise model whitens, or
  where a spike in one fold pulls the fit that predicts its neighbour: on the model
  calibration's null worlds (four orbits at 20 s, so each chunk is one sample) that test
  rejected 0.37 (pink), 0.18 (random walk) and 0.27 (spiky, 300 nT spikes) at level 0.05.

Each effect with an event design is one test; the model core names it when its test passes at
the confirmation level divided by the number of such tests made (Bonferroni over them).

Which of them is tested is chosen on the training span, as the other effects are, by a posterior
probability (:func:`event_evidence`): the exact Gaussian evidence of each training event's own
amplitudes (the effect's prior, its width scaled by one factor shared by the events and
averaged over a log-uniform grid) against no field, on the residual of the chosen model whitened
by a noise model fitted where no event is (the events' own field would otherwise be taken as
noise), at the same prior inclusion rate as every candidate; times the posterior probability that
the events' field reaches the size that makes it the effect (the design's ``material_nt``: a
sheet of a few nT is real, but not the auroral currents). Only one whose probability reaches the
selection cut-off is tested on the final block; that probability is the one the report states.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from orbitcal.arrays import FloatArray, IntArray
from orbitcal.diagnose.data import DiagnosisData
from orbitcal.diagnose.effects import Effect
from orbitcal.diagnose.event_design import Event
from orbitcal.diagnose.model.confirm import Confirmation, clark_west, confirm, whitened_rows
from orbitcal.diagnose.model.gram import ranges_prior
from orbitcal.diagnose.model.noise_model import AxisNoise, filtered, fit_noise, run_starts
from orbitcal.diagnose.options import ModelOptions

__all__ = [
    "EVENT_SCALES",
    "EVENT_SHIFTS",
    "EventEvidence",
    "EventJudgement",
    "event_confirmation",
    "event_evidence",
    "event_prediction",
    "judged_by_events",
    "shifted_statistics",
]

#: The least quiet (event-free) training samples to fit the events' noise model on.
MIN_QUIET_SAMPLES = 50


def event_prediction(
    data: DiagnosisData,
    index: IntArray,
    residual_nt: FloatArray,
    effect: Effect,
    sigma_nt: Sequence[float],
    prior_sd_fraction: float,
    scale: float = 1.0,
    events: Sequence[Event] | None = None,
) -> FloatArray | None:
    """The out-of-fold prediction of ``residual_nt`` (the samples ``index``, (m, 3) [nT], or
    (m, 3, s): s residuals at once) by ``effect``'s events (``events`` if given, else found),
    zero outside them, each event's amplitudes the posterior mean under its prior (its width
    times ``scale``) and white noise of ``sigma_nt`` per axis; None when the block holds no
    event."""
    design = effect.event_design
    if design is None:
        return None
    if events is None:
        events = design.events(data, index)
    if not events:
        return None
    t_s = data.t_utc_s[index]
    weight = 1.0 / np.maximum(np.asarray(sigma_nt, dtype=float), 1e-9)  # per axis
    res = np.asarray(residual_nt, dtype=float).reshape(residual_nt.shape[0], 3, -1)
    pred = np.zeros_like(res)
    for ev in events:
        mean, sd = ranges_prior([effect.param_range(n) for n in ev.names], prior_sd_fraction)
        precision = 1.0 / np.maximum(scale * sd, 1e-12) ** 2
        g = ev.columns * weight[None, :, None]
        r = res[ev.rows] * weight[None, :, None]
        chunk = ((t_s[ev.rows] - t_s[ev.rows[0]]) // design.chunk_s).astype(np.intp)
        fold = chunk % design.folds
        for f in np.unique(fold):
            held = fold == f
            if held.all():
                continue  # one chunk: nothing to fit it on
            x = g[~held].reshape(-1, g.shape[2])
            lhs = x.T @ x + np.diag(precision)
            rhs = x.T @ r[~held].reshape(x.shape[0], -1) + (precision * mean)[:, None]
            coef = np.linalg.solve(lhs, rhs)
            pred[ev.rows[held]] = np.einsum("hak,ks->has", ev.columns[held], coef)
    return pred.reshape(residual_nt.shape)


#: Circular shifts of the final block's residual against its events' columns whose statistics
#: make the within-event test's null distribution: its p-values are in steps of 1/(shifts + 1),
#: and at 99 a test at level 0.05 is exact when the shifted residuals are exchangeable.
EVENT_SHIFTS = 99
#: Shifts whose statistics are computed together (bounds the memory on a day at 1 Hz).
_SHIFT_BATCH = 20


def event_confirmation(
    data: DiagnosisData,
    index: IntArray,
    residual_nt: FloatArray,
    effect: Effect,
    noise: Sequence[AxisNoise],
    run_start: IntArray,
    prior_sd_fraction: float,
    block_samples: int = 0,
    *,
    sigma_nt: Sequence[float] | None = None,
    scale: float = 1.0,
    shifts: int = EVENT_SHIFTS,
) -> Confirmation | None:
    """``effect``'s within-event confirmation on the final block (the samples ``index``, their
    residual ``residual_nt``; see the module); None when the block holds none of its events.
    The within-event fits take white noise of ``sigma_nt`` per axis (the noise models'
    innovations' if None) and the prior's width times ``scale``.

    The p-value is a Monte Carlo one: the rank of the test's statistic among the same statistic
    on the residual circularly shifted against the events by ``shifts`` offsets spread over the
    block (:func:`shifted_statistics`). A shifted residual holds the block's noise, with all its
    persistence and its spikes, at other samples: under no event field and a noise stationary
    over the block it is drawn as the residual is, whatever the noise model missed."""
    sigma = [n.sigma_nt for n in noise] if sigma_nt is None else sigma_nt
    design = effect.event_design
    events = design.events(data, index) if design is not None else []

    def predict(residual: FloatArray) -> FloatArray | None:
        return event_prediction(
            data, index, residual, effect, sigma, prior_sd_fraction, scale, events
        )

    pred = predict(residual_nt)
    if pred is None:
        return None
    conf = confirm(residual_nt, residual_nt - pred, noise, run_start, block_samples)
    null = shifted_statistics(residual_nt, predict, noise, run_start, shifts)
    if null.size == 0:
        return conf
    p = (1.0 + float(np.sum(null >= conf.statistic))) / (null.size + 1.0)
    return dataclasses.replace(conf, p_value=p)


def shifted_statistics(
    residual_nt: FloatArray,
    predict: Callable[[FloatArray], FloatArray | None],
    noise: Sequence[AxisNoise],
    run_start: IntArray,
    shifts: int = EVENT_SHIFTS,
) -> FloatArray:
    """The within-event test's z statistic on ``residual_nt`` rolled by each of ``shifts``
    offsets spread evenly over the block's samples (every offset once when there are fewer),
    ``predict`` giving the events' out-of-fold prediction of (m, 3, s) residuals at once."""
    m = residual_nt.shape[0]
    offsets = np.unique(np.round(np.arange(1, shifts + 1) * m / (shifts + 1.0)).astype(np.intp))
    offsets = offsets[(offsets > 0) & (offsets < m)]
    out: list[float] = []
    for lo in range(0, offsets.size, _SHIFT_BATCH):
        batch = offsets[lo : lo + _SHIFT_BATCH]
        rolled = np.stack([np.roll(residual_nt, int(k), axis=0) for k in batch], axis=2)
        pred = predict(rolled)
        if pred is None:
            return np.zeros(0)
        wb = whitened_rows(rolled, noise, run_start)
        wm = whitened_rows(rolled - pred, noise, run_start)
        for j in range(batch.size):
            out.append(clark_west(wb[:, :, j], wm[:, :, j])[0])
    return np.asarray(out)


def _run_ends(run_start: IntArray) -> IntArray:
    """Per position, the last position of its run."""
    run_start = np.asarray(run_start)
    n = run_start.size
    firsts = np.flatnonzero(np.r_[True, run_start[1:] != run_start[:-1]])
    lasts = np.r_[firsts[1:] - 1, n - 1]
    return np.asarray(lasts[np.searchsorted(firsts, np.arange(n), side="right") - 1])


#: The events' amplitude scale is not known within the catalogue's range: a hierarchical prior
#: (one scale shared by every event, each event's amplitudes drawn at that scale), log-uniform
#: over these fractions of the range's Gaussian width (1/1000 to 1: ~1 to 1000 nT for the
#: auroral currents); the evidence is averaged over them (:func:`event_evidence`).
EVENT_SCALES: tuple[float, ...] = tuple(float(x) for x in np.geomspace(1e-3, 1.0, 13))
#: Posterior draws of the events' amplitudes for the probability that their field reaches the
#: design's ``material_nt`` (its standard error is at most 0.025 at this many).
MATERIAL_DRAWS = 400


@dataclass(frozen=True)
class EventEvidence:
    """What an effect's training events tell.

    Attributes
    ----------
    log_bayes_factor : float
        Its events' own amplitudes against no field, averaged over :data:`EVENT_SCALES`.
    scale : float
        The scale of greatest evidence (what the final block's within-event fits use).
    material : float
        Given the effect, the posterior probability that its field's RMS over the events'
        samples reaches the design's ``material_nt`` (at that scale).
    """

    log_bayes_factor: float
    scale: float
    material: float

    def probability(self, prior_inclusion: float) -> float:
        """The probability that the effect is there, at the size that makes it the effect:
        present (the Bayes factor against no field, at ``prior_inclusion``) and material."""
        log_odds = self.log_bayes_factor + math.log(prior_inclusion) - math.log1p(-prior_inclusion)
        return float(0.5 * (1.0 + math.tanh(0.5 * log_odds))) * self.material


@dataclass(frozen=True)
class _Cluster:
    """Events whose whitened columns overlap: the whitened columns and residual over the valid
    rows of their windows, the raw columns over the events' own samples, the names."""

    x_white: FloatArray
    y_white: FloatArray
    x_raw: FloatArray
    names: list[str]


def _whitened_clusters(
    data: DiagnosisData,
    index: IntArray,
    residual_nt: FloatArray,
    effect: Effect,
    noise: Sequence[AxisNoise],
    run_start: IntArray,
    events: Sequence[Event],
) -> list[_Cluster]:
    """The clusters of ``events`` (``effect``'s among the samples ``index``; see
    :class:`_Cluster`)."""
    if not events:
        return []
    wy = np.zeros_like(residual_nt, dtype=float)
    valid = np.ones(residual_nt.shape[0], dtype=bool)
    for i, nz in enumerate(noise):
        wy[:, i], ok = nz.whiten(residual_nt[:, i], run_start)
        valid &= ok
    filters = [nz.filter for nz in noise]
    lag = max(f.size - 1 for f in filters)
    ends = _run_ends(run_start)
    windows = [(int(ev.rows[0]), int(min(ev.rows[-1] + lag, ends[ev.rows[-1]]))) for ev in events]
    groups: list[list[int]] = []
    group_end = -1
    for k in np.argsort([w[0] for w in windows]).tolist():
        if groups and windows[k][0] <= group_end:
            groups[-1].append(k)  # overlaps the group's windows so far
        else:
            groups.append([k])
        group_end = max(group_end, windows[k][1])
    out = []
    for group in groups:
        lo = min(windows[k][0] for k in group)
        hi = max(windows[k][1] for k in group)
        width = sum(events[k].columns.shape[2] for k in group)
        x = np.zeros((hi - lo + 1, 3, width))
        inside = np.zeros(hi - lo + 1, dtype=bool)
        names: list[str] = []
        col = 0
        for k in group:
            ev = events[k]
            kk = ev.columns.shape[2]
            x[ev.rows - lo, :, col : col + kk] = ev.columns
            inside[ev.rows - lo] = True
            names += ev.names
            col += kk
        raw = x[inside].copy()
        for i, a in enumerate(filters):
            x[:, i, :] = filtered(a, x[:, i, :].copy()) / noise[i].sigma_nt
        rows = valid[lo : hi + 1]
        y = wy[lo : hi + 1][rows].reshape(-1)
        out.append(_Cluster(x[rows].reshape(-1, width), y, raw, names))
    return out


@dataclass(frozen=True)
class _Posterior:
    """One cluster's amplitudes' Gaussian posterior at one scale, and its log Bayes factor."""

    log_bf: float
    mean: FloatArray
    precision: FloatArray


def _posterior(c: _Cluster, effect: Effect, prior_sd_fraction: float, scale: float) -> _Posterior:
    """``log N(y; X mu, I + X S X') - log N(y; 0, I)`` (S the prior's at ``scale``) and the
    amplitudes' posterior."""
    mean, sd = ranges_prior([effect.param_range(n) for n in c.names], prior_sd_fraction)
    y = c.y_white - c.x_white @ mean
    var = np.maximum(scale * sd, 1e-12) ** 2
    a_mat = c.x_white.T @ c.x_white + np.diag(1.0 / var)
    b = c.x_white.T @ y
    _sign, logdet = np.linalg.slogdet(a_mat)
    shift = np.linalg.solve(a_mat, b)
    fit = 0.5 * float(b @ shift) + 0.5 * float(c.y_white @ c.y_white - y @ y)
    log_bf = fit - 0.5 * (float(np.sum(np.log(var))) + logdet)
    return _Posterior(log_bf, mean + shift, a_mat)


def _material(
    posts: Sequence[_Posterior], clusters: Sequence[_Cluster], material_nt: float
) -> float:
    """The share of :data:`MATERIAL_DRAWS` posterior draws of every cluster's amplitudes whose
    field's RMS over the events' samples (per component) reaches ``material_nt``."""
    rng = np.random.default_rng(0)  # the same draws for the same data: a reproducible report
    energy = np.zeros(MATERIAL_DRAWS)
    samples = 0
    for post, c in zip(posts, clusters, strict=True):
        chol = np.linalg.cholesky(post.precision)
        z = rng.standard_normal((post.mean.size, MATERIAL_DRAWS))
        draws = post.mean[:, None] + np.linalg.solve(chol.T, z)  # precision^(-1/2) z
        field = np.einsum("rak,kd->rad", c.x_raw, draws)
        energy += np.sum(field**2, axis=(0, 1))
        samples += c.x_raw.shape[0]
    rms = np.sqrt(energy / max(3 * samples, 1))
    return float(np.mean(rms >= material_nt))


def event_evidence(
    data: DiagnosisData,
    index: IntArray,
    residual_nt: FloatArray,
    effect: Effect,
    noise: Sequence[AxisNoise],
    run_start: IntArray,
    prior_sd_fraction: float,
    scales: Sequence[float] = EVENT_SCALES,
    events: Sequence[Event] | None = None,
) -> EventEvidence | None:
    """What ``effect``'s events among the samples ``index`` tell of it, from the residual
    ``residual_nt`` ((m, 3) [nT]) whitened by ``noise`` (runs ``run_start``); None when they
    hold no event.

    A column is zero outside its event, so its whitened value is too outside the event and the
    filter's tail after it: events whose windows overlap are one cluster, and the evidence at one
    scale is the sum over clusters of the exact Gaussian ``log N(y; X mu, I + X S X')`` less
    that of ``log N(y; 0, I)`` over the cluster's valid whitened rows; the Bayes factor is its
    average over ``scales``. Whether the field is large enough to be the effect (the design's
    ``material_nt``: a sheet of a few nT is not the auroral currents) is read from the posterior
    of the amplitudes at the scale of greatest evidence."""
    design = effect.event_design
    if events is None:
        events = design.events(data, index) if design is not None else []
    clusters = _whitened_clusters(data, index, residual_nt, effect, noise, run_start, events)
    if design is None or not clusters:
        return None
    by_scale = [[_posterior(c, effect, prior_sd_fraction, s) for c in clusters] for s in scales]
    logs = np.array([sum(p.log_bf for p in posts) for posts in by_scale])
    top = float(np.max(logs))
    log_bf = top + math.log(float(np.mean(np.exp(logs - top))))
    best = int(np.argmax(logs))
    material = _material(by_scale[best], clusters, design.material_nt)
    return EventEvidence(log_bf, float(scales[best]), material)


@dataclass(frozen=True)
class EventJudgement:
    """What the effects with an event design got.

    Attributes
    ----------
    probability : dict of str to float
        Per such effect with events in the training span, its posterior probability there.
    confirmations : dict of str to Confirmation
        Per one of them whose probability reaches the selection cut-off and with events in the
        final block, its within-event confirmation there.
    """

    probability: dict[str, float] = field(default_factory=dict)
    confirmations: dict[str, Confirmation] = field(default_factory=dict)


def judged_by_events(
    data: DiagnosisData,
    train: tuple[IntArray, IntArray, int, FloatArray],
    final: tuple[IntArray, IntArray, FloatArray, int],
    catalogue: Sequence[Effect],
    options: ModelOptions,
    *,
    force: bool = False,
) -> EventJudgement:
    """Each effect of ``catalogue`` with an event design: its probability on the training span
    (``train``: sample index, run starts, step, the chosen model's residual there, the events'
    own field not removed) and, when chosen, its confirmation on the final block (``final``:
    sample index, run starts, what the forecast confirmation leaves, an orbit's samples). With
    ``force``, each is tested whatever its probability (for measuring the test's size)."""
    index, starts, step, residual = train
    h_index, h_starts, left, orbit = final
    prior = min(max(options.expected_effects / max(len(catalogue), 1), 1e-9), 1.0 - 1e-9)
    out = EventJudgement()
    for eff in catalogue:
        if eff.event_design is None:
            continue
        events = eff.event_design.events(data, index)  # built once, for the mask and evidence
        inside = np.zeros(index.size, dtype=bool)
        for ev in events:
            inside[ev.rows] = True
        quiet = np.flatnonzero(~inside)
        if not inside.any() or quiet.size < MIN_QUIET_SAMPLES:
            continue
        noise = fit_noise(
            residual[quiet],
            run_starts(data, index[quiet], step),
            max_order=options.noise_max_order,
        )
        evidence = event_evidence(
            data, index, residual, eff, noise, starts, options.prior_sd_fraction, events=events
        )
        if evidence is None:
            continue
        out.probability[eff.name] = evidence.probability(prior)
        if out.probability[eff.name] < options.selection_probability and not force:
            continue
        # the within-event fits of the final block: the scale the training events chose, and
        # the quiet residual's own spread per axis (what a fit that ignores the noise's
        # persistence must count as noise)
        quiet_rms = np.sqrt(np.mean(residual[quiet] ** 2, axis=0))
        conf = event_confirmation(
            data,
            h_index,
            left,
            eff,
            noise,
            h_starts,
            options.prior_sd_fraction,
            orbit,
            sigma_nt=quiet_rms.tolist(),
            scale=evidence.scale,
        )
        if conf is not None:
            out.confirmations[eff.name] = conf
    return out
