"""The injection side of the effects catalogue (CONTRACT section 5 names, issue 5).

Each effect is a small dataclass: ``name`` (the contract's effect name), ``params`` (its
parameters, JSON-ready) and ``inject(state, rng) -> Injection`` returning the field-equivalent
disturbance ``db_body_nt`` (N, 3) [nT] in body axes, added to the reference field *before* the
sensor's ``A`` and ``B_0`` (Wang 2020 eq. 1), plus any housekeeping channels and diagnostic
``info`` for the ground truth. The housekeeping an effect couples to (temperature, magnetorquer
commands, attitude, Sun) is produced by the world for every spacecraft, so its presence never
betrays the effect.

Default magnitudes are physically sensible for a LEO fluxgate on a small spacecraft:

======================  =========================================================================
temperature             bias 1.5–2.5 nT/°C and scale 20–30 ppm/°C about 20 °C; the orbital
                        thermal cycle swings ±10 °C → ~20 nT
magnetorquer            3×3 coupling 1–15 nT per A·m² of the (≤ 2 A·m²) dipole commands
time_offset             time tags 0.5 s late → dB = B(t − δ) − B(t), ~20–35 nT at LEO
external_field          uniform ring-current field −50 nT along the geomagnetic dipole axis
                        (or the RC-index-driven model of ``orbitcal.field``)
crustal_field           MF7 (or LCS-1) lithospheric field, ~3 nT rms, up to ~20 nT
sun_driven              body-fixed 3×3 pattern ~10 nT of the Sun direction in body, sunlit only
nonlinearity            cubic 1e-12 nT⁻² per axis → ~30–60 nT at 40 000 nT
orbit_error             1 km along-track error (or the true orbit from a later TLE)
parameter_drift         bias step ~15 nT half-way plus a trend of a few nT/day
field_aligned_currents  300 nT transverse (magnetic east ⟂ B) at |magnetic latitude| 60–75°
attitude_error          0.05° slowly varying rotation → ~35 nT ⟂ B, scalar residual clean
======================  =========================================================================
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

import numpy as np

from orbitcal.arrays import FloatArray
from orbitcal.errors import BadInputError
from orbitcal.geomag import dipole_axis_itrs, magnetic_latitude_deg

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.simulate.state import WorldState

__all__ = [
    "EFFECTS",
    "EFFECT_NAMES",
    "AttitudeErrorEffect",
    "CrustalFieldEffect",
    "Effect",
    "ExternalFieldEffect",
    "FieldAlignedCurrentsEffect",
    "Injection",
    "MagnetorquerEffect",
    "NonlinearityEffect",
    "OrbitErrorEffect",
    "ParameterDriftEffect",
    "SunDrivenEffect",
    "TemperatureEffect",
    "TimeOffsetEffect",
    "make_effect",
    "parse_effect_spec",
]


class Injection(NamedTuple):
    """What an effect adds to a world."""

    db_body_nt: FloatArray
    hk: dict[str, FloatArray] = {}  # noqa: RUF012 - NamedTuple default, never mutated
    info: dict[str, Any] = {}  # noqa: RUF012


def _vec3(x: Any, name: str) -> FloatArray:
    v = np.broadcast_to(np.asarray(x, dtype=np.float64), (3,))
    if not np.all(np.isfinite(v)):
        raise BadInputError(f"{name} must be finite")
    return np.array(v)


def _mat3(x: Any, name: str) -> FloatArray:
    m = np.asarray(x, dtype=np.float64)
    if m.shape == (9,):
        m = m.reshape(3, 3)
    elif m.ndim == 0 or m.shape == (3,):
        m = np.diag(np.broadcast_to(m, (3,)))
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        raise BadInputError(f"{name} must be a finite 3×3 matrix (9 numbers, 3 diagonal or 1)")
    return m


@dataclass(frozen=True)
class Effect:
    """Base class: a named disturbance with parameters (dataclass fields)."""

    name: ClassVar[str] = ""
    #: Parameters proportional to the disturbance's size (multiplied by :meth:`scaled`).
    magnitude_params: ClassVar[tuple[str, ...]] = ()

    def scaled(self, factor: float) -> Effect:
        """The same effect with its magnitude parameters multiplied by ``factor``.

        E.g. ``make_effect("time_offset").scaled(4)`` is a 2 s offset; the blind benchmark uses
        it to inject each effect at several magnitudes.
        """
        changes: dict[str, Any] = {}
        for key in self.magnitude_params:
            value = getattr(self, key)
            if isinstance(value, tuple):
                changes[key] = tuple(float(x) * factor for x in value)
            elif value is not None:
                changes[key] = float(value) * factor
        return dataclasses.replace(self, **changes)

    @property
    def params(self) -> dict[str, Any]:
        """The parameters, JSON-ready."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            out[f.name] = np.asarray(v).tolist() if isinstance(v, tuple | np.ndarray) else v
        return out

    def inject(self, state: WorldState, rng: np.random.Generator) -> Injection:
        """The disturbance for this world (see the module docstring)."""
        raise NotImplementedError


