"""Synthetic worlds with known ground truth: attitude profiles, injectable effects, Wang 2020.

Three layers (STYLE: pure functions → objects holding parameters → a pipeline):
:mod:`~orbitcal.simulate.wang2020` (the paper's scenarios as pure functions),
:mod:`~orbitcal.simulate.attitude_profiles` and :mod:`~orbitcal.simulate.effects` (parameterised
objects), :func:`simulate_world` (the pipeline) returning a :class:`World` that writes itself as a
directory (telemetry, TLE, ``truth.json``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from orbitcal._lazy import lazy_exports

if TYPE_CHECKING:
    from orbitcal.simulate.attitude_profiles import (
        ATTITUDE_PROFILES,
        AttitudeProfile,
        Inertial,
        NadirLVLH,
        Tumbling,
        attitude_profile,
    )
    from orbitcal.simulate.effects import (
        EFFECT_NAMES,
        EFFECTS,
        Effect,
        Injection,
        make_effect,
        parse_effect_spec,
    )
    from orbitcal.simulate.wang2020 import (
        Wang2020Scenario,
        wang2020_ground,
        wang2020_orbit,
        wang2020_time_s,
        wang2020_truth_nt,
    )
    from orbitcal.simulate.world import (
        Housekeeping,
        Kinematics,
        TleSet,
        World,
        WorldFiles,
        WorldOptions,
        WorldState,
        kinematics,
        parse_tles,
        read_world,
        select_tle,
        simulate_measured_field,
        simulate_world,
    )

# Imported on first access: scipy and pandas are heavy, and ``orbitcal simulate --help`` needs
# only the effect names.
_EXPORTS = {
    **dict.fromkeys(
        ("ATTITUDE_PROFILES", "AttitudeProfile", "Inertial", "NadirLVLH", "Tumbling"),
        "orbitcal.simulate.attitude_profiles",
    ),
    "attitude_profile": "orbitcal.simulate.attitude_profiles",
    **dict.fromkeys(
        ("EFFECT_NAMES", "EFFECTS", "Effect", "Injection", "make_effect", "parse_effect_spec"),
        "orbitcal.simulate.effects",
    ),
    **dict.fromkeys(
        (
            "Wang2020Scenario",
            "wang2020_ground",
            "wang2020_orbit",
            "wang2020_time_s",
            "wang2020_truth_nt",
        ),
        "orbitcal.simulate.wang2020",
    ),
    **dict.fromkeys(
        (
            "Housekeeping",
            "Kinematics",
            "TleSet",
            "World",
            "WorldFiles",
            "WorldOptions",
            "WorldState",
            "kinematics",
            "parse_tles",
            "read_world",
            "select_tle",
            "simulate_measured_field",
            "simulate_world",
        ),
        "orbitcal.simulate.world",
    ),
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

__all__ = [
    "ATTITUDE_PROFILES",
    "EFFECTS",
    "EFFECT_NAMES",
    "AttitudeProfile",
    "Effect",
    "Housekeeping",
    "Inertial",
    "Injection",
    "Kinematics",
    "NadirLVLH",
    "TleSet",
    "Tumbling",
    "Wang2020Scenario",
    "World",
    "WorldFiles",
    "WorldOptions",
    "WorldState",
    "attitude_profile",
    "kinematics",
    "make_effect",
    "parse_effect_spec",
    "parse_tles",
    "read_world",
    "select_tle",
    "simulate_measured_field",
    "simulate_world",
    "wang2020_ground",
    "wang2020_orbit",
    "wang2020_time_s",
    "wang2020_truth_nt",
]
