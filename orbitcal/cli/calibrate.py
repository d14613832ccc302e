"""``orbitcal calibrate``: fit a calibration and write its CONTRACT section-4 document.

``orbitcal calibrate TELEMETRY --tle TLE [--method NAME] --out CAL.json`` with
``--attitude-frame GCRS|ITRS``, ``--time-scale UTC|TAI|GPS``, ``--field NAME``; ``--tle`` may be
left out when the table carries positions. Long (iterative) fits show a rich progress line on
stderr.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from orbitcal.cli._inputs import add_field_argument, add_table_arguments, load_orbit, load_table

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``calibrate`` sub-command."""
    from orbitcal.calibrate import DEFAULT_METHOD, METHODS
    from orbitcal.calibrate.holdout import HOLDOUT_FRACTION

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
    add_table_arguments(p)
    add_field_argument(p)
    p.add_argument(
        "--method",
        default=DEFAULT_METHOD,
        metavar="NAME",
        help=f"calibration method (default {DEFAULT_METHOD}): {', '.join(METHODS)}",
    )
    p.add_argument("--out", required=True, metavar="CAL.json", help="output document")
    p.add_argument(
        "--holdout-fraction",
        type=float,
        default=HOLDOUT_FRACTION,
        metavar="F",
        help="share of the latest samples held out for metrics.holdout_rms_nt (default "
        f"{HOLDOUT_FRACTION:g}, as on every surface)",
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


def run(args: argparse.Namespace) -> int:
    """Execute ``orbitcal calibrate``."""
    import numpy as np

    from orbitcal.calibrate import METHODS
    from orbitcal.calibrate.document import write_document
    from orbitcal.cli import CliError
    from orbitcal.pipeline import calibrate_telemetry

    if args.method not in METHODS:
        raise CliError(f"unknown method {args.method!r}; known: {', '.join(METHODS)}")
    tel = load_table(args, "calibrate")
    orbit = load_orbit(args, tel)
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
    print(f"{summary_line(doc)}; wrote {args.out}")
    return 0


def summary_line(doc: dict[str, Any]) -> str:
    """``"linear: 16.213 nT held out (the last 25 % of 2500 samples), 8.1x the noise of 2.0 nT;
    fit 15.9 nT on 1875"``: the document's held-out RMS beside the noise it is measured against."""
    m = doc["metrics"]
    n = int(m["n_fit"] + m["n_holdout"])
    line = (
        f"{doc['method']}: {m['holdout_rms_nt']:.3f} nT held out (RMS over the last "
        f"{100 * m['holdout_fraction']:g} % of {n} samples: {int(m['n_holdout'])})"
    )
    noise = m.get("holdout_noise_nt")
    if noise is not None and noise == noise and noise > 0:
        line += f", {m['holdout_rms_nt'] / noise:.1f}\u00d7 the noise of {noise:.1f} nT"
    return line + f"; fit {m['train_rms_nt']:.3f} nT on {int(m['n_fit'])}"
