"""Effects no larger than the slow wander of the noise (issue 25: colored noise).

A sensor whose offset wanders (a random walk, 1/f noise) by a nT or two over hours leaves a
residual that no template fits and that the held-out blocks cannot tell from a small effect: a
drift, an external field's trend or an orbit error that follows the wander into the held-out
blocks shrinks them chunk after chunk, and was called significant on independent null worlds
(seeds 9500-9700: 6 of 54 null worlds, all six of random-walk or 1/f noise).

What tells them apart is on the training samples. A real effect, once modelled, leaves a residual
whose average over half an hour is flat (what is left is white noise averaged over a few hundred
samples); a wander leaves such averages of the size of what the effect drew from it. So over spans
of at least :data:`WANDER_MIN_SPAN_S`, an effect whose fitted field (its variation over every
sample the fits use, RMS per component) is less than ``1 /`` :data:`WANDER_RATIO` times the
:data:`WANDER_WINDOW_S` moving average of the final model's training residual (RMS per component)
cannot be told from the noise and is withdrawn (``status: "wander"``); a field that follows a
telemetry column or a published model (:data:`WITNESSED`) only when it is smaller than the wander
itself (:data:`WITNESSED_RATIO`). A field across the main field (an attitude error,
:data:`ACROSS_B`) is judged against the wander of the residual's component along it.

The ratio (wander / variation) measured when the test was added: real effects 0.005-0.057
(eight parameter-drift worlds of ``orbitcal simulate`` at magnitude 0.5 and 1, nadir and
tumbling; the temperature, time offset and storm of independent worlds); the spurious ones
0.27-1.9 (drifts on random-walk and 1/f worlds, a Sun-driven field beside a temperature, an
external field on 1/f noise, an orbit error on a random walk).
"""

from __future__ import annotations

import math

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.span_options import ORBIT_S

#: Window of the moving average that shows the residual's slow wander [s].
WANDER_WINDOW_S = 1800.0
#: An effect whose fitted field is below 1 / this times the wander is within the noise [-].
WANDER_RATIO = 0.15
#: Shorter spans have no wander test: a pass shorter than an orbit is one stretch of track whose
#: residual beside auroral currents or a storm is smooth by nature [s].
WANDER_MIN_SPAN_S = 2.0 * ORBIT_S
#: Residuals beyond this many robust standard deviations are left out of the averages (spikes).
WANDER_CLIP_SIGMA = 5.0
#: Effects whose field follows a measured column of the telemetry (the sensor's temperature, the
#: torquer currents) or a published model (the crust, a pattern of minutes along the track),
#: which a wandering offset follows only by chance: they are within the noise only when their
#: field varies less than the wander itself (ratio above :data:`WITNESSED_RATIO`). With the
#: others' 0.15 a real temperature of a few nT beside a 3 nT random walk was withdrawn at
#: 0.3-0.5 (worlds of ``tests/test_diagnose_wander.py``), as were real crusts of 1.5-3 nT on
#: independent worlds (seed 9600 worlds 15 and 18), while a torquer that a walk drew was named
#: at 2.3.
WITNESSED = frozenset({"temperature", "magnetorquer", "crustal_field"})
WITNESSED_RATIO = 1.0
#: Effects whose field is perpendicular to the main field (a rotation: db = dtheta x B). A
#: wandering sensor offset wanders along B as much as across it, so for these the wander is
#: read on the residual's component along B alone: an attitude error that wanders (a random walk
#: the model follows only in part) leaves its remainder across B, where it is no sign of a
#: wandering offset. (Independent world 10900 no. 15: a real attitude error of 22 nT was
#: withdrawn beside 3.4 nT of wander, most of it its own remainder. In 10600 no. 4 an unmodelled
#: temperature wanders along B too, and the attitude error beside it stays withdrawn.) Beside
#: such an effect every other effect is judged against the wander along B as well: what wanders
#: across B is then that effect's remainder, not a sign of a wandering offset. (Independent world
#: 12100 no. 3: a real crust of 0.99 nT beside an attitude error was withdrawn beside 1.11 nT of
#: wander, most of it the attitude error's random walk across B.)
ACROSS_B = frozenset({"attitude_error"})


