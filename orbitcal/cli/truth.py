"""``orbitcal truth``: the reference field at each telemetry sample, in the body frame.

``orbitcal truth TELEMETRY --tle TLE [--attitude-frame GCRS|ITRS] [--field NAME]
[--time-scale UTC|TAI|GPS] --out OUT.csv`` writes ``time,b_x,b_y,b_z`` [nT] (CONTRACT section 2).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from orbitcal.field import DEFAULT_FIELD

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``truth`` sub-command."""
    p = sub.add_parser(
        "truth",
        help="reference field at each sample in the body frame (CSV time,b_x,b_y,b_z, nT)",
        description=(
            "Compute the reference field (default IGRF-14) at every telemetry sample, each at its "
            "own time, rotated into the body frame with the table's quaternions."
        ),
    )
    p.add_argument(
        "telemetry", metavar="TELEMETRY", help="telemetry table (.csv/.parquet/.ndjson/.json)"
    )
    p.add_argument("--tle", metavar="TLE", help="file with one TLE (needed without r_x,r_y,r_z)")
    p.add_argument(
        "--attitude-frame",
        default="GCRS",
        choices=("GCRS", "ITRS"),
        help="frame the quaternions refer to (default GCRS)",
    )
    p.add_argument(
        "--field",
        default=DEFAULT_FIELD,
        metavar="NAME",
        help="field model, terms joined by '+', e.g. IGRF-14, IGRF-13, CHAOS-8.1+LCS-1+RC "
        "(default IGRF-14)",
    )
    p.add_argument(
        "--time-scale",
        default="UTC",
        choices=("UTC", "TAI", "GPS"),
        help="time scale of the table's times (default UTC)",
    )
    p.add_argument("--out", required=True, metavar="OUT.csv", help="output CSV")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``orbitcal truth``; bad input raises CliError or a typed ValueError (exit 2)."""
    from orbitcal.cli import CliError
    from orbitcal.field import get_field
    from orbitcal.telemetry import read_telemetry, write_field_csv
    from orbitcal.truth import truth_for_telemetry

    field = get_field(args.field)  # unknown names fail before any reading
    result = read_telemetry(args.telemetry, time_scale=args.time_scale)
    tel = result.telemetry
    if result.rejected:
        first = result.rejected[0]
        print(
            f"orbitcal truth: {len(result.rejected)} rows rejected (first: row {first.row}: "
            f"{first.reason}); the {len(tel)} valid rows are used",
            file=sys.stderr,
        )
    if len(tel) == 0:
        raise CliError(f"{args.telemetry}: no valid rows")
    if tel.q_wxyz is None:
        raise CliError(
            f"{args.telemetry}: no quaternion columns q_w, q_x, q_y, q_z: the body-frame field "
            "needs the attitude"
        )
    orbit = None
    if tel.r_itrs_km is None:
        if not args.tle:
            raise CliError(
                f"{args.telemetry} has no positions (r_x, r_y, r_z): give the spacecraft's --tle"
            )
        from orbitcal.orbit import Orbit

        orbit = Orbit.from_tle(Path(args.tle).read_text())
    truth = truth_for_telemetry(tel, orbit=orbit, attitude_frame=args.attitude_frame, field=field)
    assert truth.b_body_nt is not None
    write_field_csv(args.out, truth.t_utc_s, truth.b_body_nt)
    return 0
