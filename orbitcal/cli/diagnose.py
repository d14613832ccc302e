"""``orbitcal diagnose``: where the sim-to-real gap lies and which unmodelled effect causes it.

``orbitcal diagnose TELEMETRY --tle TLE --out REPORT.json [--html REPORT.html]
[--attitude-frame GCRS|ITRS] [--time-scale UTC|TAI|GPS] [--field NAME] [--calibration CAL.json]``
writes the CONTRACT section-5 report (and optionally a self-contained HTML page with plots).
``--calibration`` takes the calibration in service as a prior on the 12 parameters.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from orbitcal.cli._inputs import add_field_argument, add_table_arguments, load_orbit, load_table
from orbitcal.diagnose.prior import DEFAULT_SIGMA_MATRIX, DEFAULT_SIGMA_OFFSET_NT

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``diagnose`` sub-command."""
    p = sub.add_parser(
        "diagnose",
        help="diagnosis report: which unmodelled effect explains the calibrated residual (JSON)",
        description=(
            "Fit the 12-parameter calibration and every candidate effect on the earlier time "
            "blocks, judge them on the later held-out blocks, and report the verdict, the ranked "
            "effects with their held-out shrink, and where the residual lies (CONTRACT section 5)."
        ),
    )
    add_table_arguments(p)
    add_field_argument(p)
    p.add_argument("--out", required=True, metavar="REPORT.json", help="output report (JSON)")
    p.add_argument("--html", metavar="REPORT.html", help="also write an HTML report with plots")
    p.add_argument(
        "--calibration",
        metavar="CAL.json",
        help=(
            "the calibration in service (section-4 document): a prior on the 12 parameters, "
            "needed on short spans such as a storm pass (widths: --prior-sigma-matrix, "
            "--prior-sigma-offset)"
        ),
    )
    p.add_argument(
        "--prior-sigma-matrix",
        type=float,
        default=DEFAULT_SIGMA_MATRIX,
        metavar="S",
        help=f"prior standard deviation of each matrix element (default {DEFAULT_SIGMA_MATRIX:g})",
    )
    p.add_argument(
        "--prior-sigma-offset",
        type=float,
        default=DEFAULT_SIGMA_OFFSET_NT,
        metavar="NT",
        help=f"prior standard deviation of each offset in nT (default {DEFAULT_SIGMA_OFFSET_NT:g})",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the learned model (default 0)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``orbitcal diagnose``; bad input raises CliError or a typed ValueError (exit 2)."""
    import numpy as np

    from orbitcal.blas import one_blas_thread
    from orbitcal.diagnose.api import diagnose_parts, diagnosis_data
    from orbitcal.diagnose.report import report_html
    from orbitcal.field import get_field
    from orbitcal.memory import release_freed_arrays, trim_heap

    release_freed_arrays()
    get_field(args.field)  # unknown names fail before any reading
    tel = load_table(
        args,
        "diagnose",
        need_attitude="the diagnosis compares vectors in the body frame and needs the attitude",
    )
    orbit = None if tel.r_itrs_km is not None else load_orbit(args, tel)
    prior = None
    if args.calibration:
        from orbitcal.calibrate.document import read_document
        from orbitcal.diagnose.prior import prior_from_document

        prior = prior_from_document(
            read_document(args.calibration),
            sigma_a=args.prior_sigma_matrix,
            sigma_o_nt=args.prior_sigma_offset,
        )
    trim_heap()
    with one_blas_thread():
        data = diagnosis_data(
            tel,
            orbit=orbit,
            field=args.field,
            attitude_frame=args.attitude_frame,
            calibration_prior=prior,
        )
        del tel, orbit  # the diagnosis holds what it needs of them
        trim_heap()
        report, _att = diagnose_parts(data, rng=np.random.default_rng(args.seed))
        Path(args.out).write_text(json.dumps(report, indent=1) + "\n")
        if args.html:
            Path(args.html).write_text(report_html(report))
    print(
        f"verdict: {report['verdict']}; held-out RMS {report['baseline']['holdout_rms_nt']} nT "
        f"-> {report['final']['holdout_rms_nt']} nT; report written to {args.out}"
        + (f", HTML page to {args.html}" if args.html else "")
    )
    return 0
