"""``orbitcal diagnose``: where the sim-to-real gap lies and which unmodelled effect causes it.

``orbitcal diagnose TELEMETRY --tle TLE --out REPORT.json [--html REPORT.html]
[--attitude-frame GCRS|ITRS] [--time-scale UTC|TAI|GPS] [--field NAME] [--calibration CAL.json]
[--engine rules|model]``
writes the CONTRACT section-5 report (and optionally a self-contained HTML page with plots).
``--calibration`` takes the calibration in service as a prior on the 12 parameters.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from orbitcal.cli._inputs import add_field_argument, add_table_arguments, load_orbit, load_table
from orbitcal.diagnose.options import DiagnosisOptions

_DEFAULTS = DiagnosisOptions()

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
        default=_DEFAULTS.prior_sigma_matrix,
        metavar="S",
        help="prior standard deviation of each matrix element "
        f"(default {_DEFAULTS.prior_sigma_matrix:g})",
    )
    p.add_argument(
        "--prior-sigma-offset",
        type=float,
        default=_DEFAULTS.prior_sigma_offset_nt,
        metavar="NT",
        help="prior standard deviation of each offset in nT "
        f"(default {_DEFAULTS.prior_sigma_offset_nt:g})",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=_DEFAULTS.seed,
        help=f"seed of the learned model (default {_DEFAULTS.seed})",
    )
    p.add_argument(
        "--engine",
        choices=("rules", "model"),
        default=_DEFAULTS.model.engine,
        help="which engine makes the verdict: the held-out rules or the model core "
        "(probabilities and the confirmation come from the model core under both; "
        f"default {_DEFAULTS.model.engine})",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``orbitcal diagnose``; bad input raises CliError or an OrbitcalError (exit != 0)."""
    from orbitcal.diagnose.api import diagnose
    from orbitcal.diagnose.html_report import report_html
    from orbitcal.diagnose.options import DiagnosisOptions, ModelOptions
    from orbitcal.field import get_field
    from orbitcal.memory import release_freed_arrays, trim_heap

    release_freed_arrays()
    get_field(args.field)  # unknown names fail before any reading
    options = DiagnosisOptions(
        field=args.field,
        attitude_frame=args.attitude_frame,
        prior_sigma_matrix=args.prior_sigma_matrix,
        prior_sigma_offset_nt=args.prior_sigma_offset,
        seed=args.seed,
        model=ModelOptions(engine=args.engine),
    )
    tel = load_table(
        args,
        "diagnose",
        need_attitude="the diagnosis compares vectors in the body frame and needs the attitude",
    )
    orbit = None if tel.r_itrs_km is not None else load_orbit(args, tel)
    prior = None
    if args.calibration:
        from orbitcal.calibrate.document import read_document

        prior = read_document(args.calibration)
    trim_heap()
    diagnosis = diagnose(tel, orbit=orbit, options=options, prior=prior)
    report = diagnosis.report
    Path(args.out).write_text(report.to_json_text(indent=1) + "\n")
    if args.html:
        Path(args.html).write_text(report_html(report.to_json()))
    split = options.attribution
    print(
        f"verdict: {report.verdict}; held-out RMS {report.baseline_holdout_rms_nt} nT "
        f"-> {report.final_holdout_rms_nt} nT (the diagnosis's own split: the last "
        f"{split.holdout_blocks} of {split.n_blocks} time blocks, not calibrate's hold-out); "
        f"report written to {args.out}" + (f", HTML page to {args.html}" if args.html else "")
    )
    _print_first_screen(report.to_json())
    return 0


def _print_first_screen(document: dict[str, object]) -> None:
    """The report page's first screen as plain lines: size, how sure, what to do next."""
    from orbitcal.diagnose.first_screen import first_screen

    screen = first_screen(document)
    if screen.size:
        print(f"  size: {screen.size.replace('`', '')}")
    for line in screen.how_sure:
        print(f"  how sure: {line}")
    for step in screen.next_steps:
        print(f"  next: {step.replace('`', '')}")