@dataclass(frozen=True)
class TemperatureEffect(Effect):
    """Offset and scale factor drifting with the sensor temperature.

    ``dB = k_b ΔT + k_s ⊙ B ΔT`` with ``ΔT = T − t_ref_c``; witness: the ``temperature`` column.
    """

    name: ClassVar[str] = "temperature"
    magnitude_params: ClassVar[tuple[str, ...]] = ("bias_nt_per_c", "scale_per_c")
    bias_nt_per_c: tuple[float, ...] = (2.0, -1.5, 2.5)
    scale_per_c: tuple[float, ...] = (3.0e-5, -2.0e-5, 2.5e-5)
    t_ref_c: float = 20.0

    def inject(self, state: WorldState, rng: np.random.Generator) -> Injection:
        d_t = (state.temperature_c - self.t_ref_c)[:, None]
        kb = _vec3(self.bias_nt_per_c, "bias_nt_per_c")
        ks = _vec3(self.scale_per_c, "scale_per_c")
        db = kb * d_t + ks * state.b_ref_body_nt * d_t
        return Injection(db, info={"temperature_range_c": [float(d_t.min()), float(d_t.max())]})


@dataclass(frozen=True)
class MagnetorquerEffect(Effect):
    """Stray field of the magnetorquers: ``dB = C m`` (3×3 coupling, nT per A·m²).

    Witness: the ``mtq_x, mtq_y, mtq_z`` command columns.
    """

    name: ClassVar[str] = "magnetorquer"
    magnitude_params: ClassVar[tuple[str, ...]] = ("coupling_nt_per_am2",)
    coupling_nt_per_am2: tuple[float, ...] = (12.0, 2.0, -1.0, 1.5, -9.0, 3.0, -2.0, 1.0, 15.0)

    def inject(self, state: WorldState, rng: np.random.Generator) -> Injection:
        c = _mat3(self.coupling_nt_per_am2, "coupling_nt_per_am2")
        return Injection(state.mtq_am2 @ c.T)


@dataclass(frozen=True)
class TimeOffsetEffect(Effect):
    """Time tags late by ``offset_s``: the row stamped t holds the field of t − δ.

    ``dB = B_body(t − δ) − B_body(t)`` (orbit and attitude re-evaluated), ≈ −δ dB/dt.
    """

    name: ClassVar[str] = "time_offset"
    magnitude_params: ClassVar[tuple[str, ...]] = ("offset_s",)
    offset_s: float = 0.5

    def inject(self, state: WorldState, rng: np.random.Generator) -> Injection:
        shifted = state.field_body_nt(state.t_utc_s - float(self.offset_s))
        return Injection(shifted - state.b_ref_body_nt)


