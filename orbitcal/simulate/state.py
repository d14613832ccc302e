"""What effects see of a simulated world: kinematics, housekeeping and the :class:`WorldState`.

Split from :mod:`orbitcal.simulate.world` so that the effects (:mod:`orbitcal.simulate.effects`)
and the world builder both import this module and neither imports the other: the simulate package's
imports run one way, ``state`` ← ``effects`` ← ``world``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt

from orbitcal import frames
from orbitcal.arrays import FloatArray
from orbitcal.attitude import frame_to_body
from orbitcal.errors import BadInputError, OrbitProblemError
from orbitcal.orbit import Orbit
from orbitcal.simulate.attitude_profiles import AttitudeProfile
from orbitcal.sun import illumination_conical, sun_position_gcrs_km
from orbitcal.truth import reference_field_itrs_nt

__all__ = [
    "Housekeeping",
    "Kinematics",
    "WorldState",
    "kinematics",
    "orbital_thermal_cycle_c",
]


# --- kinematics ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Kinematics:
    """Position, velocity and attitude at a set of times."""

    t_utc_s: FloatArray
    r_itrs_km: FloatArray
    r_gcrs_km: FloatArray
    v_gcrs_km_s: FloatArray
    q_wxyz: FloatArray


def kinematics(tle: Orbit, attitude: AttitudeProfile, t_utc_s: npt.ArrayLike) -> Kinematics:
    """Orbit and attitude at the given times.

    SGP4 through :class:`orbitcal.orbit.Orbit` (TEME, ITRS), TEME → GCRS with
    :func:`orbitcal.frames.teme_to_gcrs` (a slow rotation, so velocities rotate as vectors).

    Raises
    ------
    ValueError
        When SGP4 fails at any sample (stale or decayed elements), naming the first.
    """
    t = np.asarray(t_utc_s, dtype=np.float64)
    eph = tle.propagate(t, max_age_days=None)
    code = np.asarray(eph.error_code)
    bad = np.flatnonzero(code != 0)
    if bad.size:
        raise OrbitProblemError(
            f"SGP4 failed for NORAD {tle.norad_id} at {bad.size} samples (first: sample "
            f"{int(bad[0])}, error code {int(code[bad[0]])}): the TLE is stale or decayed for "
            "these dates"
        )
    r_gcrs = frames.teme_to_gcrs(eph.r_teme_km, t)
    v_gcrs = frames.teme_to_gcrs(eph.v_teme_km_s, t)
    q = attitude.q_wxyz(t, r_gcrs, v_gcrs)
    return Kinematics(t, np.asarray(eph.r_itrs_km, dtype=np.float64), r_gcrs, v_gcrs, q)


# --- housekeeping --------------------------------------------------------------------------------


def _first_order_lag(x: FloatArray, t_s: FloatArray, tau_s: float, y0: float) -> FloatArray:
    """Exact discretisation of ``τ dy/dt = x − y`` for piecewise-constant input."""
    y = np.empty_like(x)
    alpha = 1.0 - np.exp(-np.diff(t_s, prepend=t_s[0]) / tau_s)
    acc = y0
    for k in range(x.size):
        acc += alpha[k] * (x[k] - acc)
        y[k] = acc
    return y


def orbital_thermal_cycle_c(
    t_utc_s: FloatArray,
    illumination: FloatArray,
    r_gcrs_km: FloatArray,
    sun_gcrs_km: FloatArray,
    *,
    mean_c: float = 20.0,
    amplitude_c: float = 11.0,
    tau_s: float = 900.0,
    albedo_c: float = 2.0,
) -> FloatArray:
    """Sensor temperature along the orbit [°C]: sunlit warm, eclipse cold, with thermal lag.

    ``T = mean + amplitude · (2·lag(illumination) − 1) + albedo · max(0, r̂·ŝ)``, the lag a
    first-order filter of time constant ``tau_s`` started at the mean illumination; with ~35 %
    eclipse the swing is about ±10 °C. The albedo term keeps a cycle in eclipse-free orbits.
    """
    y0 = float(np.mean(illumination)) if illumination.size else 1.0
    lagged = _first_order_lag(illumination, t_utc_s, tau_s, y0)
    r_hat = r_gcrs_km / np.linalg.norm(r_gcrs_km, axis=1, keepdims=True)
    s_hat = sun_gcrs_km / np.linalg.norm(sun_gcrs_km, axis=1, keepdims=True)
    subsolar = np.clip(np.sum(r_hat * s_hat, axis=1), 0.0, None)
    return mean_c + amplitude_c * (2.0 * lagged - 1.0) + albedo_c * subsolar


@dataclass(frozen=True)
class Housekeeping:
    """Parameters of the housekeeping every simulated spacecraft reports.

    Attributes
    ----------
    temperature_mean_c, temperature_amplitude_c, temperature_tau_s : float
        Orbital thermal cycle (see :func:`orbital_thermal_cycle_c`) [°C], [°C], [s].
    temperature_noise_c : float
        White noise of the temperature reading [°C].
    mtq_max_am2 : float
        Magnetorquer saturation dipole per axis [A·m²].
    mtq_bdot_scale_nt_s : float
        Field rate at which the B-dot command reaches 76 % of saturation (tanh law) [nT/s].
    mtq_duty : float
        Fraction of time the torquers are enabled (random dwell segments).
    mtq_dwell_s : float
        Mean length of an enabled/disabled segment [s].
    """

    temperature_mean_c: float = 20.0
    temperature_amplitude_c: float = 11.0
    temperature_tau_s: float = 900.0
    temperature_noise_c: float = 0.05
    mtq_max_am2: float = 2.0
    mtq_bdot_scale_nt_s: float = 20.0
    mtq_duty: float = 0.6
    mtq_dwell_s: float = 120.0
    solar_array_normal_body: tuple[float, float, float] = (0.0, 0.0, -1.0)
    solar_array_current_max_a: float = 2.0
    solar_array_noise_a: float = 0.01

    def solar_array_current_a(
        self, illumination: FloatArray, sun_body_unit: FloatArray, *, rng: np.random.Generator
    ) -> FloatArray:
        """Body-mounted solar array current [A] (channel ``hk_sa_current_a``).

        ``I = I_max · ν · max(0, ŝ_body · n̂)`` plus white noise, ``ν`` the visible solar disc.
        """
        n_hat = np.asarray(self.solar_array_normal_body, dtype=np.float64)
        n_hat = n_hat / np.linalg.norm(n_hat)
        cos_inc = np.clip(sun_body_unit @ n_hat, 0.0, None)
        current = self.solar_array_current_max_a * illumination * cos_inc
        return current + rng.normal(0.0, self.solar_array_noise_a, current.shape)

    def mtq_commands_am2(
        self, t_utc_s: FloatArray, b_body_nt: FloatArray, *, rng: np.random.Generator
    ) -> FloatArray:
        """Gated B-dot-like dipole commands in body axes [A·m²], shape (N, 3).

        ``m = −m_max · tanh(Ḃ / Ḃ_scale) · gate + desaturation``: the gate switches on and off in
        random dwell segments (duty ``mtq_duty``) and a slow momentum-dumping dipole (three
        sinusoids of random period 1–5 ks, ≤ 0.3 m_max) decorrelates the commands from Ḃ.
        """
        n = t_utc_s.size
        if n == 0:
            return np.zeros((0, 3))
        b_dot = np.gradient(b_body_nt, t_utc_s, axis=0) if n > 1 else np.zeros_like(b_body_nt)
        bdot_cmd = -self.mtq_max_am2 * np.tanh(b_dot / self.mtq_bdot_scale_nt_s)
        span = float(t_utc_s[-1] - t_utc_s[0]) + 1.0
        n_seg = int(span / self.mtq_dwell_s * 2) + 4
        edges = t_utc_s[0] + np.cumsum(rng.exponential(self.mtq_dwell_s, n_seg))
        states = rng.random(n_seg + 1) < self.mtq_duty
        gate = states[np.searchsorted(edges, t_utc_s)].astype(np.float64)
        periods = rng.uniform(1000.0, 5000.0, (3, 3))
        phases = rng.uniform(0.0, 2 * np.pi, (3, 3))
        dt = (t_utc_s - t_utc_s[0])[:, None, None]
        desat = 0.1 * self.mtq_max_am2 * np.sin(2 * np.pi * dt / periods + phases).sum(axis=2)
        return np.clip(bdot_cmd * gate[:, None] + desat, -self.mtq_max_am2, self.mtq_max_am2)


# --- the world state seen by effects ------------------------------------------------------------


class WorldState:
    """Everything an effect may use to compute its disturbance (read-only by convention).

    Arrays are per sample (N rows). ``b_ref_body_nt`` is the reference field in the body axes of the
    reported attitude; :meth:`field_body_nt` evaluates it anywhere else (other times, positions or
    attitudes) for effects such as time_offset, orbit_error and attitude_error.
    """

    def __init__(
        self,
        *,
        tle: Orbit | None,
        attitude: AttitudeProfile,
        field: str,
        kin: Kinematics,
        housekeeping: Housekeeping,
        hk_rng: np.random.Generator,
    ) -> None:
        self.tle = tle
        self.attitude = attitude
        self.field = field
        self.kin = kin
        self.t_utc_s = kin.t_utc_s
        self.r_itrs_km = kin.r_itrs_km
        self.r_gcrs_km = kin.r_gcrs_km
        self.v_gcrs_km_s = kin.v_gcrs_km_s
        self.q_wxyz = kin.q_wxyz
        self.b_ref_itrs_nt = reference_field_itrs_nt(self.t_utc_s, self.r_itrs_km, field=field)
        self.b_ref_body_nt = self.itrs_to_body(self.b_ref_itrs_nt)
        self.sun_gcrs_km = sun_position_gcrs_km(self.t_utc_s)
        self.illumination = illumination_conical(self.r_gcrs_km, self.sun_gcrs_km)
        self.housekeeping = housekeeping
        temp = orbital_thermal_cycle_c(
            self.t_utc_s,
            self.illumination,
            self.r_gcrs_km,
            self.sun_gcrs_km,
            mean_c=housekeeping.temperature_mean_c,
            amplitude_c=housekeeping.temperature_amplitude_c,
            tau_s=housekeeping.temperature_tau_s,
        )
        self.temperature_c = temp + hk_rng.normal(0.0, housekeeping.temperature_noise_c, temp.size)
        self.mtq_am2 = housekeeping.mtq_commands_am2(self.t_utc_s, self.b_ref_body_nt, rng=hk_rng)
        self.hk: dict[str, FloatArray] = {
            "hk_sa_current_a": housekeeping.solar_array_current_a(
                self.illumination, self.sun_body_unit, rng=hk_rng
            )
        }

    def __len__(self) -> int:
        return int(self.t_utc_s.size)

    @cached_property
    def sun_body_unit(self) -> FloatArray:
        """Unit vector to the Sun in body axes, shape (N, 3)."""
        s = self.sun_gcrs_km - self.r_gcrs_km
        return frame_to_body(s / np.linalg.norm(s, axis=1, keepdims=True), self.q_wxyz)

    def itrs_to_body(
        self,
        v_itrs: FloatArray,
        *,
        t_utc_s: FloatArray | None = None,
        q_wxyz: FloatArray | None = None,
    ) -> FloatArray:
        """Vectors in ITRS → body axes (GCRS attitude ``q_wxyz``, default the world's)."""
        t = self.t_utc_s if t_utc_s is None else t_utc_s
        q = self.q_wxyz if q_wxyz is None else q_wxyz
        return frame_to_body(frames.itrs_to_gcrs(v_itrs, t), q)

    def kinematics_at(self, t_utc_s: FloatArray) -> Kinematics:
        """Orbit and attitude of this world's spacecraft at other times."""
        if self.tle is None:
            raise BadInputError(
                "this world has positions but no orbit (measured-field world): effects that "
                "re-evaluate the orbit (time_offset, orbit_error) need a TLE"
            )
        return kinematics(self.tle, self.attitude, t_utc_s)

    def field_body_nt(
        self,
        t_utc_s: FloatArray,
        *,
        r_itrs_km: FloatArray | None = None,
        q_wxyz: FloatArray | None = None,
        field: str | None = None,
    ) -> FloatArray:
        """Reference field in body axes at any times [nT], shape (N, 3).

        Position and attitude default to the world's orbit and attitude profile at ``t_utc_s``.
        """
        if r_itrs_km is None or q_wxyz is None:
            kin = self.kinematics_at(t_utc_s)
            r_itrs_km = kin.r_itrs_km if r_itrs_km is None else r_itrs_km
            q_wxyz = kin.q_wxyz if q_wxyz is None else q_wxyz
        b_itrs = reference_field_itrs_nt(t_utc_s, r_itrs_km, field=field or self.field)
        return self.itrs_to_body(b_itrs, t_utc_s=t_utc_s, q_wxyz=q_wxyz)