def moving_average(t_s: FloatArray, x: FloatArray, window_s: float) -> tuple[FloatArray, BoolArray]:
    """Centred moving average of ``x`` (N, 3) over ``+- window_s / 2`` in time (the samples
    present: gaps shorten it), and where the window lies wholly inside the span."""
    cs = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    lo = np.searchsorted(t_s, t_s - window_s / 2.0, side="left")
    hi = np.searchsorted(t_s, t_s + window_s / 2.0, side="right")
    n = np.maximum(hi - lo, 1)[:, None]
    full = (t_s - window_s / 2.0 >= t_s[0]) & (t_s + window_s / 2.0 <= t_s[-1])
    return np.asarray((cs[hi] - cs[lo]) / n), np.asarray(full)


def slow_wander_nt(t_s: FloatArray, residual_nt: FloatArray) -> float:
    """RMS per component of the :data:`WANDER_WINDOW_S` moving average of a residual [nT]
    (spikes beyond :data:`WANDER_CLIP_SIGMA` robust standard deviations left out); nan when no
    window fits in the span."""
    r = residual_nt - np.median(residual_nt, axis=0)
    sigma = 1.4826 * np.median(np.abs(r), axis=0)
    lim = WANDER_CLIP_SIGMA * np.maximum(sigma, 1e-12)
    avg, full = moving_average(t_s, np.where(np.abs(r) > lim, 0.0, r), WANDER_WINDOW_S)
    if not np.any(full):
        return float("nan")
    return float(math.sqrt(float(np.mean(avg[full] ** 2))))


def field_variation_nt(field_nt: FloatArray) -> float:
    """RMS per component of a fitted field about its mean [nT]."""
    return float(math.sqrt(float(np.mean((field_nt - field_nt.mean(axis=0)) ** 2))))


def within_wander(
    t_s: FloatArray,
    residual_nt: FloatArray,
    fields_nt: dict[str, FloatArray],
    samples: BoolArray,
    span_s: float,
    field_samples: BoolArray | None = None,
    b_unit: FloatArray | None = None,
) -> dict[str, tuple[float, float]]:
    """The effects of ``fields_nt`` (name -> fitted field at every sample) within the noise's
    wander on ``samples`` (training): name -> (its field's variation on ``field_samples``, all
    samples by default, the wander) [nT], for those whose variation is below the wander /
    :data:`WANDER_RATIO`. The variation is taken beyond the training samples: a field that is
    flat there (a sensor temperature that starts changing in the held-out blocks) would
    otherwise count as none. With ``b_unit`` (the main field's direction at every sample) and an
    effect of :data:`ACROSS_B` among ``fields_nt``, every effect is judged against the wander of
    the residual along it."""
    if span_s < WANDER_MIN_SPAN_S or int(samples.sum()) < 10:
        return {}
    where = np.ones(t_s.size, dtype=bool) if field_samples is None else field_samples
    wander = slow_wander_nt(t_s[samples], residual_nt[samples])
    if not np.isfinite(wander):
        return {}
    along = wander
    across_kept = b_unit is not None and any(name in ACROSS_B for name in fields_nt)
    if b_unit is not None and across_kept:
        r_par = np.einsum("ij,ij->i", residual_nt[samples], b_unit[samples])[:, None]
        along = slow_wander_nt(t_s[samples], r_par)  # finite: the same windows as ``wander``
    out = {}
    for name, f in fields_nt.items():
        variation = field_variation_nt(f[where])
        ratio = WITNESSED_RATIO if name in WITNESSED else WANDER_RATIO
        w = along if across_kept else wander
        if w > ratio * variation:
            out[name] = (variation, w)
    return out


def wander_reason(variation_nt: float, wander_nt: float, *, along_b: bool = False) -> str:
    """The words of a withdrawal for being within the noise's wander (``along_b``: the wander
    of the residual's component along the main field, for the effects of :data:`ACROSS_B`)."""
    which = "training residual along the main field" if along_b else "training residual"
    return (
        f"its fitted field varies by {variation_nt:.3g} nT (RMS per component) where the final "
        f"model's {which}, averaged over {WANDER_WINDOW_S / 60:.0f} min, still wanders "
        f"by {wander_nt:.3g} nT: a field this small beside that wander is what a slowly "
        "wandering offset (random-walk or 1/f noise) draws, and the held-out blocks cannot tell "
        "it from one"
    )