@dataclass(frozen=True)
class ExternalFieldEffect(Effect):
    """Magnetospheric ring-current field.

    ``model="dipole"``: a uniform field ``amplitude_nt · ẑ_dipole`` (negative: southward, a
    storm's Dst-like depression) that recovers as ``exp(−(t − t₀)/recovery_time_s)`` when a
    recovery time is given. ``model="RC"``: the RC-index-driven field of ``orbitcal.field``
    (external + induced), times ``scale``.
    """

    name: ClassVar[str] = "external_field"
    magnitude_params: ClassVar[tuple[str, ...]] = ("scale",)
    amplitude_nt: float = -50.0
    recovery_time_s: float | None = None
    model: str = "dipole"
    scale: float = 1.0

    def inject(self, state: WorldState, rng: np.random.Generator) -> Injection:
        from orbitcal import frames

        t = state.t_utc_s
        if self.model.upper() == "RC":
            from orbitcal.field import get_field

            radius, colat, lon = frames.itrs_to_spherical(state.r_itrs_km)
            b_nec = get_field("RC").b_nec_nt(t, radius, colat, lon)
            b_itrs = frames.nec_to_itrs(b_nec, state.r_itrs_km) * float(self.scale)
        elif self.model == "dipole":
            amp = float(self.amplitude_nt) * float(self.scale) * np.ones(t.shape)
            if self.recovery_time_s:
                amp = amp * np.exp(-(t - t[0]) / float(self.recovery_time_s))
            b_itrs = amp[:, None] * dipole_axis_itrs()
        else:
            raise BadInputError(
                f"external_field model must be 'dipole' or 'RC', not {self.model!r}"
            )
        return Injection(state.itrs_to_body(b_itrs))


@dataclass(frozen=True)
class CrustalFieldEffect(Effect):
    """Lithospheric field of a crustal model (``orbitcal.field``: ``MF7``, ``LCS-1``,
    ``CHAOS-8.1-static``), static in Earth-fixed coordinates, times ``scale``."""

    name: ClassVar[str] = "crustal_field"
    magnitude_params: ClassVar[tuple[str, ...]] = ("scale",)
    model: str = "MF7"
    scale: float = 1.0

    def inject(self, state: WorldState, rng: np.random.Generator) -> Injection:
        from orbitcal import frames
        from orbitcal.field import get_field

        radius, colat, lon = frames.itrs_to_spherical(state.r_itrs_km)
        b_nec = get_field(self.model).b_nec_nt(state.t_utc_s, radius, colat, lon)
        b_itrs = frames.nec_to_itrs(b_nec, state.r_itrs_km) * float(self.scale)
        return Injection(state.itrs_to_body(b_itrs))


@dataclass(frozen=True)
class SunDrivenEffect(Effect):
    """Field organised by the Sun direction in body axes, sunlit only (Swarm's dB_Sun).

    ``dB = ν · P ŝ_body`` with ``ν`` the visible fraction of the solar disc (0 in eclipse) and
    ``P`` a body-fixed 3×3 pattern [nT] (e.g. thermo-electric currents of the solar array).
    """

    name: ClassVar[str] = "sun_driven"
    magnitude_params: ClassVar[tuple[str, ...]] = ("pattern_nt",)
    pattern_nt: tuple[float, ...] = (8.0, -3.0, 2.0, 4.0, 10.0, -5.0, -2.0, 6.0, 12.0)

    def inject(self, state: WorldState, rng: np.random.Generator) -> Injection:
        p = _mat3(self.pattern_nt, "pattern_nt")
        db = state.illumination[:, None] * (state.sun_body_unit @ p.T)
        return Injection(db, info={"sunlit_fraction": float(np.mean(state.illumination > 0.5))})


@dataclass(frozen=True)
class NonlinearityEffect(Effect):
    """Cubic non-linearity of each axis: ``dB_i = k_i B_i³`` (plus optional quadratic)."""

    name: ClassVar[str] = "nonlinearity"
    magnitude_params: ClassVar[tuple[str, ...]] = ("cubic_per_nt2", "quadratic_per_nt")
    cubic_per_nt2: tuple[float, ...] = (1.0e-12, -0.8e-12, 1.2e-12)
    quadratic_per_nt: tuple[float, ...] = (0.0, 0.0, 0.0)

    def inject(self, state: WorldState, rng: np.random.Generator) -> Injection:
        b = state.b_ref_body_nt
        k3 = _vec3(self.cubic_per_nt2, "cubic_per_nt2")
        k2 = _vec3(self.quadratic_per_nt, "quadratic_per_nt")
        return Injection(k3 * b**3 + k2 * b**2)


