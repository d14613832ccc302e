"""``orbitcal ingest``: mission files → the contract's telemetry table (CONTRACT section 2).

``orbitcal ingest gracefo PATH... --out TABLE`` reads GRACE-FO Level-1B RL04 ASCII files (MAG1B,
GNV1B, SCA1B, optionally IHK1B; files or directories); ``orbitcal ingest swarm FILE --out TABLE``
reads a Swarm MAGx_LR_1B CDF or a VirES export (CSV, CDF, NetCDF-4). The table's format follows
the extension of ``TABLE``; times are UTC, the attitude frame GCRS. A summary of what was read,
kept, dropped, flagged and where the gaps are is printed (``--summary-json`` writes it as JSON).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["register", "run_gracefo", "run_swarm"]


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``ingest`` sub-command and its ``gracefo`` / ``swarm`` sub-commands."""
    p = sub.add_parser(
        "ingest",
        help="GRACE-FO Level-1B or Swarm files -> a telemetry table (UTC, GCRS attitude)",
        description="Read a mission's published files into the contract's telemetry table.",
    )
    missions = p.add_subparsers(dest="mission", required=True, metavar="MISSION")
    g = missions.add_parser(
        "gracefo",
        help="GRACE-FO Level-1B RL04 ASCII: MAG1B + GNV1B + SCA1B (+ IHK1B temperatures)",
        description=(
            "Join MAG1B (raw platform magnetometer, torquer currents), GNV1B (GNSS positions) and "
            "SCA1B (star-camera attitude) on time, inside every product's span, into a table: "
            "b_* nT in the satellite frame, q_* GCRS, r_* km ITRS, hk_torque*_ma currents."
        ),
    )
    g.add_argument("paths", nargs="+", metavar="PATH", help="Level-1B files or directories")
    g.add_argument("--out", required=True, metavar="TABLE", help=".csv, .parquet, .ndjson or .json")
    g.add_argument(
        "--temperature-sensor",
        metavar="ID",
        help="IHK1B temperature sensor id whose value fills the 'temperature' column",
    )
    g.add_argument(
        "--no-temperatures",
        action="store_true",
        help="leave the IHK1B temperature channels out of the table",
    )
    g.add_argument(
        "--every-s",
        type=float,
        metavar="S",
        help="keep one MAG1B record per S seconds (e.g. 10 for 0.1 Hz; default: all, 2 Hz)",
    )
    g.add_argument("--summary-json", metavar="FILE", help="also write the summary as JSON")
    g.set_defaults(func=run_gracefo)
    s = missions.add_parser(
        "swarm",
        help="Swarm MAGx_LR_1B CDF or VirES export (CSV, CDF, NetCDF-4)",
        description=(
            "Read B_VFM with q_NEC_CRF (instrument frame) or B_NEC (NEC frame as the body) with "
            "positions into a table with GCRS quaternions."
        ),
    )
    s.add_argument("file", metavar="FILE", help=".cdf, .csv, .nc or .nc4")
    s.add_argument("--out", required=True, metavar="TABLE", help=".csv, .parquet, .ndjson or .json")
    s.add_argument(
        "--field",
        choices=("B_VFM", "B_NEC"),
        help="which field to take (default: B_VFM when the file has it with q_NEC_CRF)",
    )
    s.add_argument("--summary-json", metavar="FILE", help="also write the summary as JSON")
    s.set_defaults(func=run_swarm)


def _report(result: object, args: argparse.Namespace) -> int:
    from orbitcal.ingest import IngestResult

    assert isinstance(result, IngestResult)
    for line in result.summary.lines():
        print(f"ingest: {line}")
    print(f"ingest: wrote {args.out}")
    if args.summary_json:
        Path(args.summary_json).write_text(json.dumps(result.to_json(), indent=2) + "\n")
    return 0


def run_gracefo(args: argparse.Namespace) -> int:
    """Execute ``orbitcal ingest gracefo``."""
    from orbitcal.ingest import GraceFOOptions, ingest_gracefo

    options = GraceFOOptions(
        temperatures=not args.no_temperatures,
        temperature_sensor=args.temperature_sensor,
        every_s=args.every_s,
    )
    return _report(ingest_gracefo(args.paths, out=args.out, options=options), args)


def run_swarm(args: argparse.Namespace) -> int:
    """Execute ``orbitcal ingest swarm``."""
    from orbitcal.ingest import SwarmOptions, ingest_swarm

    return _report(
        ingest_swarm(args.file, out=args.out, options=SwarmOptions(field=args.field)), args
    )
