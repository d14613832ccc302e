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

import importlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.attitude_scan import design_attitude
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

__all__ = [
    "CATALOGUE",
    "EFFECT_NAMES",
    "FIELD_SCALE_NT",
    "DesignBlock",
    "DiagnosisData",
    "Effect",
    "RegionalTest",
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
    design : callable
        ``design(data, train_mask) -> DesignBlock | None``; None when the witness is missing.
        ``train_mask`` marks the samples a data-driven choice (e.g. a step time) may look at.
    absorbed_by_calibration : bool
        True when the 12 parameters can absorb it in some attitude regimes (needs split fits).
    design_beside : callable, optional
        ``design_beside(data, train, fixed)``: the design found beside already selected effects
        (their regressors fitted jointly with it), for designs found by a scan of the data: such
        an effect is scanned again on what the selected ones leave
        (:attr:`rescanned_beside_others`).
    near_twin : str, optional
        The effect the data of a few orbits hardly tell from this one: when this one is
        selected, the twin's simplest form is fitted in its place and, if the held-out blocks
        cannot tell it worse, listed as indistinguishable from it.
    regional_test : RegionalTest, optional
        How the effect is judged where the held-out blocks cannot judge it (auroral currents
        that change from crossing to crossing), and on which samples the other effects are
        fitted and judged when it fills the calibration's residual.
    """

    name: str
    physics: str
    witness: str
    design: DesignFn
    absorbed_by_calibration: bool = False
    design_beside: (
        Callable[[DiagnosisData, BoolArray, Sequence[DesignBlock]], DesignBlock | None] | None
    ) = None
    near_twin: str | None = None
    regional_test: RegionalTest | None = None

    @property
    def rescanned_beside_others(self) -> bool:
        """Whether its design comes from a scan of the residual, to be done again beside the
        effects selected before it (the attitude error's periods)."""
        return self.design_beside is not None


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


CATALOGUE: tuple[Effect, ...] = (
    Effect(
        "temperature",
        "offset and scale factor linear in the sensor temperature",
        "a temperature channel; residual correlates with it (often with sunlight)",
        _design_temperature,
        absorbed_by_calibration=True,
    ),
    Effect(
        "magnetorquer",
        "3x3 coupling of the magnetorquer dipole commands into the sensor",
        "mtq_x, mtq_y, mtq_z commands; residual steps when they switch",
        _design_magnetorquer,
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
    ),
    Effect(
        "external_field",
        "uniform magnetospheric field along the dipole (SM z) axis: ring current, "
        "constant plus RC-index-driven (or a per-window trend when no index covers the data)",
        "residual along the dipole axis, same sign at all latitudes; follows the RC/Dst index",
        _design_external,
    ),
    Effect(
        "crustal_field",
        "static lithospheric field fixed to the Earth (a crustal model, scaled)",
        "residual repeats with position on the ground track; needs a crustal model",
        _design_crustal,
    ),
    Effect(
        "sun_driven",
        "field organised by the Sun direction in the body frame, sunlit only (Swarm's dB_Sun)",
        "sunlit vs eclipse split fits disagree; needs the Sun direction and eclipse flag",
        _design_sun,
        absorbed_by_calibration=True,
    ),
    Effect(
        "nonlinearity",
        "quadratic and cubic terms of the sensor transfer function, per axis",
        "residual grows with |B| on an axis faster than linearly",
        _design_nonlinearity,
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
    ),
    Effect(
        "parameter_drift",
        "trend or step in the biases and scale factors",
        "split fits of consecutive time blocks disagree; the held-out error grows with time",
        _design_drift,
        absorbed_by_calibration=True,
    ),
    Effect(
        "field_aligned_currents",
        "transverse field at high magnetic latitude: bumps in |magnetic latitude| > 58 deg along "
        "magnetic east made perpendicular to B, modulated by magnetic local time (dawn/dusk)",
        "residual concentrated at |magnetic latitude| > 60 deg, perpendicular to B",
        _design_fac,
        regional_test=FAC_REGIONAL_TEST,
    ),
    Effect(
        "attitude_error",
        "a slowly varying attitude error dtheta(t): db = dtheta x B, dtheta a sum of up to three "
        "sinusoids with periods found on the training blocks",
        "vector residual perpendicular to B while the scalar residual stays clean",
        design_attitude,
        absorbed_by_calibration=True,
        design_beside=lambda data, train, fixed: design_attitude(data, train, fixed=fixed),
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