@dataclass(frozen=True)
class OrbitErrorEffect(Effect):
    """Position error of the operator's orbit: the spacecraft is really elsewhere.

    With ``true_tle`` (text holding a later, better element set of the same spacecraft; from a
    file of many sets the one of this NORAD id nearest the start is used) the true position is
    propagated from it; otherwise the spacecraft is ``along_track_km`` ahead of its
    TLE position (its inertial position at ``t + along_track_km / |v|``, the Earth at ``t``).
    ``dB = R(q) [B(r_true) − B(r_tle)]``
    with the reported (true) attitude. ``info`` records the along-track separation.
    """

    name: ClassVar[str] = "orbit_error"
    magnitude_params: ClassVar[tuple[str, ...]] = ("along_track_km",)
    along_track_km: float = 1.0
    true_tle: str | None = None

    def inject(self, state: WorldState, rng: np.random.Generator) -> Injection:
        from orbitcal import frames

        t = state.t_utc_s
        v = state.v_gcrs_km_s
        speed = np.linalg.norm(v, axis=1)
        if self.true_tle:
            from orbitcal.orbit import select_orbit
            from orbitcal.simulate.state import kinematics

            norad = state.tle.norad_id if state.tle is not None else None
            true_set = select_orbit(
                self.true_tle, norad_id=norad, at_utc_s=float(t[0]), prefer_past=True
            )
            r_true_itrs = kinematics(true_set, state.attitude, t).r_itrs_km
            r_true_gcrs = frames.itrs_to_gcrs(r_true_itrs, t)
        else:
            # Ahead in its orbit at the same time: the inertial position of t + ds/|v|, with the
            # Earth where it is at t (advancing the Earth too would be a time-tag error instead,
            # ~0.46 km/s x cos(lat) of ground-track difference).
            kin = state.kinematics_at(t + float(self.along_track_km) / speed)
            r_true_gcrs = kin.r_gcrs_km
            r_true_itrs = frames.gcrs_to_itrs(r_true_gcrs, t)
        along_km = np.sum((r_true_gcrs - state.r_gcrs_km) * v, axis=1) / speed
        b_true = state.field_body_nt(t, r_itrs_km=r_true_itrs, q_wxyz=state.q_wxyz)
        return Injection(
            b_true - state.b_ref_body_nt,
            info={
                "along_track_km_mean": float(np.mean(along_km)),
                "position_error_km_rms": float(
                    np.sqrt(np.mean(np.sum((r_true_gcrs - state.r_gcrs_km) ** 2, axis=1)))
                ),
            },
        )


@dataclass(frozen=True)
class ParameterDriftEffect(Effect):
    """Bias step (and scale step) at ``step_at_fraction`` of the span, plus a bias trend.

    ``dB = s H(t − t_s) + τ (t − t₀)/86400 + σ ⊙ B H(t − t_s)``.
    """

    name: ClassVar[str] = "parameter_drift"
    magnitude_params: ClassVar[tuple[str, ...]] = ("step_nt", "trend_nt_per_day", "scale_step")
    step_nt: tuple[float, ...] = (15.0, -10.0, 8.0)
    trend_nt_per_day: tuple[float, ...] = (3.0, -2.0, 1.5)
    scale_step: tuple[float, ...] = (0.0, 0.0, 0.0)
    step_at_fraction: float = 0.5

    def inject(self, state: WorldState, rng: np.random.Generator) -> Injection:
        t = state.t_utc_s
        if t.size == 0:
            return Injection(np.zeros((0, 3)))
        t_step = t[0] + float(self.step_at_fraction) * (t[-1] - t[0])
        after = (t >= t_step).astype(np.float64)[:, None]
        days = ((t - t[0]) / 86400.0)[:, None]
        db = (
            _vec3(self.step_nt, "step_nt") * after
            + _vec3(self.trend_nt_per_day, "trend_nt_per_day") * days
            + _vec3(self.scale_step, "scale_step") * state.b_ref_body_nt * after
        )
        return Injection(db, info={"step_utc_s": float(t_step)})


