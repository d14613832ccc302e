"""Physical ranges of the effect parameters (``docs/diagnosis_priors.md`` gives the sources).

Every joint fit of the diagnosis is a box-constrained least-squares problem: the 12 calibration
parameters are free (or held by the calibration prior), each effect parameter lies in the range
below. A candidate whose fit would need a parameter outside its range (a crustal model turned
upside down, a ring current changing by thousands of nT per hour) is fitted at the edge of the
range, and when only the unconstrained fit would have won, it is reported as ``implausible`` with
the parameter that had to leave its range.

The ranges are deliberately wide -- they exclude what no spacecraft or magnetosphere does, not
what is unusual -- so that a physical effect is never clipped. Each effect of the catalogue
(:mod:`orbitcal.diagnose.effects`) carries the ranges of its own parameters
(``Effect.param_ranges``, matched by prefix on its parameter names, whose units are in the
names); this module holds the type, the helpers the catalogue writes them with, and the relation
physics fixes between a time shift's two parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "DRAG_RATE_KM_PER_DAY",
    "ELEMENT_AGE_REFERENCE_DAYS",
    "FREE",
    "ParamRange",
    "PrefixRanges",
    "aged_range",
    "match_prefix",
    "symmetric",
    "time_shift_consistency",
]


@dataclass(frozen=True)
class ParamRange:
    """Plausible range of one parameter.

    Attributes
    ----------
    lower, upper : float
        Bounds in the parameter's units (in its name).
    why : str
        One line: the physics or the missions the range comes from (sources in
        ``docs/diagnosis_priors.md``).
    prior_mean, prior_sd : float, optional
        A Gaussian prior inside the range, for parameters with a published value (a model's
        amplitude is 1) and for those a common attitude leaves ill-determined (a nonlinearity's
        cross-track terms in nadir): it decides the direction the data leave open (on a 30-min
        pass a scale factor and the ring current trade off) and hardly moves a well-determined
        fit.
    """

    lower: float
    upper: float
    why: str
    prior_mean: float | None = None
    prior_sd: float | None = None

    def contains(self, value: float, *, rel_tol: float = 1e-6) -> bool:
        """Whether ``value`` lies inside the range (a relative tolerance for solver round-off)."""
        pad = rel_tol * max(abs(self.lower), abs(self.upper), 1.0)
        return self.lower - pad <= value <= self.upper + pad

    def describe(self) -> str:
        """``[lower, upper]`` with the reason."""
        return f"[{self.lower:g}, {self.upper:g}] ({self.why})"


def symmetric(x: float, why: str) -> ParamRange:
    """The range ``[-x, x]``."""
    return ParamRange(-x, x, why)


#: The range of a parameter no effect bounds.
FREE = ParamRange(-math.inf, math.inf, "no physical range")


#: Ranges by parameter-name prefix, first match wins (an effect's ``param_ranges``).
PrefixRanges = tuple[tuple[str, ParamRange], ...]


#: The fastest along-track drift drag gives an element set's error [km/day] (high drag); faster
#: is a manoeuvre after its epoch (the orbit error's range allows one; its entry says so).
DRAG_RATE_KM_PER_DAY = 50.0

#: Age of an element set at the data up to which the orbit error's ranges hold as declared [d];
#: an older set's ranges widen (:func:`aged_range`).
ELEMENT_AGE_REFERENCE_DAYS = 2.0


def aged_range(rng: ParamRange, power: int, per_day: float, age_days: float | None) -> ParamRange:
    """``rng`` for an element set ``age_days`` old at the data: widened by ``(age /
    ELEMENT_AGE_REFERENCE_DAYS) ** power`` when older than that, and to at least ``+-per_day x
    age`` (unchanged for an unknown age).

    An element set's along-track error grows with its age: an unmodelled drag acceleration ``a``
    puts the spacecraft ``a t^2 / 2`` behind or ahead after ``t`` and makes it drift at ``a t``,
    a manoeuvre after the epoch by ``3 dv t`` (a reboost of 1 m/s: 260 km a day). On real ISS
    element sets 2-8 days apart (the TLEs of ``tests/authorities``) the older one was more than
    100 km off in 4 of 12 pairs, 1,650 km at most; Swarm's stayed within 23 km.
    """
    if age_days is None or not math.isfinite(age_days):
        return rng
    age = abs(age_days)
    factor = age / ELEMENT_AGE_REFERENCE_DAYS
    k = factor**power if factor > 1.0 else 1.0
    lower, upper = rng.lower * k, rng.upper * k
    if per_day > 0.0:
        lower, upper = min(lower, -per_day * age), max(upper, per_day * age)
    if (lower, upper) == (rng.lower, rng.upper):
        return rng
    return ParamRange(
        lower,
        upper,
        f"{rng.why}; for an element set {age:.1f} days from the data",
        rng.prior_mean,
        rng.prior_sd,
    )


def match_prefix(ranges: PrefixRanges, name: str) -> ParamRange:
    """The range of the first prefix of ``ranges`` that ``name`` starts with (:data:`FREE` when
    none does)."""
    for prefix, rng in ranges:
        if name.startswith(prefix):
            return rng
    return FREE


#: The steepest main phase of a storm [nT/h] (extreme storms: a few hundred nT/h).
STORM_MAIN_PHASE_MAX_NT_PER_H = 300.0


def storm_consistency(names: list[str], values: list[float], sds: list[float]) -> list[str]:
    """Why an external field's storm variant contradicts itself (empty when it does not): a
    main phase at its bound, the steepest an extreme storm has, is a ramp drawing something
    other than a ring current (the auroral currents' crossings of a short main phase: an
    independent world lost its external field to a storm variant at 637 nT/h). Bounded fits
    clip it, so the bound itself is the sign (the ``external_field`` effect's ``consistency``).
    """
    del sds
    if "storm_main_phase_nt_per_h" not in names:
        return []
    rate = values[names.index("storm_main_phase_nt_per_h")]
    if abs(rate) >= (1.0 - 1e-6) * STORM_MAIN_PHASE_MAX_NT_PER_H:
        return [
            f"storm_main_phase_nt_per_h = {rate:.4g} at its bound "
            f"(+-{STORM_MAIN_PHASE_MAX_NT_PER_H:g} nT/h): the steepest main phase of an extreme "
            "storm, not this world's"
        ]
    return []


def time_shift_consistency(names: list[str], values: list[float], sds: list[float]) -> list[str]:
    """Why a time offset's parameters contradict each other (empty when they do not).

    The second-order coefficient of a time shift is ``dt^2`` itself: a fit whose
    ``dt_squared_s2`` differs from ``dt_s^2`` by more than three standard deviations (plus
    0.1 s^2 and a factor 2) is using the second-order column for something else (the
    ``time_offset`` effect's ``consistency``).
    """
    out: list[str] = []
    idx = {n: i for i, n in enumerate(names)}
    if "dt_s" in idx and "dt_squared_s2" in idx:
        dt, dt2 = values[idx["dt_s"]], values[idx["dt_squared_s2"]]
        sd2 = sds[idx["dt_squared_s2"]]
        sd1 = sds[idx["dt_s"]]
        # The second-order column is only approximately the second derivative (the part a
        # steady spin gives is absorbed by the 12 parameters): a factor 2 is tolerated.
        tol = 3.0 * math.hypot(sd2, 2.0 * abs(dt) * sd1) + 0.1 + dt * dt
        if math.isfinite(tol) and abs(dt2 - dt * dt) > tol:
            out.append(
                f"dt_squared_s2 = {dt2:.3g} s^2 while dt_s^2 = {dt * dt:.3g} s^2: the second-order "
                "term of a time shift must equal the square of the shift"
            )
    return out
