"""``orbitcal calibrate``: fit a calibration and write its CONTRACT section-4 document.

``orbitcal calibrate TELEMETRY --tle TLE [--method NAME] --out CAL.json`` with
``--attitude-frame GCRS|ITRS``, ``--time-scale UTC|TAI|GPS``, ``--field NAME``; ``--tle`` may be
left out when the table carries positions. Long (iterative) fits show a rich progress line on
stderr.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``calibrate`` sub-command."""
    from orbitcal.calibrate import DEFAULT_METHOD, METHODS

    methods = ", ".join(f"{k} ({v.description})" for k, v in METHODS.items())
    p = sub.add_parser(
        "calibrate",
        help="fit a magnetometer calibration and write its JSON document",
        description=(
            "Fit a calibration on the earlier samples (75 % by default) against the reference "
            "field along the orbit, score it on the later ones, and write the calibration document "
            f"(CONTRACT section 4). Methods: {methods}."
        ),
    )
    p.add_argument(
        "telemetry", metavar="TELEMETRY", help="telemetry table (.csv/.parquet/.ndjson/.json)"
    )
    p.add_argument("--tle", metavar="TLE", help="file with one TLE (needed without r_x,r_y,r_z)")
    p.add_argument(
        "--method",
        default=DEFAULT_METHOD,
        metavar="NAME",
        help=f"calibration method (default {DEFAULT_METHOD}): {', '.join(METHODS)}",
    )
    p.add_argument("--out", required=True, metavar="CAL.json", help="output document")
    p.add_argument(
        "--attitude-frame",
        default="GCRS",
        choices=("GCRS", "ITRS"),
        help="frame the quaternions refer to (default GCRS)",
    )
    p.add_argument(
        "--time-scale",
        default="UTC",
        choices=("UTC", "TAI", "GPS"),
        help="time scale of the table's times (default UTC)",
    )
    p.add_argument(
        "--field", default="IGRF-14", metavar="NAME", help="reference field (default IGRF-14)"
    )
    p.add_argument(
        "--holdout-fraction",
        type=float,
        default=0.25,
        metavar="F",
        help="share of the latest samples held out for metrics.holdout_rms_nt (default 0.25)",
    )
    p.add_argument("--spacecraft", default=None, help="spacecraft id (default: the TLE name)")
    p.add_argument(
        "--cal-version",
        dest="cal_version",
        type=int,
        default=1,
        help="version number written into the document (default 1)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the fit's random start")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.set_defaults(func=run)


def _load(args: argparse.Namespace, command: str) -> tuple[Any, Any]:
    """Read the table (reporting rejected rows) and the orbit when one is needed."""
    from orbitcal.cli import CliError
    from orbitcal.telemetry import read_telemetry

    result = read_telemetry(args.telemetry, time_scale=args.time_scale)
    tel = result.telemetry
    if result.rejected:
        first = result.rejected[0]
        print(
            f"orbitcal {command}: {len(result.rejected)} rows rejected (first: row {first.row}: "
            f"{first.reason}); the {len(tel)} valid rows are used",
            file=sys.stderr,
        )
    if len(tel) == 0:
        raise CliError(f"{args.telemetry}: no valid rows")
    orbit = None
    tle = getattr(args, "tle", None)
    if tle:
        from orbitcal.orbit import Orbit

        try:
            text = Path(tle).read_text()
        except OSError as exc:
            raise CliError(f"cannot read TLE file {tle}: {exc.strerror}") from None
        orbit = Orbit.from_tle(text)
    elif tel.r_itrs_km is None:
        raise CliError(
            f"{args.telemetry} has no positions (r_x, r_y, r_z): give the spacecraft's --tle"
        )
    return tel, orbit


def run(args: argparse.Namespace) -> int:
    """Execute ``orbitcal calibrate``."""
    import numpy as np

    from orbitcal.calibrate import METHODS
    from orbitcal.calibrate.document import write_document
    from orbitcal.cli import CliError
    from orbitcal.pipeline import calibrate_telemetry

    if args.method not in METHODS:
        raise CliError(f"unknown method {args.method!r}; known: {', '.join(METHODS)}")
    tel, orbit = _load(args, "calibrate")
    spacecraft = args.spacecraft or (getattr(orbit, "name", "") or Path(args.telemetry).stem)

    def fit(progress: Any) -> tuple[Any, dict[str, Any]]:
        return calibrate_telemetry(
            tel,
            orbit=orbit,
            method=args.method,
            field=args.field,
            attitude_frame=args.attitude_frame,
            holdout_fraction=args.holdout_fraction,
            rng=np.random.default_rng(args.seed),
            spacecraft=spacecraft,
            version=args.cal_version,
            progress=progress,
        )

    if args.quiet or not METHODS[args.method].name.startswith("lmbp"):
        _, doc = fit(None)
    else:
        from rich.console import Console
        from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

        with Progress(
            SpinnerColumn(),
            TextColumn("[bold]{task.description}"),
            TextColumn("epoch {task.completed:.0f}"),
            TextColumn("{task.fields[mse]}"),
            TimeElapsedColumn(),
            console=Console(stderr=True),
            transient=True,
        ) as bar:
            task = bar.add_task(f"fitting {args.method}", total=None, mse="")

            def progress(epoch: int, mse: float) -> None:
                bar.update(task, completed=epoch, mse=f"mse {mse:.3g} (normalised)")

            _, doc = fit(progress)
    write_document(args.out, doc)
    m = doc["metrics"]
    print(
        f"{doc['method']}: held-out rms {m['holdout_rms_nt']:.3f} nT on {int(m['n_holdout'])} "
        f"later samples (fit rms {m['train_rms_nt']:.3f} nT on {int(m['n_fit'])}); "
        f"wrote {args.out}"
    )
    return 0