@dataclass(frozen=True)
class FieldAlignedCurrentsEffect(Effect):
    """Auroral field-aligned currents: transverse field at high magnetic latitude.

    Region-1/region-2-like bipolar profile in |magnetic latitude| (peak ``amplitude_nt`` at
    ``center_mlat_deg``, width ``width_deg``, opposite lobe 4° equatorward at 60 %), along magnetic
    east made perpendicular to B, with the dawn/dusk sign reversal (−sin of the magnetic local
    time angle) and a random strength per crossing (0.5–1.5).
    """

    name: ClassVar[str] = "field_aligned_currents"
    magnitude_params: ClassVar[tuple[str, ...]] = ("amplitude_nt",)
    amplitude_nt: float = 300.0
    center_mlat_deg: float = 68.0
    width_deg: float = 2.5

    def inject(self, state: WorldState, rng: np.random.Generator) -> Injection:
        from orbitcal import frames

        r = state.r_itrs_km
        z_dip = dipole_axis_itrs()
        mlat = magnetic_latitude_deg(r)
        a = np.abs(mlat)
        c, w = float(self.center_mlat_deg), float(self.width_deg)
        profile = np.exp(-(((a - c) / w) ** 2)) - 0.6 * np.exp(-(((a - c + 4.0) / w) ** 2))
        # Magnetic local time angle: 0 at noon, +90° at dusk (Sun direction in ITRS ⟂ dipole).
        sun_itrs = frames.gcrs_to_itrs(state.sun_gcrs_km, state.t_utc_s)
        x_sm = sun_itrs - np.outer(sun_itrs @ z_dip, z_dip)
        x_sm /= np.linalg.norm(x_sm, axis=1, keepdims=True)
        y_sm = np.cross(z_dip, x_sm)
        phi = np.arctan2(np.sum(r * y_sm, axis=1), np.sum(r * x_sm, axis=1))
        sign = -np.sin(phi)
        # Random strength per high-latitude crossing.
        high = a > 55.0
        crossing = np.cumsum(np.diff(high.astype(int), prepend=0) == 1)
        strength = rng.uniform(0.5, 1.5, int(crossing.max()) + 1)[crossing]
        east = np.cross(z_dip, r)
        east /= np.maximum(np.linalg.norm(east, axis=1, keepdims=True), 1e-9)
        b_hat = state.b_ref_itrs_nt / np.linalg.norm(state.b_ref_itrs_nt, axis=1, keepdims=True)
        perp = east - np.sum(east * b_hat, axis=1, keepdims=True) * b_hat
        perp /= np.maximum(np.linalg.norm(perp, axis=1, keepdims=True), 1e-9)
        amp = float(self.amplitude_nt) * profile * sign * strength * high
        db_itrs = amp[:, None] * perp
        return Injection(state.itrs_to_body(db_itrs), info={"max_abs_mlat_deg": float(a.max())})


