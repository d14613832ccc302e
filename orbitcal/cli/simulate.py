"""``orbitcal simulate``: a synthetic world on a real TLE, written as a directory.

``orbitcal simulate --tle TLE [--norad ID] --start ISO --duration-s S --cadence-s S
--attitude nadir|inertial|tumbling [--effect NAME[:k=v,...]]... [--seed N]
[--format csv|parquet|ndjson|json] --out DIR`` writes ``telemetry.<fmt>``, ``spacecraft.tle``,
``truth.json`` and ``truth_samples.parquet`` (see :meth:`orbitcal.simulate.World.write`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``simulate`` sub-command."""
    from orbitcal.cli._inputs import add_orbit_arguments
    from orbitcal.simulate.effects import EFFECT_NAMES

    p = sub.add_parser(
        "simulate",
        help="simulate magnetometer telemetry on a real TLE with injected effects",
        description=(
            "Simulate a spacecraft on a real TLE with an attitude profile, the Wang 2020 sensor "
            "model and injected effects; write the telemetry, the TLE and the ground truth."
        ),
    )
    add_orbit_arguments(p, required=True)
    p.add_argument("--start", required=True, metavar="ISO", help="first sample, ISO-8601 UTC (Z)")
    p.add_argument("--duration-s", required=True, type=float, metavar="S", help="span [s]")
    p.add_argument("--cadence-s", required=True, type=float, metavar="S", help="sampling [s]")
    p.add_argument(
        "--attitude",
        default="nadir",
        choices=("nadir", "inertial", "tumbling"),
        help="attitude profile (default nadir)",
    )
    p.add_argument(
        "--effect",
        action="append",
        default=[],
        metavar="NAME[:k=v,...]",
        help=f"inject an effect (repeatable): {', '.join(EFFECT_NAMES)}; vectors as a/b/c, "
        "true_tle=@FILE reads a file, magnitude=K scales the default size",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--format",
        default="csv",
        choices=("csv", "parquet", "ndjson", "json"),
        help="telemetry format (default csv)",
    )
    p.add_argument(
        "--field", default="IGRF-14", metavar="NAME", help="reference field (default IGRF-14)"
    )
    p.add_argument(
        "--sensor",
        default="random",
        choices=("random", "wang2020", "ideal"),
        help="sensor parameters: random (seeded), wang2020 (eq. 15) or ideal (default random)",
    )
    p.add_argument(
        "--noise-std-nt", type=float, default=2.0, metavar="NT", help="sensor noise σ [nT]"
    )
    p.add_argument(
        "--sensor-change-at-s",
        type=float,
        metavar="S",
        help="from S seconds after the start the sensor changes as in Wang 2020 (eq. 15 → 17)",
    )
    p.add_argument(
        "--include-position", action="store_true", help="write r_x,r_y,r_z (ITRS km from the TLE)"
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``orbitcal simulate``; bad input raises CliError (exit 2)."""
    import numpy as np

    from orbitcal.cli import CliError
    from orbitcal.cli._inputs import read_orbit_file
    from orbitcal.sensor import SensorModel
    from orbitcal.simulate import attitude_profile, parse_effect_spec, simulate_world
    from orbitcal.timescales import iso_to_utc_s

    try:
        start_utc_s = float(iso_to_utc_s(args.start)[0])
    except ValueError as exc:
        raise CliError(f"--start {args.start!r}: {exc}") from None
    if args.duration_s <= 0 or args.cadence_s <= 0:
        raise CliError("--duration-s and --cadence-s must be positive")
    # The set in effect at the start (the latest not after it), as an operator would have had.
    orbit = read_orbit_file(
        args.tle,
        norad_id=args.norad,
        span_utc_s=(start_utc_s, start_utc_s + args.duration_s),
        allow_stale=args.allow_stale_elements,
        prefer_past=True,
    )
    if args.duration_s / args.cadence_s > 2e7:
        raise CliError("more than 2e7 samples requested: raise --cadence-s or lower --duration-s")
    if args.noise_std_nt < 0:
        raise CliError("--noise-std-nt must be ≥ 0")

    def read_file(path: str) -> str:
        try:
            return Path(path).read_text()
        except OSError as exc:
            raise CliError(f"cannot read {path}: {exc.strerror or exc}") from None

    try:
        effects = [parse_effect_spec(spec, read_file=read_file) for spec in args.effect]
    except (ValueError, TypeError) as exc:
        raise CliError(f"--effect: {exc}") from None

    rng = np.random.default_rng(args.seed)
    sensor: SensorModel
    if args.sensor == "wang2020":
        sensor = SensorModel.from_wang2020_ground(noise_std_nt=args.noise_std_nt)
    elif args.sensor == "ideal":
        sensor = SensorModel(noise_std_nt=args.noise_std_nt)
    else:
        sensor = SensorModel.random(
            rng=np.random.default_rng([args.seed, 1]), noise_std_nt=args.noise_std_nt
        )
    sensor_after = None
    change_utc_s = None
    if args.sensor_change_at_s is not None:
        if not 0 <= args.sensor_change_at_s <= args.duration_s:
            raise CliError("--sensor-change-at-s must lie within the simulated span")
        sensor_after = sensor.with_wang2020_change()
        change_utc_s = start_utc_s + args.sensor_change_at_s
    try:
        world = simulate_world(
            orbit,
            start_utc_s=start_utc_s,
            duration_s=args.duration_s,
            cadence_s=args.cadence_s,
            rng=rng,
            attitude=attitude_profile(args.attitude),
            sensor=sensor,
            sensor_after=sensor_after,
            sensor_change_utc_s=change_utc_s,
            effects=effects,
            field=args.field,
            include_position=args.include_position,
            seed=args.seed,
        )
    except ValueError as exc:
        raise CliError(str(exc)) from None
    paths = world.write(args.out, fmt=args.format)
    names = ", ".join(e["name"] for e in world.truth["effects"]) or "none"
    print(
        f"simulated {len(world.telemetry)} samples of NORAD {world.truth['spacecraft']} "
        f"({args.attitude}, effects: {names}) → {paths['telemetry']}"
    )
    return 0
