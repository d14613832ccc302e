"""Synthetic worlds: a spacecraft on a real TLE, an attitude profile, a sensor and injected effects.

A world is built in this order (all seeded from one ``np.random.Generator``):

1. sample times ``t_utc_s`` (start + k · cadence);
2. orbit (SGP4 on the TLE) → ``r_itrs_km``, ``r_gcrs_km``, ``v_gcrs_km_s``; attitude profile →
   ``q_wxyz`` (GCRS);
3. reference field in body axes, ``b_ref_body_nt = orbitcal.truth.truth_body_nt(...)``
   (IGRF-14 by default) — what a calibration is compared with;
4. Sun (analytic) and the conical Earth shadow → illumination 0…1;
5. housekeeping that every spacecraft has, whether or not an effect couples to it: a sensor
   temperature following the orbital thermal cycle (±10 °C sunlit/eclipse, first-order lag),
   magnetorquer dipole commands from a gated B-dot-like law and a body-mounted solar array
   current (``hk_sa_current_a``);
6. each effect's field-equivalent disturbance ``dB_body_nt`` (see :mod:`orbitcal.simulate.effects`);
7. the sensor, Wang 2020 eq. 1: ``b_raw = A (b_ref + Σ dB) + B_0 + noise``.

The telemetry carries the sample times, ``b_raw``, the attitude quaternions and the housekeeping
(positions only when asked: by default they come from the TLE, CONTRACT section 1). The ground
truth — sensor parameters, effects with their parameters and RMS, the injected field per sample —
is kept in :class:`World` and written next to the telemetry and the TLE by :meth:`World.write`.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from orbitcal import frames
from orbitcal.arrays import FloatArray
from orbitcal.errors import BadInputError
from orbitcal.metrics import norm_rms_nt
from orbitcal.orbit import Orbit, read_tle_sets, select_orbit
from orbitcal.sensor import SensorModel
from orbitcal.simulate.attitude_profiles import AttitudeProfile, NadirLVLH, Tumbling
from orbitcal.simulate.state import (
    Housekeeping,
    Kinematics,
    WorldState,
    kinematics,
    orbital_thermal_cycle_c,
)
from orbitcal.telemetry import Telemetry, format_from_path, write_telemetry
from orbitcal.timescales import utc_s_to_iso

if TYPE_CHECKING:  # pragma: no cover
    from orbitcal.simulate.effects import Effect

__all__ = [
    "Housekeeping",
    "Kinematics",
    "TleSet",
    "World",
    "WorldFiles",
    "WorldOptions",
    "WorldState",
    "kinematics",
    "orbital_thermal_cycle_c",
    "parse_tles",
    "read_world",
    "select_tle",
    "simulate_measured_field",
    "simulate_world",
]

_UNIX_EPOCH_JD = 2_440_587.5


# --- element sets: read by orbitcal.orbit (one TLE/OMM parser) ---------------------------------

#: An element set of the simulator is an :class:`orbitcal.orbit.Orbit` (name kept for callers).
TleSet = Orbit


def parse_tles(text: str) -> list[Orbit]:
    """Every element set in a TLE file: :func:`orbitcal.orbit.read_tle_sets`."""
    return read_tle_sets(text)


def select_tle(text: str, *, norad_id: int | None = None, at_utc_s: float | None = None) -> Orbit:
    """The set of one spacecraft in effect at a time: the latest epoch not after ``at_utc_s``
    (else the nearest); :func:`orbitcal.orbit.select_orbit` with ``prefer_past``.

    Parameters
    ----------
    text : str
        TLE file contents, possibly many sets of many spacecraft.
    norad_id : int or None
        Catalogue number; required when the file holds more than one spacecraft.
    at_utc_s : float or None
        Time the world starts, POSIX seconds of UTC [s]; None picks the latest epoch.
    """
    return select_orbit(read_tle_sets(text), norad_id=norad_id, at_utc_s=at_utc_s, prefer_past=True)


# --- the world -----------------------------------------------------------------------------------


def _jsonable(x: Any) -> Any:
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    return x


@dataclass
class World:
    """A simulated world: telemetry plus its ground truth.

    Attributes
    ----------
    telemetry : Telemetry
        What the spacecraft downlinks (CONTRACT section 1).
    tle : TleSet or None
        The element set the operator has (the one written with the world); None for a world
        built on measured positions (:func:`simulate_measured_field`).
    sensor : SensorModel
        True sensor parameters.
    effects : list of Effect
        Injected effects.
    b_ref_body_nt : ndarray, shape (N, 3)
        Reference field in body axes (the calibration target) [nT].
    injected_body_nt : dict of str to ndarray, shape (N, 3)
        Each effect's field-equivalent disturbance in body axes [nT].
    truth : dict
        JSON-ready ground truth (see :meth:`write`).
    """

    telemetry: Telemetry
    tle: TleSet | None
    sensor: SensorModel
    effects: list[Effect]
    b_ref_body_nt: FloatArray
    injected_body_nt: dict[str, FloatArray]
    truth: dict[str, Any] = field(default_factory=dict)

    @property
    def b_true_body_nt(self) -> FloatArray:
        """The field the sensor saw: reference plus every injected disturbance [nT]."""
        total = self.b_ref_body_nt.copy()
        for db in self.injected_body_nt.values():
            total = total + db
        return total

    def write(self, directory: str | Path, *, fmt: str = "csv") -> dict[str, Path]:
        """Write the world as a directory.

        Files: ``telemetry.<fmt>`` (CONTRACT section 1), ``spacecraft.tle`` (the operator's
        element set), ``truth.json`` (sensor, effects, parameters, RMS, attitude, field, seed) and
        ``truth_samples.parquet`` (per sample: time, reference field and each injected field in
        body axes [nT]).

        Returns
        -------
        dict of str to Path
            ``telemetry``, ``tle``, ``truth``, ``truth_samples``.
        """
        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        paths = {
            "telemetry": out / f"telemetry.{fmt}",
            "tle": out / "spacecraft.tle",
            "truth": out / "truth.json",
            "truth_samples": out / "truth_samples.parquet",
        }
        format_from_path(paths["telemetry"])  # validates fmt
        write_telemetry(paths["telemetry"], self.telemetry)
        if self.tle is not None:
            paths["tle"].write_text(self.tle.text)
        else:
            del paths["tle"]
        truth = dict(self.truth)
        truth["files"] = {k: p.name for k, p in paths.items()}
        paths["truth"].write_text(json.dumps(_jsonable(truth), indent=2) + "\n")
        samples: dict[str, Any] = {"time": utc_s_to_iso(self.telemetry.t_utc_s)}
        for j, axis in enumerate("xyz"):
            samples[f"b_ref_{axis}"] = self.b_ref_body_nt[:, j]
        for name, db in self.injected_body_nt.items():
            for j, axis in enumerate("xyz"):
                samples[f"db_{name}_{axis}"] = db[:, j]
        pd.DataFrame(samples).to_parquet(paths["truth_samples"], index=False)
        return paths


@dataclass(frozen=True)
class WorldFiles:
    """A world read back from its directory (see :meth:`World.write`)."""

    telemetry: Telemetry
    tle_text: str  # "" for a measured-field world (positions in the telemetry)
    truth: dict[str, Any]
    samples: pd.DataFrame


def read_world(directory: str | Path) -> WorldFiles:
    """Read a world directory written by :meth:`World.write` (telemetry validated as usual).

    Raises
    ------
    ValueError
        When ``truth.json`` is missing or the telemetry has rejected rows (a world never has).
    """
    from orbitcal.telemetry import read_telemetry

    root = Path(directory)
    truth_path = root / "truth.json"
    if not truth_path.is_file():
        raise BadInputError(f"{root} is not a world directory (no truth.json)")
    truth = json.loads(truth_path.read_text())
    files = truth.get("files", {})
    res = read_telemetry(root / files.get("telemetry", "telemetry.csv"))
    if res.rejected:
        raise BadInputError(
            f"{root}: {len(res.rejected)} telemetry rows rejected: {res.rejected[0]}"
        )
    samples = pd.read_parquet(root / files.get("truth_samples", "truth_samples.parquet"))
    tle_path = root / files.get("tle", "spacecraft.tle")
    tle_text = tle_path.read_text() if tle_path.is_file() else ""
    return WorldFiles(res.telemetry, tle_text, truth, samples)


def _anchor(profile: AttitudeProfile, t0_utc_s: float) -> AttitudeProfile:
    """Fix a tumbling profile's reference time to the world's start, so that re-evaluating the
    attitude at other times (time_offset) continues the same motion instead of restarting it."""
    if isinstance(profile, Tumbling) and profile.t0_utc_s is None:
        return dataclasses.replace(profile, t0_utc_s=t0_utc_s)
    return profile


def _inject(
    state: WorldState, effects: Sequence[Effect], rngs: Sequence[np.random.Generator], n: int
) -> tuple[dict[str, FloatArray], list[dict[str, Any]], dict[str, FloatArray]]:
    """Each effect's field ``(N, 3)`` [nT, body] by name, its truth record, and the housekeeping
    channels the effects add (in the effects' order, one child generator each)."""
    injected: dict[str, FloatArray] = {}
    effect_truth: list[dict[str, Any]] = []
    extra_hk: dict[str, FloatArray] = {}
    for effect, erng in zip(effects, rngs, strict=True):
        inj = effect.inject(state, erng)
        key = effect.name if effect.name not in injected else f"{effect.name}_{len(injected)}"
        injected[key] = np.asarray(inj.db_body_nt, dtype=np.float64)
        extra_hk.update(inj.hk)
        effect_truth.append(
            {
                "name": effect.name,
                "params": _jsonable(effect.params),
                "rms_nt": norm_rms_nt(injected[key]),
                "axis_rms_nt": np.sqrt(np.mean(injected[key] ** 2, axis=0)).tolist(),
                "max_nt": float(np.max(np.linalg.norm(injected[key], axis=1))) if n else 0.0,
                **({"info": _jsonable(inj.info)} if inj.info else {}),
            }
        )
    return injected, effect_truth, extra_hk


def _measure(
    b_true_nt: FloatArray,
    t_utc_s: FloatArray,
    sensor: SensorModel,
    sensor_after: SensorModel | None,
    change_utc_s: float | None,
    noise_rng: np.random.Generator,
) -> FloatArray:
    """Raw readings ``(N, 3)`` [nT, sensor axes] of the true field, through ``sensor`` (and
    ``sensor_after`` from ``change_utc_s`` on) with one draw of white noise."""
    # Wang 2020 eq. 1 (the same draws as SensorModel.measure: normal = σ · standard normal).
    z = noise_rng.standard_normal(b_true_nt.shape)
    b_raw: FloatArray = sensor.measure_noiseless(b_true_nt) + sensor.noise_std_nt * z
    if sensor_after is not None and change_utc_s is not None:
        after = t_utc_s >= change_utc_s
        b_raw[after] = (
            sensor_after.measure_noiseless(b_true_nt[after]) + sensor_after.noise_std_nt * z[after]
        )
    return b_raw


def _sensor_change_truth(after: SensorModel | None, change_utc_s: float | None) -> dict[str, Any]:
    if after is None or change_utc_s is None:
        return {}
    return {
        "sensor_after": after.to_dict(),
        "linear_after": after.linear,
        "sensor_change": utc_s_to_iso([change_utc_s])[0],
    }


@dataclass(frozen=True)
class WorldOptions:
    """What :func:`simulate_world` simulates (one typed object instead of a keyword list).

    Attributes
    ----------
    start_utc_s : float
        First sample, POSIX seconds of UTC [s].
    duration_s, cadence_s : float
        Span and sampling interval [s].
    attitude : AttitudeProfile or None
        Default nadir pointing (LVLH).
    sensor : SensorModel or None
        Default ``SensorModel.random(rng=...)`` (Wang 2020-like spread, σ = 2 nT).
    sensor_after, sensor_change_utc_s : SensorModel, float, optional
        A change of the sensor parameters in orbit (Wang 2020 section 5, eq. 17): samples at or
        after ``sensor_change_utc_s`` [POSIX s] are measured with ``sensor_after``.
    effects : sequence of Effect
        Disturbances to inject (CONTRACT section-5 names).
    field : str
        Reference field name (``orbitcal.field.get_field``), default ``"IGRF-14"``.
    housekeeping : Housekeeping or None
        Thermal cycle and magnetorquer command parameters.
    include_position : bool
        Add ``r_x, r_y, r_z`` (ITRS, from the TLE) to the telemetry.
    norad_id : int or None
        Spacecraft to pick when ``tle`` is a file's text.
    seed : int or None
        Recorded in the truth (the caller made ``rng`` from it).
    """

    start_utc_s: float
    duration_s: float
    cadence_s: float
    attitude: AttitudeProfile | None = None
    sensor: SensorModel | None = None
    sensor_after: SensorModel | None = None
    sensor_change_utc_s: float | None = None
    effects: Sequence[Effect] = ()
    field: str = "IGRF-14"
    housekeeping: Housekeeping | None = None
    include_position: bool = False
    norad_id: int | None = None
    seed: int | None = None


def simulate_world(
    tle: TleSet | str,
    *,
    rng: np.random.Generator,
    options: WorldOptions | None = None,
    **keywords: Any,
) -> World:
    """Simulate a spacecraft's magnetometer telemetry with known ground truth.

    Parameters
    ----------
    tle : TleSet or str
        The element set (or a TLE file's text: the set nearest ``start_utc_s`` is chosen).
    rng : numpy.random.Generator
        The one source of randomness (child generators are spawned for the sensor, the
        housekeeping and each effect in order, so results are reproducible).
    options : WorldOptions
        What to simulate.
    **keywords
        Instead of ``options``: its fields as keywords (``start_utc_s=..., duration_s=...``).

    Returns
    -------
    World
    """
    if options is not None and keywords:
        raise TypeError("simulate_world() takes options or keywords, not both")
    o = options if options is not None else WorldOptions(**keywords)
    n = _checked_sample_count(o)
    effects = o.effects
    tle_set = (
        tle
        if isinstance(tle, TleSet)
        else select_tle(tle, norad_id=o.norad_id, at_utc_s=o.start_utc_s)
    )
    profile: AttitudeProfile = o.attitude if o.attitude is not None else NadirLVLH()
    housekeeping = o.housekeeping or Housekeeping()
    children = rng.spawn(3 + len(effects))
    sensor_rng, hk_rng, noise_rng, effect_rngs = children[0], children[1], children[2], children[3:]
    sensor = o.sensor or SensorModel.random(rng=sensor_rng)

    t = np.asarray(o.start_utc_s + np.arange(n) * o.cadence_s, dtype=np.float64)
    profile = _anchor(profile, float(t[0]))
    kin = kinematics(tle_set, profile, t)
    state = WorldState(
        tle=tle_set,
        attitude=profile,
        field=o.field,
        kin=kin,
        housekeeping=housekeeping,
        hk_rng=hk_rng,
    )

    injected, effect_truth, extra_hk = _inject(state, effects, effect_rngs, n)

    b_true = state.b_ref_body_nt.copy()
    for db in injected.values():
        b_true += db
    b_raw = _measure(b_true, t, sensor, o.sensor_after, o.sensor_change_utc_s, noise_rng)

    temperature = extra_hk.pop("temperature", state.temperature_c)
    hk = dict(state.hk)
    hk.update({k: np.asarray(v) for k, v in extra_hk.items() if k.startswith("hk_")})
    telemetry = Telemetry(
        t_utc_s=t,
        b_raw_nt=b_raw,
        q_wxyz=kin.q_wxyz,
        r_itrs_km=kin.r_itrs_km if o.include_position else None,
        temperature_c=np.asarray(temperature, dtype=np.float64),
        mtq_am2=state.mtq_am2,
        hk=hk,
    )
    truth = _world_truth(o, tle_set, state, sensor, effect_truth, n)
    return World(
        telemetry=telemetry,
        tle=tle_set,
        sensor=sensor,
        effects=list(effects),
        b_ref_body_nt=state.b_ref_body_nt,
        injected_body_nt=injected,
        truth=truth,
    )


def _checked_sample_count(o: WorldOptions) -> int:
    """The number of samples ``o`` asks for; BadInputError for a span, cadence or sensor change
    that makes no world."""
    if o.duration_s <= 0 or o.cadence_s <= 0:
        raise BadInputError("duration_s and cadence_s must be positive")
    n = int(np.floor(o.duration_s / o.cadence_s + 1e-9))
    if n < 2:
        raise BadInputError(f"{n} sample(s): make duration_s at least twice cadence_s")
    if (o.sensor_after is None) != (o.sensor_change_utc_s is None):
        raise BadInputError("give both sensor_after and sensor_change_utc_s, or neither")
    return n


def _world_truth(
    o: WorldOptions,
    tle_set: TleSet,
    state: WorldState,
    sensor: SensorModel,
    effect_truth: list[dict[str, Any]],
    n: int,
) -> dict[str, Any]:
    """The world's ground truth: the element set, span, attitude, sensor, effects injected."""
    t = state.kin.t_utc_s
    return {
        "spacecraft": str(tle_set.norad_id),
        "tle": {"name": tle_set.name, "line1": tle_set.line1, "line2": tle_set.line2},
        "start": utc_s_to_iso([o.start_utc_s])[0],
        "end": utc_s_to_iso([t[-1]])[0] if n else None,
        "n": n,
        "cadence_s": o.cadence_s,
        "attitude": state.attitude.to_dict(),
        "attitude_frame": "GCRS",
        "reference_field": o.field,
        "sensor": sensor.to_dict(),
        "linear": sensor.linear,
        **_sensor_change_truth(o.sensor_after, o.sensor_change_utc_s),
        "effects": effect_truth,
        "verdict": effect_truth[0]["name"]
        if len(effect_truth) == 1
        else ("none" if not effect_truth else "multiple"),
        "housekeeping": _jsonable(state.housekeeping.__dict__),
        "eclipse_fraction": float(np.mean(state.illumination < 0.5)) if n else 0.0,
        "b_ref_rms_nt": norm_rms_nt(state.b_ref_body_nt),
        "seed": o.seed,
    }


def simulate_measured_field(
    t_utc_s: npt.ArrayLike,
    r_itrs_km: npt.ArrayLike,
    b_nec_nt: npt.ArrayLike,
    *,
    rng: np.random.Generator,
    attitude: AttitudeProfile | None = None,
    sensor: SensorModel | None = None,
    field: str = "IGRF-14",
    housekeeping: Housekeeping | None = None,
    source: str = "",
    seed: int | None = None,
) -> World:
    """Put a real measured field through a synthetic attitude and sensor.

    E.g. the Swarm A storm pass: its measured ``B_NEC`` at its own positions becomes raw
    magnetometer telemetry of a spacecraft with the given attitude profile, so the whole gap between
    the measurement and the reference field (external, crustal, auroral currents) is real.

    Parameters
    ----------
    t_utc_s : array_like, shape (N,)
        Sample times, POSIX seconds of UTC [s] (ascending).
    r_itrs_km : array_like, shape (N, 3)
        Positions, ITRS [km]; written to the telemetry (``r_x, r_y, r_z``).
    b_nec_nt : array_like, shape (N, 3)
        Measured field, geocentric North, East, Centre [nT].
    rng : numpy.random.Generator
        Seeded source (sensor, housekeeping, noise).
    attitude : AttitudeProfile or None
        Default nadir pointing; velocities for it come from differentiating the positions.
    sensor : SensorModel or None
        Default ``SensorModel.random``.
    field : str
        Reference field for ``b_ref_body_nt`` (the calibration target), default IGRF-14.
    source : str
        Where the measurement came from (recorded in the truth).

    Returns
    -------
    World
        ``injected_body_nt["measured_minus_reference"]`` holds measured − reference in body axes;
        ``tle`` is None.
    """
    t, r_itrs, b_nec = _checked_track(t_utc_s, r_itrs_km, b_nec_nt)
    profile: AttitudeProfile = attitude if attitude is not None else NadirLVLH()
    housekeeping = housekeeping or Housekeeping()
    sensor_rng, hk_rng, noise_rng = rng.spawn(3)
    sensor = sensor or SensorModel.random(rng=sensor_rng)
    profile = _anchor(profile, float(t[0]))
    r_gcrs = frames.itrs_to_gcrs(r_itrs, t)
    v_gcrs = np.gradient(r_gcrs, t, axis=0)
    kin = Kinematics(t, r_itrs, r_gcrs, v_gcrs, profile.q_wxyz(t, r_gcrs, v_gcrs))
    state = WorldState(
        tle=None, attitude=profile, field=field, kin=kin, housekeeping=housekeeping, hk_rng=hk_rng
    )
    b_meas_body = state.itrs_to_body(frames.nec_to_itrs(b_nec, r_itrs))
    gap = b_meas_body - state.b_ref_body_nt
    telemetry = Telemetry(
        t_utc_s=t,
        b_raw_nt=sensor.measure(b_meas_body, rng=noise_rng),
        q_wxyz=kin.q_wxyz,
        r_itrs_km=r_itrs,
        temperature_c=state.temperature_c,
        mtq_am2=state.mtq_am2,
        hk=dict(state.hk),
    )
    return World(
        telemetry=telemetry,
        tle=None,
        sensor=sensor,
        effects=[],
        b_ref_body_nt=state.b_ref_body_nt,
        injected_body_nt={"measured_minus_reference": gap},
        truth=_measured_truth(state, sensor, gap, source=source, seed=seed),
    )


def _checked_track(
    t_utc_s: npt.ArrayLike, r_itrs_km: npt.ArrayLike, b_nec_nt: npt.ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Times, positions and measured field as float arrays; BadInputError for shapes that do
    not match or times not strictly ascending."""
    t = np.asarray(t_utc_s, dtype=np.float64)
    r_itrs = np.asarray(r_itrs_km, dtype=np.float64)
    b_nec = np.asarray(b_nec_nt, dtype=np.float64)
    if t.ndim != 1 or t.size < 2 or r_itrs.shape != (t.size, 3) or b_nec.shape != (t.size, 3):
        raise BadInputError("need t (N,), r_itrs_km (N, 3) and b_nec_nt (N, 3) with N ≥ 2")
    if np.any(np.diff(t) <= 0):
        raise BadInputError("times must be strictly ascending")
    return t, r_itrs, b_nec


def _measured_truth(
    state: WorldState, sensor: SensorModel, gap: FloatArray, *, source: str, seed: int | None
) -> dict[str, Any]:
    """The ground truth of a measured field put through a synthetic attitude and sensor: the
    gap measured - reference is its one effect."""
    t = state.kin.t_utc_s
    return {
        "spacecraft": source or "measured",
        "source": source,
        "start": utc_s_to_iso([t[0]])[0],
        "end": utc_s_to_iso([t[-1]])[0],
        "n": int(t.size),
        "attitude": state.attitude.to_dict(),
        "attitude_frame": "GCRS",
        "reference_field": state.field,
        "sensor": sensor.to_dict(),
        "linear": sensor.linear,
        "effects": [
            {
                "name": "measured_minus_reference",
                "params": {},
                "rms_nt": norm_rms_nt(gap),
                "axis_rms_nt": np.sqrt(np.mean(gap**2, axis=0)).tolist(),
                "max_nt": float(np.max(np.linalg.norm(gap, axis=1))),
            }
        ],
        "verdict": "measured",
        "housekeeping": _jsonable(state.housekeeping.__dict__),
        "eclipse_fraction": float(np.mean(state.illumination < 0.5)),
        "b_ref_rms_nt": norm_rms_nt(state.b_ref_body_nt),
        "seed": seed,
    }