@dataclass(frozen=True)
class AttitudeErrorEffect(Effect):
    """Error of the reported attitude: the sensor sits in a body frame rotated by δ(t).

    ``δ(t)`` is a rotation vector of three sinusoids (periods ``period_s`` × 1, 1.3, 0.7, random
    phases) of amplitude ``amplitude_deg`` plus a constant ``bias_deg``; the true body field is
    ``R(δ)ᵀ B_body`` so ``dB ⟂ B`` (the scalar residual stays clean).
    """

    name: ClassVar[str] = "attitude_error"
    magnitude_params: ClassVar[tuple[str, ...]] = ("amplitude_deg", "bias_deg")
    amplitude_deg: float = 0.05
    period_s: float = 5400.0
    bias_deg: tuple[float, ...] = (0.0, 0.0, 0.0)

    def inject(self, state: WorldState, rng: np.random.Generator) -> Injection:
        from scipy.spatial.transform import Rotation

        t = state.t_utc_s - (state.t_utc_s[0] if state.t_utc_s.size else 0.0)
        phases = rng.uniform(0.0, 2 * np.pi, 3)
        periods = float(self.period_s) * np.array([1.0, 1.3, 0.7])
        rotvec_deg = float(self.amplitude_deg) * np.sin(
            2 * np.pi * t[:, None] / periods + phases
        ) + _vec3(self.bias_deg, "bias_deg")
        rot = Rotation.from_rotvec(np.deg2rad(rotvec_deg))
        b_true = rot.inv().apply(state.b_ref_body_nt) if t.size else np.zeros((0, 3))
        angle = np.linalg.norm(rotvec_deg, axis=1)
        return Injection(
            b_true - state.b_ref_body_nt,
            info={"angle_deg_rms": float(np.sqrt(np.mean(angle**2))) if t.size else 0.0},
        )


#: Effects by CONTRACT section-5 name.
EFFECTS: dict[str, type[Effect]] = {
    cls.name: cls
    for cls in (
        TemperatureEffect,
        MagnetorquerEffect,
        TimeOffsetEffect,
        ExternalFieldEffect,
        CrustalFieldEffect,
        SunDrivenEffect,
        NonlinearityEffect,
        OrbitErrorEffect,
        ParameterDriftEffect,
        FieldAlignedCurrentsEffect,
        AttitudeErrorEffect,
    )
}
EFFECT_NAMES: tuple[str, ...] = tuple(EFFECTS)


def make_effect(name: str, **params: Any) -> Effect:
    """An effect by its contract name with (some of) its parameters.

    Vector parameters take a list, or one number broadcast to every component.
    """
    try:
        cls = EFFECTS[name]
    except KeyError:
        raise BadInputError(
            f"unknown effect {name!r}: use one of {', '.join(EFFECT_NAMES)}"
        ) from None
    known = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(params) - set(known))
    if unknown:
        raise BadInputError(
            f"effect {name!r} has no parameter {unknown[0]!r}; its parameters: {', '.join(known)}"
        )
    coerced: dict[str, Any] = {}
    for key, value in params.items():
        default = known[key].default
        if isinstance(default, tuple):
            arr = np.atleast_1d(np.asarray(value, dtype=np.float64))
            coerced[key] = tuple(float(x) for x in arr)
        else:
            coerced[key] = value
    return cls(**coerced)


def _parse_value(text: str) -> Any:
    text = text.strip()
    if "/" in text:
        return [float(x) for x in text.split("/")]
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    if text.lower() in {"none", "null"}:
        return None
    return text


def parse_effect_spec(spec: str, *, read_file: Callable[[str], str] | None = None) -> Effect:
    """``NAME[:k=v,k=v,...]`` → an effect (the ``--effect`` option of ``orbitcal simulate``).

    Values are numbers, ``a/b/c`` for vectors (or 9 numbers for a 3×3 matrix, row by row), or
    text; ``true_tle=@path`` reads a file through ``read_file``. The reserved key
    ``magnitude=K`` multiplies the effect's size (:meth:`Effect.scaled`), e.g.
    ``time_offset:magnitude=4`` is a 2 s offset.
    """
    name, _, rest = spec.partition(":")
    params: dict[str, Any] = {}
    magnitude = 1.0
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, eq, value = item.partition("=")
        if not eq:
            raise BadInputError(f"effect parameter {item!r} must be written key=value")
        if key.strip() == "magnitude":
            magnitude = float(value)
        elif value.startswith("@") and read_file is not None:
            params[key.strip()] = read_file(value[1:])
        else:
            params[key.strip()] = _parse_value(value)
    effect = make_effect(name.strip(), **params)
    return effect.scaled(magnitude) if magnitude != 1.0 else effect
