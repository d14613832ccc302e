"""The effects catalogue: one candidate model per CONTRACT section-5 name, with its witness.

Every candidate is a *linear* extension of the 12-parameter calibration. The forward model of the
raw measurement, per sensor axis ``i`` and sample ``n``, is

    b_raw[n, i] = sum_j A[i, j] b_ref[n, j] + o[i] + sum_k c[k] G[n, i, k] + noise

where ``b_ref`` is the reference field in the body frame [nT], ``A`` (3x3) and ``o`` (3) are the 12
calibration parameters and ``G`` (N, 3, p) is the effect's design block (its *regressors*) with the
``p`` effect parameters ``c``. Effects that physically add a field outside the sensor (external,
crustal, field-aligned currents, Sun-driven) and effects inside it (temperature, magnetorquer,
nonlinearity, drift) are both written this way: with ``A`` close to identity the distinction changes
the parameters by the (small) calibration error only.

Each effect declares its *witness*: the data it needs (a temperature channel, magnetorquer commands,
the Sun direction, a crustal model ...). An effect whose witness is missing is not a candidate.

Geometry helpers use the centred dipole of :mod:`orbitcal.geomag` (IGRF-14 at 2020.0), the same
one the simulator uses.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import threading
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose import imperfect as imperfect_columns
from orbitcal.diagnose.attitude_scan import design_attitude
from orbitcal.diagnose.bounds import (
    FREE,
    STORM_MAIN_PHASE_MAX_NT_PER_H,
    ParamRange,
    PrefixRanges,
    aged_range,
    match_prefix,
    storm_consistency,
    symmetric,
    time_shift_consistency,
)
from orbitcal.diagnose.data import FIELD_SCALE_NT, DiagnosisData
from orbitcal.diagnose.design import (
    QUIET_MLAT_DEG,
    DesignBlock,
    DesignFn,
    _design_crustal,
    _design_drift,
    _design_external,
    _design_fac,
    _design_magnetorquer,
    _design_nonlinearity,
    _design_orbit,
    _design_sun,
    _design_temperature,
    _design_time_offset,
)
from orbitcal.diagnose.event_design import FAC_EVENTS, EventDesign
from orbitcal.diagnose.orbit_phase import design_attitude_by_phase

__all__ = [
    "CATALOGUE",
    "EFFECT_NAMES",
    "FIELD_SCALE_NT",
    "DesignBlock",
    "DiagnosisData",
    "Effect",
    "ParamRange",
    "RegionalTest",
    "block_inconsistencies",
    "block_ranges",
    "effect_param_range",
    "get_effect",
]


#: Every effect name of CONTRACT section 5 except ``none``, in catalogue order.
EFFECT_NAMES: tuple[str, ...] = (
    "temperature",
    "magnetorquer",
    "time_offset",
    "external_field",
    "crustal_field",
    "sun_driven",
    "nonlinearity",
    "orbit_error",
    "parameter_drift",
    "field_aligned_currents",
    "attitude_error",
)


@dataclass(frozen=True)
class Effect:
    """A candidate unmodelled effect.

    Attributes
    ----------
    name : str
        CONTRACT section-5 effect name.
    physics : str
        One line: what the model is.
    witness : str
        One line: what in the data reveals it (and which inputs it needs).
    build : callable
        ``build(data, train_mask) -> DesignBlock | None``; None when the witness is missing.
        ``train_mask`` marks the samples a data-driven choice (e.g. a step time) may look at.
        :meth:`design` calls it and marks the block (its alternatives and refinements too) as
        this effect's.
    absorbed_by_calibration : bool
        True when the 12 parameters can absorb it in some attitude regimes (needs split fits).
    build_beside : callable, optional
        ``build_beside(data, train, fixed)``: the design found beside already selected effects
        (their regressors fitted jointly with it), for designs found by a scan of the data: such
        an effect is scanned again on what the selected ones leave
        (:attr:`rescanned_beside_others`, :meth:`design_beside`).
    near_twin : str, optional
        The effect the data of a few orbits hardly tell from this one: when this one is
        selected, the twin's simplest form is fitted in its place and, if the held-out blocks
        cannot tell it worse, listed as indistinguishable from it.
    regional_test : RegionalTest, optional
        How the effect is judged where the held-out blocks cannot judge it (auroral currents
        that change from crossing to crossing), and on which samples the other effects are
        fitted and judged when it fills the calibration's residual.
    param_ranges : tuple of (prefix, ParamRange)
        The physical range (and, for some, a Gaussian prior) of each of its parameters, by
        parameter-name prefix, first match wins (sources in ``docs/diagnosis_priors.md``):
        every joint fit keeps the parameters inside (:meth:`param_range`).
    consistency : callable, optional
        ``consistency(names, values, sds) -> list of str``: why the fitted parameters contradict
        a relation physics fixes between them (empty when they do not); a variant that does is
        not chosen.
    age_growth : tuple of (prefix, int, float)
        Parameters whose range widens with the element set's age at the data (the orbit
        error's), by prefix: the power of the age they widen with beyond two days, and the
        least half-width per day of age (:func:`orbitcal.diagnose.bounds.aged_range`).
    event_design : EventDesign, optional
        For an effect whose amplitudes change from event to event (auroral crossings), its
        events' own columns (:mod:`orbitcal.diagnose.event_design`): no fit on the training span
        forecasts it, so the model core confirms its form within each event of the final block
        instead (:mod:`orbitcal.diagnose.model.within_event`).
    imperfect : callable, optional
        ``imperfect(data, train) -> DesignBlock | None``: columns of what the effect's own
        forms leave out when it is real but not exactly as written (the external field's
        components across the dipole axis), appended to each of its forms by the model core
        (:mod:`orbitcal.diagnose.model`) under the shrinkage prior of their ``param_ranges``;
        an effect present in a form the catalogue does not write then leaves less for the
        other effects' columns to take.
    further_forms : callable, optional
        ``further_forms(data, train) -> DesignBlock | None``: a form of the effect that only the
        model core weighs, beside :meth:`design`'s (by evidence, the scan behind it paid for
        as its block's ``forms_searched``): the attitude error as a constant rotation inside one
        window of the orbital phase (:mod:`orbitcal.diagnose.orbit_phase`, three columns),
        which the rules engine's choice among alternatives by the training BIC was never
        measured with.
    """

    name: str
    physics: str
    witness: str
    build: DesignFn
    absorbed_by_calibration: bool = False
    build_beside: (
        Callable[[DiagnosisData, BoolArray, Sequence[DesignBlock]], DesignBlock | None] | None
    ) = None
    near_twin: str | None = None
    regional_test: RegionalTest | None = None
    param_ranges: PrefixRanges = ()
    consistency: Callable[[list[str], list[float], list[float]], list[str]] | None = None
    age_growth: tuple[tuple[str, int, float], ...] = ()
    imperfect: DesignFn | None = None
    event_design: EventDesign | None = None
    further_forms: DesignFn | None = None

    @property
    def rescanned_beside_others(self) -> bool:
        """Whether its design comes from a scan of the residual, to be done again beside the
        effects selected before it (the attitude error's periods)."""
        return self.build_beside is not None

    def design(self, data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
        """Its design block on ``data`` (None when the witness is missing), marked as its own.

        Kept for the next call with the same data object and training samples: the rules
        engine and the model core (:mod:`orbitcal.diagnose.model`) ask for the same blocks, and
        a scan (the attitude error's periods) takes seconds on a day at 1 Hz."""
        key = (self.name, hashlib.blake2b(np.packbits(train).tobytes(), digest_size=16).digest())
        with _DESIGNS_LOCK:  # effects' designs are built on threads side by side (api.py)
            ref, held = _DESIGNS.get(id(data), (None, {}))
            if ref is None or ref() is not data:
                held = {}
                _DESIGNS[id(data)] = (weakref.ref(data), held)
                for stale in [k for k, (r, _) in _DESIGNS.items() if r() is None]:
                    del _DESIGNS[stale]
        if key not in held:
            held[key] = _owned(self.build(data, train), self.name)
        return held[key]

    def further_design(self, data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
        """The form of :attr:`further_forms` on ``data``, marked as its own (None without)."""
        if self.further_forms is None:
            return None
        return _owned(self.further_forms(data, train), self.name)

    def design_beside(
        self, data: DiagnosisData, train: BoolArray, fixed: Sequence[DesignBlock]
    ) -> DesignBlock | None:
        """Its design found beside the blocks ``fixed`` (for :attr:`rescanned_beside_others`
        effects; else its plain :meth:`design`)."""
        if self.build_beside is None:
            return self.design(data, train)
        return _owned(self.build_beside(data, train, fixed), self.name)

    def param_range(self, name: str, age_days: float | None = None) -> ParamRange:
        """The physical range of its parameter ``name`` (unbounded when none is declared), for
        an element set ``age_days`` from the data (of unknown age if None)."""
        rng = match_prefix(self.param_ranges, name)
        power, per_day = next(
            ((k, d) for prefix, k, d in self.age_growth if name.startswith(prefix)), (0, 0.0)
        )
        return aged_range(rng, power, per_day, age_days)

    def inconsistencies(self, names: list[str], values: list[float], sds: list[float]) -> list[str]:
        """Why fitted values of its parameters contradict each other (:attr:`consistency`)."""
        return [] if self.consistency is None else self.consistency(names, values, sds)


#: Design blocks per data object (by id, with a weak reference that tells a reused id): per
#: (effect, training samples), the block or None (:meth:`Effect.design`).
_DESIGNS: dict[int, tuple[Any, dict[tuple[str, bytes], DesignBlock | None]]] = {}
#: Guards the creation of a data object's entry in :data:`_DESIGNS`. The blocks are built
#: outside it: the builder threads (``api._model_core_started``) ask for different effects, and
#: the engines ask only once they are all built.
_DESIGNS_LOCK = threading.Lock()


def _owned(block: DesignBlock | None, effect: str) -> DesignBlock | None:
    """``block`` marked as ``effect``'s, with its alternatives, the forms its refinement makes
    and its other sizes (so that a joint fit asks that effect for the ranges of the block's
    parameters)."""
    if block is None:
        return None
    refine, sizes = block.refine, block.other_sizes

    def owned(make: Callable[[], Sequence[DesignBlock]]) -> Callable[[], list[DesignBlock]]:
        return lambda: [b for b in (_owned(x, effect) for x in make()) if b is not None]

    return dataclasses.replace(
        block,
        effect=effect,
        alternatives=tuple(
            b for b in (_owned(x, effect) for x in block.alternatives) if b is not None
        ),
        refine=None if refine is None else owned(refine),
        other_sizes=None if sizes is None else owned(sizes),
    )


def block_ranges(block: DesignBlock) -> list[ParamRange]:
    """The physical range of each of ``block``'s parameters, from the effect it belongs to
    (unbounded for a block of no effect of the catalogue)."""
    if not block.effect:
        return [FREE] * block.width
    effect = get_effect(block.effect)
    return [effect.param_range(n, block.element_age_days) for n in block.names]


def effect_param_range(effect: str, name: str, age_days: float | None = None) -> ParamRange:
    """The range of the parameter ``name`` of the effect called ``effect`` (unbounded when no
    effect of the catalogue is called so), for an element set ``age_days`` from the data: for
    the report's effects, named by their dicts."""
    return _BY_NAME[effect].param_range(name, age_days) if effect in _BY_NAME else FREE


def block_inconsistencies(block: DesignBlock, values: list[float], sds: list[float]) -> list[str]:
    """Why the fitted ``values`` of ``block``'s parameters contradict each other, asked of the
    effect it belongs to (none for a block of no effect)."""
    if not block.effect:
        return []
    return get_effect(block.effect).inconsistencies(block.names, values, sds)


@dataclass(frozen=True)
class RegionalTest:
    """How an effect the held-out blocks cannot judge is judged in its region instead.

    Attributes
    ----------
    test : str
        ``"module:function"`` of ``test(data, residual_nt, selected) -> EffectScore | None``:
        the effect judged on the residual of the selected model (None when it cannot be judged
        or is selected already). Named, not imported: the test lives with the engine
        (:mod:`orbitcal.diagnose.attribution.regional`), which imports this catalogue.
    quiet_mask : callable
        ``quiet_mask(data) -> ndarray of bool``: the samples where the effect does not act. When
        the test finds it in the calibration's residual, the other effects are fitted and judged
        on these only.
    quiet_note : str
        What the report says about that restriction.
    """

    test: str
    quiet_mask: Callable[[DiagnosisData], BoolArray]
    quiet_note: str

    def run(self, data: DiagnosisData, residual_nt: FloatArray, selected: Sequence[str]) -> Any:
        """The test on ``residual_nt`` (an ``EffectScore``, or None)."""
        module, _, name = self.test.partition(":")
        return getattr(importlib.import_module(module), name)(data, residual_nt, selected)


def _fac_quiet(data: DiagnosisData) -> BoolArray:
    return np.asarray(np.abs(data.mlat_deg) < QUIET_MLAT_DEG)


#: The field-aligned currents' regional test (:mod:`orbitcal.diagnose.attribution.regional`).
FAC_REGIONAL_TEST = RegionalTest(
    test="orbitcal.diagnose.attribution.regional:regional_fac",
    quiet_mask=_fac_quiet,
    quiet_note=(
        f"|magnetic latitude| < {QUIET_MLAT_DEG:.0f} deg: the currents found in the "
        "calibration's residual would swamp every other effect's held-out test"
    ),
)


_SENSITIVITY_THERMAL = "sensitivity thermal coefficient <= 500 ppm/degC (x 5e4 nT)"
_SOLAR_ARRAY = "stray field of solar-array currents, <= 500 nT"
_NONLINEARITY = "nonlinearity <= 1 % of 5e4 nT"
_FAC_PERTURBATION = "field-aligned-current perturbation at LEO <= 3000 nT"

#: The catalogue, each effect with the ranges of its parameters (``docs/diagnosis_priors.md``).
CATALOGUE: tuple[Effect, ...] = (
    Effect(
        "temperature",
        "offset and scale factor linear in the sensor temperature",
        "a temperature channel; residual correlates with it (often with sunlight)",
        _design_temperature,
        absorbed_by_calibration=True,
        param_ranges=(
            # fluxgate offset and sensitivity thermal coefficients
            ("offset_", symmetric(10.0, "fluxgate offset thermal coefficient, <= 10 nT/degC")),
            *((f"scale_{a}_per_degc", symmetric(25.0, _SENSITIVITY_THERMAL)) for a in "xyz"),
            # imperfect-model columns (shrinkage priors): a thermistor that lags the sensor by
            # up to ~10 min (the offset coefficient times the lag), a quadratic coefficient
            (
                "thermal_lag_",
                ParamRange(
                    -20.0,
                    20.0,
                    "offset coefficient x thermistor lag / 300 s: <= 10 nT/degC x 2",
                    0.0,
                    3.0,
                ),
            ),
            (
                "thermal_quadratic_",
                ParamRange(-1.0, 1.0, "quadratic offset coefficient, <= 1 nT/degC^2", 0.0, 0.1),
            ),
        ),
        imperfect=imperfect_columns.temperature_lag,
    ),
    Effect(
        "magnetorquer",
        "3x3 coupling of the magnetorquer dipole commands into the sensor (or, without "
        "commands, a 3 x k coupling of the k torquer currents)",
        "mtq_x, mtq_y, mtq_z commands, or hk_ torquer currents [mA or A] (hk_torque1a_ma); "
        "residual steps when they switch",
        _design_magnetorquer,
        param_ranges=(
            # a coil of <= 100 A m^2 per A (GRACE-FO's: ~ 30 A m^2 at 0.1 A), its dipole field at
            # d >= 0.27 m
            (
                "current_coupling_",
                symmetric(1.0e6, "torquer field at the sensor <= 1000 nT per mA of coil current"),
            ),
            # the dipole law 2 mu0 m / (4 pi d^3) at d >= 0.27 m
            ("coupling_", symmetric(1.0e4, "dipole field of 1 A m^2 at >= 0.27 m from the sensor")),
            # imperfect-model columns: the coupling times lag / reference lag (a coil's field
            # lags its command by inductance and eddy currents, seconds)
            (
                "lag_coupling_",
                ParamRange(
                    -1.0e4, 1.0e4, "coupling x lag / 10 s: the coupling's range", 0.0, 100.0
                ),
            ),
        ),
        imperfect=imperfect_columns.torquer_lag,
    ),
    Effect(
        "time_offset",
        "a constant time-tag error dt: db = dt * d(B_body)/dt",
        "residual follows the body-frame time derivative of B (attitude motion included)",
        _design_time_offset,
        absorbed_by_calibration=True,
        # A time-tag error moves each sample along the track relative to the Earth, a constant
        # along-track error of the element set along the inertial velocity: the two differ by
        # the Earth's rotation only (0.46 km/s x cos(latitude) of 7.6 km/s, across the track),
        # which a few orbits hardly tell apart (Selection.near_twins).
        near_twin="orbit_error",
        param_ranges=(
            # a clock synchronised by ground contacts or GNSS
            (
                "dt_squared_s2",
                ParamRange(0.0, 25.0, "second order of the same shift: 0 <= dt^2 <= 25"),
            ),
            ("dt_s", symmetric(5.0, "time-tag error of a synchronised on-board clock, <= 5 s")),
            # imperfect-model column: a clock drifting between synchronisations (TCXO 1-10 ppm)
            (
                "dt_rate_s_per_day",
                ParamRange(-10.0, 10.0, "clock drift <= 100 ppm (10 s/day)", 0.0, 1.0),
            ),
        ),
        imperfect=imperfect_columns.clock_drift,
        consistency=time_shift_consistency,
    ),
    Effect(
        "external_field",
        "uniform magnetospheric field along the dipole (SM z) axis: ring current, "
        "constant plus RC-index-driven (or, when no index covers the data, a trend, a recovery or "
        "a storm's main phase and recovery)",
        "residual along the dipole axis, same sign at all latitudes; follows the RC/Dst index",
        _design_external,
        param_ranges=(
            # the ring current and its rate of change
            (
                "uniform_along_dipole_nt",
                ParamRange(
                    -2000.0, 200.0, "magnetospheric field along the dipole: Dst >= -1760 nT"
                ),
            ),
            (
                "uniform_trend_nt_per_day",
                symmetric(7200.0, "ring-current rate of change <= 300 nT/h (extreme storms)"),
            ),
            (
                "storm_quiet_level_nt",
                ParamRange(
                    -200.0,
                    200.0,
                    "quiet-time magnetospheric field along the dipole beside a storm, near 0",
                    0.0,
                    30.0,
                ),
            ),
            (
                "storm_main_phase_nt_per_h",
                symmetric(
                    STORM_MAIN_PHASE_MAX_NT_PER_H,
                    "ring-current rate of change <= 300 nT/h (extreme storms)",
                ),
            ),
            (
                "storm_recovering_nt",
                symmetric(2000.0, "storm-time ring-current field at its minimum: |Dst| <= 1760 nT"),
            ),
            (
                "uniform_recovering_nt",
                symmetric(
                    2000.0, "decaying storm-time ring-current field at the start: |Dst| <= 1760 nT"
                ),
            ),
            (
                "rc_coefficient",
                ParamRange(0.3, 3.0, "field per nT of RC index, external + induced", 1.0, 0.5),
            ),
            (
                "rc_model_scale",
                ParamRange(0.2, 3.0, "RC-driven model amplitude, positive, near 1", 1.0, 0.5),
            ),
            (
                "asymmetric_",
                ParamRange(
                    -500.0,
                    500.0,
                    "ring current's local-time asymmetry (partial ring current): ASY-H up to"
                    " ~200 nT in great storms, a few nT when quiet",
                    0.0,
                    100.0,
                ),
            ),
            (
                "across_dipole_sm_",
                ParamRange(
                    -500.0,
                    500.0,
                    "external field across the dipole axis (partial ring current, tail):"
                    " ASY-H up to ~200 nT in great storms, a few nT when quiet",
                    0.0,
                    100.0,
                ),
            ),
        ),
        consistency=storm_consistency,
        imperfect=imperfect_columns.external_asymmetry,
    ),
    Effect(
        "crustal_field",
        "static lithospheric field fixed to the Earth (a crustal model, scaled)",
        "residual repeats with position on the ground track; needs a crustal model",
        _design_crustal,
        param_ranges=(
            # a published model's amplitude
            (
                "crust_scale",
                ParamRange(0.3, 3.0, "amplitude of a published crustal model, near 1", 1.0, 0.5),
            ),
            (
                "crust_low_degrees_scale",
                ParamRange(
                    -1.0,
                    3.0,
                    "a crustal model's degrees up to 20, where the core's small scales are as "
                    "large and the models disagree: near 1, perhaps absent",
                    1.0,
                    1.0,
                ),
            ),
        ),
    ),
    Effect(
        "sun_driven",
        "field organised by the Sun direction in the body frame, sunlit only (Swarm's dB_Sun)",
        "sunlit vs eclipse split fits disagree; needs the Sun direction and eclipse flag",
        _design_sun,
        absorbed_by_calibration=True,
        param_ranges=(
            # solar-array currents
            ("sunlit_offset_", symmetric(500.0, _SOLAR_ARRAY)),
            ("sun_", symmetric(500.0, _SOLAR_ARRAY)),
        ),
    ),
    Effect(
        "nonlinearity",
        "quadratic and cubic terms of the sensor transfer function, per axis",
        "residual grows with |B| on an axis faster than linearly",
        _design_nonlinearity,
        param_ranges=(
            # at 5e4 nT
            ("quadratic_", ParamRange(-500.0, 500.0, _NONLINEARITY, 0.0, 250.0)),
            ("cubic_", ParamRange(-500.0, 500.0, _NONLINEARITY, 0.0, 250.0)),
            # imperfect-model columns: cross-axis quadratic terms
            ("cross_", ParamRange(-500.0, 500.0, _NONLINEARITY, 0.0, 20.0)),
        ),
        imperfect=imperfect_columns.cross_nonlinearity,
    ),
    Effect(
        "orbit_error",
        "along-track position error (constant plus growth with time): "
        "db = ds * dB/ds along the inertial velocity (the Earth fixed at the sample time)",
        "residual follows the along-track gradient of the field, not the attitude motion; "
        "needs positions propagated from a TLE/OMM (not measured ones)",
        _design_orbit,
        absorbed_by_calibration=True,
        near_twin="time_offset",
        param_ranges=(
            # of an element set
            (
                "along_track_rate_km_per_day",
                symmetric(
                    600.0,
                    "SGP4 along-track error growth: drag <= 50 km/day, a manoeuvre after the "
                    "epoch 3 dv (260 km/day per m/s; ISS reboosts are 0.5-2 m/s)",
                ),
            ),
            ("along_track_km", symmetric(100.0, "SGP4 along-track error <= 100 km")),
            ("along_track_", symmetric(20.0, "once-per-rev along-track error <= 20 km")),
            ("radial_", symmetric(20.0, "radial error of an element set <= 20 km")),
            ("cross_track_", symmetric(20.0, "cross-track error of an element set <= 20 km")),
        ),
        # older than two days: the offset widens as the square of the age (drag), the rest as
        # the age; a manoeuvre after the epoch moves the offset at up to the rate's bound
        age_growth=(
            ("along_track_km", 2, 600.0),
            ("along_track_rate", 0, 0.0),
            ("along_track_", 1, 0.0),
            ("radial_", 1, 0.0),
            ("cross_track_", 1, 0.0),
        ),
    ),
    Effect(
        "parameter_drift",
        "trend or step in the biases and scale factors",
        "split fits of consecutive time blocks disagree; the held-out error grows with time",
        _design_drift,
        absorbed_by_calibration=True,
        param_ranges=(
            *((f"bias_{a}_step", symmetric(2000.0, "offset step <= 2000 nT")) for a in "xyz"),
            ("bias_", symmetric(100.0, "offset drift <= 100 nT/day")),
            *(
                (f"scale_{a}_x5e+04_step", symmetric(2500.0, "scale-factor step <= 5 % (x 5e4 nT)"))
                for a in "xyz"
            ),
            ("scale_", symmetric(100.0, "scale-factor drift <= 2000 ppm/day (x 5e4 nT)")),
        ),
    ),
    Effect(
        "field_aligned_currents",
        "transverse field at high magnetic latitude: bumps in |magnetic latitude| > 58 deg along "
        "magnetic east made perpendicular to B, modulated by magnetic local time (dawn/dusk)",
        "residual concentrated at |magnetic latitude| > 60 deg, perpendicular to B",
        _design_fac,
        regional_test=FAC_REGIONAL_TEST,
        param_ranges=(
            ("east_", symmetric(3000.0, _FAC_PERTURBATION)),
            # the within-event columns' second direction across B (event_design)
            ("across_", symmetric(3000.0, _FAC_PERTURBATION)),
        ),
        event_design=FAC_EVENTS,
    ),
    Effect(
        "attitude_error",
        "a slowly varying attitude error dtheta(t): db = dtheta x B, dtheta a sum of up to three "
        "sinusoids with periods found on the training blocks and a drift held at its last value "
        "after them",
        "vector residual perpendicular to B while the scalar residual stays clean",
        design_attitude,
        absorbed_by_calibration=True,
        build_beside=lambda data, train, fixed: design_attitude(data, train, fixed=fixed),
        param_ranges=(
            # a star-tracker head's misalignment from the others after calibration on ground
            ("dtheta_phase_", symmetric(3.0, "star-tracker head misalignment <= 3 mrad")),
            ("dtheta_", symmetric(100.0, "attitude error <= 100 mrad (~6 deg)")),
        ),
        further_forms=design_attitude_by_phase,
    ),
)

assert tuple(e.name for e in CATALOGUE) == EFFECT_NAMES
_BY_NAME = {e.name: e for e in CATALOGUE}
assert all(e.near_twin is None or _BY_NAME[e.near_twin].near_twin == e.name for e in CATALOGUE)


def get_effect(name: str) -> Effect:
    """The catalogue entry called ``name``; raises KeyError for unknown names."""
    if name in _BY_NAME:
        return _BY_NAME[name]
    raise KeyError(f"unknown effect {name!r}; known: {', '.join(EFFECT_NAMES)}")
