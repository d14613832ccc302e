"""The attitude error's own test: a held-out residual that turns the field without changing it.

An attitude error rotates the measured field: ``db = dtheta x B`` lies across B, and the part
along B (what an attitude-free scalar check sees) stays at the noise. Its catalogue model --
sinusoids and a drift held at its last value after the training blocks -- forecasts a periodic
error, but not a random walk of the rotation (a star tracker's slow wander, a boom's thermal
creep): the held-out blocks come after the training span, so the held-out test fails such a
walk however large it is. On the independent generator's worlds (``benchmarks/independent``,
seeds 13400-13900) it was the commonest miss: 8 of 33 attitude errors beside another effect,
with held-out residuals of up to 12.7 x the noise floor across B left as "none" or as an
unexplained gap "that wanders slowly, as a random-walk offset of the sensor would". A sensor's
offset wander is isotropic: a third of its power lies along B.

So, when the attitude error was not selected, the shape of what the final model leaves on the
held-out blocks is asked (:func:`rotation_test`), on quiet magnetic latitudes (auroral currents
are across B too) and without isolated samples:

* the residual across B exceeds the noise floor ``sigma`` (white part of the noise) by a margin:
  RMS per component >= :data:`ROTATION_MIN_TIMES_NOISE` x sigma;
* its excess power across B (per component, beyond sigma^2) is at least
  :data:`ROTATION_EXCESS_RATIO` x that along B (floored at a quarter of sigma^2): an isotropic
  misfit gives about 1, a rotation gives a large ratio;
* the attitude error's own model shrinks the held-out residual (p < :data:`ROTATION_ALONE_ALPHA`),
  fitted beside the calibration alone or beside the effects kept: a rotation that the training
  blocks do show (beside a torquer of 100 nT, the attitude error alone shrinks nothing).

Beside a kept time-tag error the test is not asked (a time-tag error on a turning body is a
rotation too: :data:`orbitcal.diagnose.honesty.ROTATING_TWIN`). An attitude error so named is
reported significant, judged by this test (``rotation_test``), with
no block in the final model: its model did not forecast the held-out blocks.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.noise import isolated_samples, noise_floor_nt

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.diagnose.attribution.scores import EffectScore
    from orbitcal.diagnose.data import DiagnosisData

__all__ = [
    "ROTATION_ALONE_ALPHA",
    "ROTATION_EXCESS_RATIO",
    "ROTATION_MIN_SAMPLES",
    "ROTATION_MIN_TIMES_NOISE",
    "ROTATION_QUIET_MLAT_DEG",
    "RotationTest",
    "rotation_test",
]

#: Held-out samples at or below this |magnetic latitude| are asked [deg] (as the split fits'
#: quiet guard: auroral currents, across B as well, flow poleward of it).
ROTATION_QUIET_MLAT_DEG = 60.0
#: The residual across B, RMS per component, must reach this many times the noise floor [-]:
#: an unexplained gap across B (:data:`orbitcal.diagnose.gap.GAP_TIMES_NOISE`). With the
#: excess ratio below, a residual at the noise along B needs 1.73 x across it.
ROTATION_MIN_TIMES_NOISE = 1.5
#: Excess power across B over excess power along B at or above which the residual is a rotation
#: [-]. On seeds 13400-13900 of the independent generator, worlds without an attitude error
#: reached 7.4 at most (auroral currents' far field beside a crust), and 3.5 among the null
#: worlds (random-walk offsets); the attitude errors the held-out test missed, 2.5-53.
#: The shape alone is not enough: on seeds 14600-14900 the far field of auroral currents beside
#: an orbit error reached 14 at 2.1 x the noise (14800 no. 4, no attitude error), and the
#: attitude error's own model refused it (p = 0.14 alone, 1.0 beside the effects kept).
ROTATION_EXCESS_RATIO = 8.0
#: The attitude error's own held-out test (beside the calibration alone or beside the effects
#: kept) must reach this level.
ROTATION_ALONE_ALPHA = 0.05
#: Fewer quiet held-out samples than this and the test is not made.
ROTATION_MIN_SAMPLES = 100


@dataclass(frozen=True)
class RotationTest:
    """The shape of the final held-out residual on quiet latitudes.

    Attributes
    ----------
    n : int
        Quiet held-out samples asked (isolated samples left out).
    across_b_rms_nt, along_b_rms_nt : float
        RMS per component across B (of the two components) and along B [nT].
    noise_floor_nt : float
        White-noise floor of the final residual on the held-out samples [nT].
    excess_ratio : float
        Excess power across B over excess power along B [-].
    alone_shrink, alone_p_value : float
        The attitude error's own held-out test beside the calibration alone.
    beside_p_value : float or None
        Its held-out test beside the effects kept (None when not fitted beside them).
    named : bool
        Every condition holds: the attitude error is named by this test.
    """

    n: int
    across_b_rms_nt: float
    along_b_rms_nt: float
    noise_floor_nt: float
    excess_ratio: float
    alone_shrink: float
    alone_p_value: float
    beside_p_value: float | None
    named: bool

    def to_json(self) -> dict[str, Any]:
        return {
            "judged_on": (
                f"the final model's held-out residual at |magnetic latitude| <= "
                f"{ROTATION_QUIET_MLAT_DEG:.0f} deg, across vs along the main field"
            ),
            "n": self.n,
            "across_b_rms_nt": round(self.across_b_rms_nt, 4),
            "along_b_rms_nt": round(self.along_b_rms_nt, 4),
            "noise_floor_nt": round(self.noise_floor_nt, 4),
            "excess_ratio": round(self.excess_ratio, 3),
            "alone_shrink": round(self.alone_shrink, 4),
            "alone_p_value": float(f"{self.alone_p_value:.3g}"),
            "beside_p_value": None
            if self.beside_p_value is None
            else float(f"{self.beside_p_value:.3g}"),
            "named": self.named,
        }

    def words(self) -> str:
        """Why the attitude error is named (for its ``rotation_reason``)."""
        return (
            "named by the shape of the held-out residual: on quiet latitudes what the final "
            f"model leaves is {self.across_b_rms_nt:.3g} nT per component across the main field "
            f"and {self.along_b_rms_nt:.3g} nT along it (noise floor "
            f"{self.noise_floor_nt:.3g} nT; excess power {self.excess_ratio:.3g} x), a rotation "
            "of the field that no change of its size explains, and the attitude error's own "
            + self._own_model_words()
            + "; its model (sinusoids and a drift held at its last "
            "value) does not forecast the held-out blocks, as a random walk of the attitude "
            "would not be, so the final model leaves it out"
        )

    def _own_model_words(self) -> str:
        alone = (
            f"model shrinks the held-out residual by {self.alone_shrink:.3g} x alone "
            f"(p = {self.alone_p_value:.2g})"
        )
        if _significant(self.alone_p_value) or self.beside_p_value is None:
            return alone
        return (
            f"model, not significant alone (p = {self.alone_p_value:.2g}), shrinks it beside "
            f"the effects kept (p = {self.beside_p_value:.2g})"
        )


def _significant(p: float | None) -> bool:
    return p is not None and bool(np.isfinite(p)) and p < ROTATION_ALONE_ALPHA


def rotation_test(
    data: DiagnosisData,
    residual_nt: FloatArray,
    holdout: BoolArray,
    alone: EffectScore | None,
    *,
    beside_p_value: float | Callable[[], float | None] | None = None,
) -> RotationTest | None:
    """The attitude error's own test on the final held-out residual ``residual_nt`` (N x 3,
    body axes [nT]); ``alone`` is the attitude error's score beside the calibration alone,
    ``beside_p_value`` its held-out test beside the effects kept (None when not fitted there),
    or a function that fits it there, called only when the shape holds and ``alone`` is not
    significant.

    None when it cannot be asked: no such score (no design on this span), an implausible fit,
    fewer than :data:`ROTATION_MIN_SAMPLES` quiet held-out samples, or no noise floor.
    """
    if alone is None or alone.implausible is not None:
        return None
    r = np.asarray(residual_nt, dtype=float)
    sigma = noise_floor_nt(r, holdout)
    if not (np.isfinite(sigma) and sigma > 0.0):
        return None
    quiet = np.abs(data.mlat_deg) <= ROTATION_QUIET_MLAT_DEG
    asked = holdout & quiet & ~isolated_samples(r, data.t_utc_s, sigma)
    n = int(np.count_nonzero(asked))
    if n < ROTATION_MIN_SAMPLES:
        return None
    b_hat = data.b_hat_body[asked]
    ra = r[asked]
    along = np.einsum("ni,ni->n", ra, b_hat)
    across = ra - along[:, None] * b_hat
    along_rms = float(np.sqrt(np.mean(along**2)))
    across_rms = float(np.sqrt(np.mean(np.sum(across**2, axis=1)) / 2.0))
    excess_across = max(across_rms**2 - sigma**2, 0.0)
    excess_along = max(along_rms**2 - sigma**2, 0.25 * sigma**2)
    ratio = excess_across / excess_along
    p = float(alone.p_value)
    shape = bool(across_rms >= ROTATION_MIN_TIMES_NOISE * sigma and ratio >= ROTATION_EXCESS_RATIO)
    own_alone = alone.shrink > 1.0 and _significant(p)
    if callable(beside_p_value):
        beside_p_value = beside_p_value() if shape and not own_alone else None
    named = shape and (own_alone or _significant(beside_p_value))
    return RotationTest(
        n, across_rms, along_rms, float(sigma), ratio, alone.shrink, p, beside_p_value, named
    )
