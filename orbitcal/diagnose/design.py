"""The design blocks: each effect's regressors ``G`` (N, 3, p) and how they are built.

A :class:`DesignBlock` holds an effect's columns (lazily, by chunks of rows) and parameter names;
the ``_design_*`` builders make one from :class:`~orbitcal.diagnose.data.DiagnosisData` for each
effect of the catalogue (:mod:`orbitcal.diagnose.effects`) but the attitude error, whose periods
come from a scan of the data (:mod:`orbitcal.diagnose.attitude_scan`).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.diagnose.columns import (
    Columns,
    Factor,
    FunctionColumns,
    Index,
    PerAxisColumns,
    ScaledVectorColumns,
    chunk_slices,
    take,
)
from orbitcal.diagnose.data import (
    FIELD_SCALE_NT,
    ORBIT_S,
    SECONDS_PER_DAY,
    DiagnosisData,
    _time_derivative,
)
from orbitcal.diagnose.orbit_shift import along_track_offset_km, shifted_columns

__all__ = ["DesignBlock", "DesignFn"]


@dataclass(frozen=True)
class DesignBlock:
    """An effect's regressors and parameter names.

    Attributes
    ----------
    source : ndarray, shape (N, 3, p), or Columns
        The regressors, or (:mod:`orbitcal.diagnose.columns`) their factors, from which the rows
        of the samples asked for are built: most blocks are products of quantities held anyway,
        and held whole every candidate's every variant would grow with N.
    names : list of str
        Parameter names with their units, e.g. ``"dt_s"``.
    variant : str
        Which form of the model was used (e.g. ``"trend"`` or ``"step"`` for drift).
    alternatives : sequence of DesignBlock
        Other forms of the same effect; the attribution keeps the one that fits the *training*
        blocks best (never the held-out ones).
    refine : callable, optional
        Forms near this one (a bias step a little earlier or later), tried when this one is
        chosen among the alternatives; each may refine further.
    effect : str
        The catalogue effect the block belongs to ("" for none), which the joint fit asks for
        the ranges of its parameters; set by ``Effect.design``.
    searched : int
        Parameters of the form chosen by search rather than fitted (a storm's minimum time and
        recovery time), counted with the names in the BIC of the choice among alternatives.
    indexed : bool
        The form is driven by a measured index (the RC index, an RC-driven model).
    unless_indexed : bool
        A storm's shape drawn from the data alone: where an ``indexed`` alternative beats the
        first form on training BIC (by
        :data:`~orbitcal.diagnose.attribution.joint_fit.INDEX_TRACKS_BIC`) and this form beats
        that, it must also predict the end of the training span better (``_forward_choice``).
    in_range_forms : bool
        When the form the training BIC prefers fits only with a parameter outside its physical
        range, the best form that fits within the ranges is taken instead (the external field
        on a span shorter than an orbit: ``joint_fit._plausible``).
    element_age_days : float, optional
        The element set's age at the data, which widens the orbit error's ranges
        (:attr:`DiagnosisData.element_age_days`).
    forms_searched : int
        How many forms a scan of the training data chose this one among (the attitude error's
        phase windows); the model core's posterior pays for the choice as for that many forms
        (:attr:`orbitcal.diagnose.model.gram.Form.n_forms`).
    other_sizes : callable, optional
        The forms of other numbers of terms than this one's, where a rule of the scan chose the
        number (the attitude error's sinusoids: one to three periods, the number by a forward
        forecast within the training span). The model core's posterior chooses among them and
        this one by evidence, each paid for as one more form; the rules engine keeps this one.
    sensor_matrix : bool
        The regressors already hold the sensor's matrix (estimated with the form: a field of
        thousands of nT, :mod:`orbitcal.diagnose.orbit_shift`); the stated values are not
        refitted through the fitted one again (``uncertainty.through_sensor``).
    """

    source: FloatArray | Columns
    names: list[str]
    variant: str = ""
    alternatives: Sequence[DesignBlock] = ()
    refine: Callable[[], Sequence[DesignBlock]] | None = field(default=None, compare=False)
    effect: str = field(default="", compare=False)
    searched: int = field(default=0, compare=False)
    indexed: bool = field(default=False, compare=False)
    unless_indexed: bool = field(default=False, compare=False)
    in_range_forms: bool = field(default=False, compare=False)
    element_age_days: float | None = field(default=None, compare=False)
    sensor_matrix: bool = field(default=False, compare=False)
    forms_searched: int = field(default=1, compare=False)
    other_sizes: Callable[[], Sequence[DesignBlock]] | None = field(default=None, compare=False)

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.source.n if callable(self.source) else self.source.shape[0])

    @property
    def width(self) -> int:
        """Number of parameters ``p``."""
        return len(self.names)

    def rows(self, index: Index) -> FloatArray:
        """Regressors of the samples ``index``, shape (m, 3, p); parameter ``k`` adds
        ``c[k] * rows[:, :, k]`` [nT] in the sensor/body frame."""
        if callable(self.source):
            return self.source(index)
        return self.source[index]

    def axis_columns(self) -> list[npt.NDArray[np.intp]]:
        """Per sensor axis, the parameters whose regressors are not all zero on that axis's rows
        (all of them unless the block acts on one axis per column)."""
        if isinstance(self.source, PerAxisColumns):
            return self.source.axis_columns()
        return [np.arange(self.width)] * 3

    def axis_rows(self, index: Index) -> list[FloatArray]:
        """Per sensor axis ``i``, the regressors of :meth:`axis_columns` on axis ``i``'s rows of
        the samples ``index``, (m, len(axis_columns()[i])) each."""
        if isinstance(self.source, PerAxisColumns):
            return self.source.axis_rows(index)
        g = self.rows(index)
        return [g[:, i, :] for i in range(3)]

    @property
    def g(self) -> FloatArray:
        """All regressors, shape (N, 3, p) (built whole: for small data and checks)."""
        return self.rows(slice(None))

    def apply(self, coef: FloatArray) -> FloatArray:
        """The field ``G @ coef`` at every sample [nT], shape (N, 3), a block at a time."""
        if not callable(self.source):
            return np.asarray(self.source @ coef)
        out = np.empty((self.n, 3))
        for part in chunk_slices(self.n):
            out[part] = self.rows(part) @ coef
        return out

    def all_finite(self) -> bool:
        """True when every regressor is finite (checked a block of samples at a time)."""
        if not callable(self.source):
            return bool(np.all(np.isfinite(self.source)))
        return all(bool(np.all(np.isfinite(self.rows(p)))) for p in chunk_slices(self.n))


DesignFn = Callable[[DiagnosisData, BoolArray], DesignBlock | None]


def _tau_days(data: DiagnosisData, train: BoolArray) -> FloatArray:
    t0 = float(np.mean(data.t_utc_s[train]))
    return np.asarray((data.t_utc_s - t0) / SECONDS_PER_DAY)


def _varies(x: FloatArray | None, *, tol: float = 1e-9) -> bool:
    return x is not None and bool(np.all(np.isfinite(x))) and float(np.std(x)) > tol


def _design_temperature(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    temp = data.hk("temperature")
    if temp is None or not _varies(temp):
        return None
    dtemp = temp - float(np.mean(temp[train]))
    g = PerAxisColumns(data.n, [dtemp, partial(_scaled_by, data.b_ref_body_nt, dtemp)])
    names = [f"offset_{a}_nt_per_degc" for a in "xyz"] + [
        f"scale_{a}_per_degc_x{FIELD_SCALE_NT:.0e}" for a in "xyz"
    ]
    return DesignBlock(g, names)


#: Housekeeping channels that carry magnetorquer currents (GRACE-FO MAG1B's ``torque1A`` ...
#: ``torque3B`` as ``hk_torque1a_ma`` ...), with their unit: milliamperes or amperes.
TORQUER_CURRENT = re.compile(r"^hk_.*(torq|mtq|magnetorquer).*_(ma|a)$", re.IGNORECASE)
#: Correlation above which a current channel repeats one already taken (a redundant coil
#: driven alike): it would add a column the data cannot separate.
SAME_CHANNEL_CORRELATION = 0.999


def torquer_currents(data: DiagnosisData) -> list[tuple[str, FloatArray]]:
    """The varying magnetorquer-current channels of ``data``, in amperes: ``(name, current_a)``.

    A channel proportional to one already taken is left out."""
    out: list[tuple[str, FloatArray]] = []
    for name in data.hk_names:
        match = TORQUER_CURRENT.match(name)
        x = data.hk(name)
        if match is None or x is None or not _varies(x):
            continue
        amps = np.asarray(x, dtype=float) * (1e-3 if match.group(2).lower() == "ma" else 1.0)
        if any(abs(float(np.corrcoef(amps, y)[0, 1])) > SAME_CHANNEL_CORRELATION for _, y in out):
            continue
        out.append((name, amps))
    return out


def _design_magnetorquer(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    cols = [data.hk(f"mtq_{a}") for a in "xyz"]
    if all(c is None or not _varies(c) for c in cols):
        # Without dipole commands, the torquer currents: the coils' field at the sensor is
        # linear in each coil's current (a 3 x k coupling, nT per A).
        currents = torquer_currents(data)
        if not currents:
            return None
        g_currents = PerAxisColumns(data.n, [x for _, x in currents], axis_major=True)
        return DesignBlock(
            g_currents,
            [
                f"current_coupling_{a}_{name.removeprefix('hk_')}_nt_per_a"
                for a in "xyz"
                for name, _ in currents
            ],
            variant="currents",
        )
    kinds = [c if c is not None else np.zeros(data.n) for c in cols]
    g = PerAxisColumns(data.n, kinds, axis_major=True)
    names = []
    for i in range(3):
        for j in range(3):
            names.append(f"coupling_{'xyz'[i]}{'xyz'[j]}_nt_per_am2")
    return DesignBlock(g, names)


def _design_time_offset(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    first = data.db_ref_body_dt_nt_s
    # Second order of the shift, b(t + dt) - b(t) = dt b' + dt^2 b''/2: under a fast spin the
    # cross term of the body rate and the along-track change of the field (not absorbed by the
    # 12 parameters) reaches ~1 nT for dt = 1 s at 1 deg/s; its coefficient is free (~dt^2).
    second = 0.5 * _time_derivative(data.t_utc_s, first)
    return DesignBlock(
        first[:, :, None],
        ["dt_s"],
        alternatives=(
            DesignBlock(
                ScaledVectorColumns(data.n, [first, second], [None, None]),
                ["dt_s", "dt_squared_s2"],
                "second_order",
            ),
        ),
    )


#: Decay times of the ring current's recovery phase tried by the external-field model [h].
EXTERNAL_RECOVERY_TIMES_H: tuple[float, ...] = tuple(
    float(x) for x in np.geomspace(2.0, 24.0, 10).round(2)
)


def _design_external(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    axis = data.dipole_axis_body
    tau = _tau_days(data, train)
    options = [
        DesignBlock(
            ScaledVectorColumns(data.n, [axis, axis], [None, tau]),
            ["uniform_along_dipole_nt", "uniform_trend_nt_per_day"],
            variant="dipole_axis",
        )
    ]
    # A storm's recovery phase: the ring-current field decays as exp(-t / tau) with tau of a few
    # to twenty hours (Burton et al. 1975: 7.7 h; O'Brien & McPherron 2000: 3-20 h), which a
    # linear trend extrapolates badly over the held-out blocks; tau from a grid, by training BIC.
    t_rel_s = data.t_utc_s - float(data.t_utc_s[0])
    for tau_h in EXTERNAL_RECOVERY_TIMES_H:
        decay = partial(_recovery_decay, t_rel_s, tau_h)
        options.append(
            DesignBlock(
                ScaledVectorColumns(data.n, [axis, axis], [None, decay]),
                ["uniform_along_dipole_nt", "uniform_recovering_nt"],
                variant=f"recovery_{tau_h:.3g}h",
            )
        )
    t_train = data.t_utc_s[train]
    short = bool(t_train.size) and float(t_train[-1] - t_train[0]) < ORBIT_S
    if short:
        # On a span shorter than an orbit the track passes each region once, so time along it
        # is position: a trend then takes up a field's latitude structure (the storm pass's
        # subauroral fields asked 420-760 nT/h of it, beyond a storm's 300 nT/h) and carries it
        # into the held-out blocks. The constant alone is the form left when the trend runs out
        # of its range (``in_range_forms``).
        options.append(
            DesignBlock(
                ScaledVectorColumns(data.n, [axis], [None]),
                ["uniform_along_dipole_nt"],
                variant="uniform",
            )
        )
    rc = data.rc_index_nt
    if rc is not None and _varies(rc[train], tol=1.0):
        options.append(
            DesignBlock(
                ScaledVectorColumns(data.n, [axis, axis], [None, rc - float(np.mean(rc[train]))]),
                ["uniform_along_dipole_nt", "rc_coefficient"],
                variant="rc_index",
                indexed=True,
            )
        )
    if data.b_ext_body_nt is not None and _varies(data.b_ext_body_nt[train, 0], tol=1e-3):
        options.append(
            DesignBlock(
                ScaledVectorColumns(data.n, [axis, data.b_ext_body_nt], [None, None]),
                ["uniform_along_dipole_nt", "rc_model_scale"],
                variant="rc_model",
                indexed=True,
            )
        )
        # The RC index is hourly: a storm's ring current also changes within the hour.
        options.append(
            DesignBlock(
                ScaledVectorColumns(data.n, [axis, data.b_ext_body_nt, axis], [None, None, tau]),
                ["uniform_along_dipole_nt", "rc_model_scale", "uniform_trend_nt_per_day"],
                variant="rc_model+trend",
                indexed=True,
            )
        )
    # Last: tried only when no index-driven form above follows the field (``unless_indexed``).
    options += _storm_variants(data, train, axis)
    first = options[0]
    return DesignBlock(
        first.source, first.names, first.variant, tuple(options[1:]), in_range_forms=short
    )


#: Times of the storm's minimum tried on the training span (10 % to 90 %), refined by halving
#: down to :data:`STORM_MINIMUM_RESOLUTION_S`.
STORM_MINIMUM_TIMES = 9
STORM_MINIMUM_RESOLUTION_S = 300.0
#: The recovery's decay time of the grid [h] (Burton et al. 1975: 7.7 h), and those the
#: refinement tries beside it at the chosen minimum (O'Brien & McPherron 2000: 3-20 h with the
#: solar wind).
STORM_RECOVERY_H = 7.7
STORM_RECOVERY_ALTERNATIVES_H: tuple[float, ...] = (4.0, 15.0)
#: Spans of training data shorter than this [s] (two orbits) have no storm variants.
STORM_MIN_SPAN_S = 10800.0


def _storm_variants(data: DiagnosisData, train: BoolArray, axis: FloatArray) -> list[DesignBlock]:
    """A storm's main phase and recovery (Burton et al. 1975): the ring-current field along the
    dipole falls linearly to its minimum at ``t_m`` (a sustained injection), then recovers as
    exp(-(t - t_m) / tau) towards its quiet-time level; ``t_m`` on a grid over the training span
    with tau = 7.7 h, refined by halving, the other decay times tried at each refined minimum.
    Spans shorter than two orbits have none (a pass sees a storm's phase, not its shape)."""
    t_train = data.t_utc_s[train]
    if t_train.size == 0:
        return []
    span = float(t_train[-1] - t_train[0])
    if span < STORM_MIN_SPAN_S:
        return []
    fracs = np.linspace(0.1, 0.9, STORM_MINIMUM_TIMES)
    half_s = 0.5 * float(fracs[1] - fracs[0]) * span
    return [
        _storm_at(data, axis, float(t_train[0] + f * span), STORM_RECOVERY_H, half_s) for f in fracs
    ]


def _storm_at(
    data: DiagnosisData, axis: FloatArray, tm: float, tau_h: float, half_s: float
) -> DesignBlock:
    main = partial(_main_phase_h, data.t_utc_s, tm)
    recovery = partial(_recovery_from, data.t_utc_s, tm, tau_h)
    refine = None
    if half_s >= STORM_MINIMUM_RESOLUTION_S:
        refine = partial(_storms_near, data, axis, tm, tau_h, half_s)
    # The quiet-time level beside the storm has a prior (near 0): under a nadir attitude the 12
    # parameters take a constant field along the dipole up, and free it ran to its bound
    # (-2000 nT) and bent the storm's shape.
    return DesignBlock(
        ScaledVectorColumns(data.n, [axis, axis, axis], [None, main, recovery]),
        ["storm_quiet_level_nt", "storm_main_phase_nt_per_h", "storm_recovering_nt"],
        variant=f"storm@{tm:.0f}_recovery_{tau_h:.3g}h",
        refine=refine,
        searched=2,
        unless_indexed=True,
    )


def _storms_near(
    data: DiagnosisData, axis: FloatArray, tm: float, tau_h: float, half_s: float
) -> list[DesignBlock]:
    """The minimum ``half_s`` earlier and later, at ``tm`` with the other decay times, and at
    ``tm`` again refining by half as much."""
    taus = (STORM_RECOVERY_H, *STORM_RECOVERY_ALTERNATIVES_H)
    return [
        *(_storm_at(data, axis, tm + d, tau_h, half_s / 2.0) for d in (-half_s, half_s)),
        *(_storm_at(data, axis, tm, other, half_s / 2.0) for other in taus if other != tau_h),
        _storm_at(data, axis, tm, tau_h, half_s / 2.0),
    ]


def _main_phase_h(t_s: FloatArray, tm: float, index: Index) -> FloatArray:
    """Hours before the storm's minimum ``tm`` (negative), 0 after, at the samples ``index``."""
    return np.asarray(np.minimum(t_s[index] - tm, 0.0) / 3600.0)


def _recovery_from(t_s: FloatArray, tm: float, tau_h: float, index: Index) -> FloatArray:
    """1 before the minimum ``tm``, exp(-(t - tm) / tau) after [-]."""
    return np.asarray(np.exp(-np.maximum(t_s[index] - tm, 0.0) / (tau_h * 3600.0)))


def _recovery_decay(t_rel_s: FloatArray, tau_h: float, index: Index) -> FloatArray:
    """The recovery-phase decay ``exp(-t / tau)`` of the samples ``index`` [-]."""
    return np.asarray(np.exp(-t_rel_s[index] / (tau_h * 3600.0)))


def _scaled_by(b_nt: FloatArray, x: Factor, index: Index) -> FloatArray:
    """``x * b / FIELD_SCALE_NT`` of the samples ``index``, (m, 3)."""
    return np.asarray(take(x, index)[:, None] * (b_nt[index] / FIELD_SCALE_NT))


def _field_power(b_nt: FloatArray, power: int, index: Index) -> FloatArray:
    """``(b / FIELD_SCALE_NT) ** power`` of the samples ``index``, (m, 3)."""
    return np.asarray((b_nt[index] / FIELD_SCALE_NT) ** power)


def _crust_bands(crust_nt: FloatArray, low_nt: FloatArray, index: Index) -> FloatArray:
    """The crust's degrees above the low band and the low band at the samples ``index``,
    (m, 3, 2): built when asked, not held."""
    low = low_nt[index]
    return np.stack([crust_nt[index] - low, low], axis=2)


def _design_crustal(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    """The crustal model scaled; where it has degrees at and below
    :data:`~orbitcal.diagnose.prepare.CRUST_LOW_BAND_NMAX` above the main field's, the form
    ``bands`` scales them apart (``crust_low_degrees_scale``; ``crust_scale`` then scales the
    degrees above). There the crust's spectrum meets the core's: the residual of a degree-13
    main field holds the core's small scales too, and models disagree on those degrees (CHAOS
    counts them as core, its crust starts at degree 21). Independent worlds whose crust was
    CHAOS-7's (degrees 21-185) fitted LCS-1 (degrees 14-185) at 0.3-0.66 x their scale of 1-2
    and left it unnamed; LCS-1's degrees 21+ alone correlate 0.84 with it, its degrees 14+
    0.60.

    Only over an orbit or more: along one stretch of track the low band's wavelengths (2,000 km
    and more) are a smooth curve that a storm's misfit or the calibration's extrapolation
    draws as well (the real storm pass: a crust named beside the external field in one of 40
    fresh draws with the bands, none without)."""
    if data.b_crust_body_nt is None:
        return None
    variant = data.crust_model or "model"
    low = data.b_crust_low_body_nt
    t_train = data.t_utc_s[train]
    span_s = float(t_train[-1] - t_train[0]) if t_train.size > 1 else 0.0
    bands: tuple[DesignBlock, ...] = ()
    if low is not None and float(np.max(np.abs(low))) > 0.0 and span_s >= ORBIT_S:
        bands = (
            DesignBlock(
                FunctionColumns(data.n, 2, partial(_crust_bands, data.b_crust_body_nt, low)),
                ["crust_scale", "crust_low_degrees_scale"],
                variant=f"{variant} bands",
            ),
        )
    return DesignBlock(
        data.b_crust_body_nt[:, :, None], ["crust_scale"], variant=variant, alternatives=bands
    )


def _design_sun(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    if data.sun_body is None or (data.sunlit is None and data.illumination is None):
        return None
    lit = (
        np.asarray(data.illumination, dtype=float)
        if data.illumination is not None
        else np.asarray(data.sunlit, dtype=float)
    )
    cols = [lit * data.sun_body[:, k] for k in range(3)]
    names = []
    for k in "xyz":
        names += [f"sun_{k}_to_{a}_nt" for a in "xyz"]
    if 0.02 < float(np.mean(lit[train] > 0.5)) < 0.98:
        # With eclipses in the data the sunlit offset is separable from the calibration offset.
        cols = [lit, *cols]
        names = [f"sunlit_offset_{a}_nt" for a in "xyz"] + names
    return DesignBlock(PerAxisColumns(data.n, cols), names)


def _design_nonlinearity(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    b = data.b_ref_body_nt
    g = PerAxisColumns(data.n, [partial(_field_power, b, 2), partial(_field_power, b, 3)])
    names = [f"quadratic_{a}_nt" for a in "xyz"] + [f"cubic_{a}_nt" for a in "xyz"]
    return DesignBlock(g, names)


def _design_orbit(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    if data.positions_measured:
        return None  # GNSS positions: no element-set error to model
    grads = data.db_ref_body_drtn_nt_km
    grad = grads[:, :, 1]
    tau = _tau_days(data, train)
    growing = DesignBlock(
        ScaledVectorColumns(data.n, [grad, grad], [None, tau]),
        ["along_track_km", "along_track_rate_km_per_day"],
        variant="growing",
    )
    # An element set's error in all three directions (Hill / Clohessy-Wiltshire motion): the
    # along-track error grows; an eccentricity error adds once-per-rev radial and (twice as large)
    # along-track terms, an inclination or node error once-per-rev cross-track terms.
    u = data.orbit_phase_rad
    c, sn = np.cos(u), np.sin(u)
    rad, nrm = grads[:, :, 0], grads[:, :, 2]
    rtn = DesignBlock(
        ScaledVectorColumns(
            data.n,
            [grad, grad, grad, grad, rad, rad, rad, nrm, nrm],
            [None, tau, c, sn, None, c, sn, c, sn],
        ),
        [
            "along_track_km",
            "along_track_rate_km_per_day",
            "along_track_cos_km",
            "along_track_sin_km",
            "radial_km",
            "radial_cos_km",
            "radial_sin_km",
            "cross_track_cos_km",
            "cross_track_sin_km",
        ],
        variant="rtn",
    )
    forms = [growing, rtn]
    # Hundreds of km off: the same form linearised where the spacecraft is (orbit_shift).
    rtn_columns = rtn.source
    assert isinstance(rtn_columns, ScaledVectorColumns)
    shift = along_track_offset_km(data, train, rtn_columns, tau)
    if shift is not None:
        s0, a = shift
        forms.append(
            DesignBlock(
                shifted_columns(data, s0, tau, a),
                rtn.names,
                variant=f"rtn_shifted_{s0:.0f}km",
                sensor_matrix=True,
            )
        )
    age = data.element_age_days
    return DesignBlock(
        grad[:, :, None],
        ["along_track_km"],
        "constant",
        alternatives=tuple(dataclasses.replace(f, element_age_days=age) for f in forms),
        element_age_days=age,
    )


def _design_drift(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    tau = _tau_days(data, train)
    b = data.b_ref_body_nt
    names_b = [f"bias_{a}" for a in "xyz"]
    names_s = [f"scale_{a}_x{FIELD_SCALE_NT:.0e}" for a in "xyz"]
    trend = PerAxisColumns(data.n, [tau, partial(_scaled_by, b, tau)])
    best = DesignBlock(trend, [n + "_nt_per_day" for n in names_b + names_s], variant="trend")
    # A step at one of ~20 candidate times inside the training span, chosen on training only by the
    # residual of the joint fit (done by the caller through ``choose_variant``).
    t_train = data.t_utc_s[train]
    span = float(t_train[-1] - t_train[0]) if t_train.size > 1 else 0.0
    if span <= 0.0:
        return best
    names = [n + "_step_nt" for n in names_b + names_s] + [n + "_nt_per_day" for n in names_b]

    fracs = np.linspace(0.1, 0.9, DRIFT_STEP_TIMES)
    spacing_s = float(fracs[1] - fracs[0]) * span
    cadence_s = float(np.median(np.diff(data.t_utc_s)))
    finest_s = max(DRIFT_STEP_RESOLUTION_S, cadence_s)
    steps = [
        _drift_step(data, names, tau, float(t_train[0] + f * span), spacing_s / 2.0, finest_s)
        for f in fracs
    ]
    return DesignBlock(best.source, best.names, best.variant, alternatives=tuple(steps))


#: Step times tried on the training span (10 % to 90 %), then refined by halving.
DRIFT_STEP_TIMES = 17
#: The refinement of a step time stops at this spacing [s] (or at the cadence, if coarser).
DRIFT_STEP_RESOLUTION_S = 30.0


def _drift_step(
    data: DiagnosisData,
    names: list[str],
    tau: FloatArray,
    ts: float,
    half_s: float,
    finest_s: float,
) -> DesignBlock:
    """The drift's bias and scale step at ``ts`` with its bias trend. Its refinement tries the
    step ``half_s`` earlier and later (each refining by half again) while ``half_s`` is at least
    ``finest_s``: a step misplaced by half the grid spacing leaves a box of the step's height
    that long, ~4 nT RMS over four orbits for a 30 nT step, which other effects then take up."""
    b = data.b_ref_body_nt
    step = partial(_step_at, data.t_utc_s, ts)
    kinds: list[Factor] = [step, partial(_scaled_by, b, step), tau]
    refine = None
    if half_s >= finest_s:
        refine = partial(_drift_steps_near, data, names, tau, ts, half_s, finest_s)
    return DesignBlock(
        PerAxisColumns(data.n, kinds), names, variant=f"step@{ts:.0f}+trend", refine=refine
    )


def _drift_steps_near(
    data: DiagnosisData,
    names: list[str],
    tau: FloatArray,
    ts: float,
    half_s: float,
    finest_s: float,
) -> list[DesignBlock]:
    """The step ``half_s`` earlier and later, and at ``ts`` again refining by half as much."""
    return [
        _drift_step(data, names, tau, ts + d, half_s / 2.0, finest_s)
        for d in (-half_s, half_s, 0.0)
    ]


def _step_at(t_s: FloatArray, ts: float, index: Index) -> FloatArray:
    """1 from the time ``ts`` on, 0 before, at the samples ``index``."""
    return np.asarray((t_s[index] >= ts).astype(float))


#: Magnetic-latitude centres [deg] and width [deg] of the field-aligned-current basis bumps.
FAC_CENTRES_DEG: tuple[float, ...] = tuple(float(c) for c in np.arange(58.0, 82.0, 2.0))
FAC_WIDTH_DEG = 1.5
FAC_MIN_MLAT_DEG = 58.0
#: |magnetic latitude| above which field-aligned currents flow / below which data are quiet [deg].
AURORAL_MLAT_DEG = 55.0
QUIET_MLAT_DEG = 50.0


def _design_fac(data: DiagnosisData, train: BoolArray) -> DesignBlock | None:
    mlat = data.mlat_deg
    if not np.any(np.abs(mlat[train]) > FAC_MIN_MLAT_DEG):
        return None
    # Region-1/2 currents reverse between dawn and dusk: each latitude bump is modulated by sin
    # and cos of the magnetic local time angle (when the Sun direction is known); two passes at
    # different local times are fitted exactly, and a constant term would be collinear with them.
    mods = ("",) if data.mlt_angle_rad is None else ("_sin_mlt", "_cos_mlt")
    bumps: list[tuple[float, float, str]] = []
    names = []
    for hemi, sign in (("n", 1.0), ("s", -1.0)):
        for c in FAC_CENTRES_DEG:
            bump = _fac_bump(mlat, sign, c)
            if float(np.max(bump[train], initial=0.0)) < 0.05:
                continue
            for suffix in mods:
                bumps.append((sign, c, suffix))
                names.append(f"east_{hemi}{c:.0f}{suffix}_nt")
    if not bumps:
        return None
    fn = partial(_fac_columns, data, tuple(bumps))
    return DesignBlock(FunctionColumns(data.n, len(bumps), fn), names)


def _fac_bumps(mlat_deg: FloatArray, sign: float, centres_deg: Sequence[float]) -> FloatArray:
    """Latitude bumps of the field-aligned-current basis of one hemisphere, (N, len(centres)):
    zero equatorward of their range, all centres in one exponential."""
    x = sign * mlat_deg
    on = np.flatnonzero(x >= FAC_MIN_MLAT_DEG - 3 * FAC_WIDTH_DEG)
    out = np.zeros((x.shape[0], len(centres_deg)))
    if on.size and len(centres_deg):
        d = (x[on, None] - np.asarray(centres_deg, dtype=float)) / FAC_WIDTH_DEG
        out[on] = np.exp(-0.5 * d**2)
    return out


def _fac_bump(mlat_deg: FloatArray, sign: float, centre_deg: float) -> FloatArray:
    """One latitude bump of the field-aligned-current basis (:func:`_fac_bumps`)."""
    return _fac_bumps(mlat_deg, sign, [centre_deg])[:, 0]


def _fac_columns(
    data: DiagnosisData, bumps: tuple[tuple[float, float, str], ...], index: Index
) -> FloatArray:
    """The field-aligned-current regressors of the samples ``index``, (m, 3, len(bumps)): built
    when a fit asks for them (two dozen columns held for the whole attribution took 95 MB at
    86,400 samples)."""
    east = data.transverse_body[index, 0, :]
    phi = data.mlt_angle_rad
    mlat = data.mlat_deg[index]
    mods = {} if phi is None else {"_sin_mlt": np.sin(phi[index]), "_cos_mlt": np.cos(phi[index])}
    weights = np.zeros((mlat.shape[0], len(bumps)))
    for sign in (1.0, -1.0):
        centres = sorted({c for sg, c, _ in bumps if sg == sign})
        values = _fac_bumps(mlat, sign, centres)
        for k, (sg, c, suffix) in enumerate(bumps):
            if sg == sign:
                w = values[:, centres.index(c)]
                weights[:, k] = w * mods[suffix] if suffix in mods else w
    return np.asarray(east[:, :, None] * weights[:, None, :])
