"""``orbitcal apply CAL.json TELEMETRY --out OUT.csv``: the calibrated field (CONTRACT section 2).

Writes ``time,b_x,b_y,b_z``: the calibration of the document applied to each valid row, body frame,
nT. Methods with housekeeping inputs read the same columns (temperature, ``mtq_*``, ``hk_*``) from
the table.
"""

from __future__ import annotations

import argparse

from orbitcal.cli._inputs import add_table_arguments, load_table

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``apply`` sub-command."""
    p = sub.add_parser(
        "apply",
        help="apply a calibration document to telemetry (CSV time,b_x,b_y,b_z, nT)",
        description="Apply a calibration document (CONTRACT section 4) to a telemetry table.",
    )
    p.add_argument("calibration", metavar="CAL.json", help="calibration document")
    add_table_arguments(
        p,
        tle=False,
        attitude_help="accepted for symmetry with the other commands; apply needs no attitude",
    )
    p.add_argument("--out", required=True, metavar="OUT.csv", help="output CSV")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``orbitcal apply``."""
    from orbitcal.calibrate.document import read_document
    from orbitcal.cli import CliError
    from orbitcal.pipeline import apply_document
    from orbitcal.telemetry import write_field_csv

    try:
        doc = read_document(args.calibration)
    except OSError as exc:
        raise CliError(f"cannot read {args.calibration}: {exc.strerror}") from None
    tel = load_table(args, "apply")
    from orbitcal.plausibility import check_table, table_radius_km

    check_table(tel.b_raw_nt, r_km=table_radius_km(tel))  # Tesla, Gauss: named, not applied
    b_cal = apply_document(doc, tel)
    write_field_csv(args.out, tel.t_utc_s, b_cal)
    import numpy as np

    raw_norm = np.linalg.norm(tel.b_raw_nt, axis=1)
    cal_norm = np.linalg.norm(b_cal, axis=1)
    print(
        f"apply: {doc.get('method', '?')} version {doc.get('version', '?')} on {len(tel)} samples; "
        f"mean |B| {np.nanmean(raw_norm):.0f} nT raw -> {np.nanmean(cal_norm):.0f} nT calibrated; "
        f"wrote {args.out}"
    )
    return 0
