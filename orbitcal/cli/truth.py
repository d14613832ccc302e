"""``orbitcal truth``: the reference field at each telemetry sample, in the body frame.

``orbitcal truth TELEMETRY --tle TLE [--attitude-frame GCRS|ITRS] [--field NAME]
[--time-scale UTC|TAI|GPS] --out OUT.csv`` writes ``time,b_x,b_y,b_z`` [nT] (CONTRACT section 2).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from orbitcal.cli._inputs import add_field_argument, add_table_arguments, load_orbit, load_table

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
    add_table_arguments(p)
    add_field_argument(p)
    p.add_argument("--out", required=True, metavar="OUT.csv", help="output CSV")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``orbitcal truth``; bad input raises CliError or a typed ValueError (exit 2)."""
    from orbitcal.field import get_field
    from orbitcal.telemetry import write_field_csv
    from orbitcal.truth import truth_for_telemetry

    field = get_field(args.field)  # unknown names fail before any reading
    tel = load_table(args, "truth", need_attitude="the body-frame field needs the attitude")
    orbit = None if tel.r_itrs_km is not None else load_orbit(args, tel)
    truth = truth_for_telemetry(tel, orbit=orbit, attitude_frame=args.attitude_frame, field=field)
    assert truth.b_body_nt is not None
    write_field_csv(args.out, truth.t_utc_s, truth.b_body_nt)
    print(f"truth: {truth_summary(truth.t_utc_s, truth.b_body_nt, field.name)}; wrote {args.out}")
    if truth.eop_status != "observed":  # never silently past the EOP table (issue 12)
        print(f"orbitcal truth: UT1 - UTC is {truth.eop_status} for these dates", file=sys.stderr)
    return 0


def truth_summary(t_utc_s: Any, b_nt: Any, field_name: str) -> str:
    """One line: ``86400 samples FIRST … LAST, IGRF-14, |B| 22102–48390 nT``."""
    import numpy as np

    from orbitcal.timescales import utc_s_to_iso

    n = len(t_utc_s)
    if n == 0:
        return f"0 samples, {field_name}"
    first, last = utc_s_to_iso([float(np.min(t_utc_s)), float(np.max(t_utc_s))])
    norm = np.linalg.norm(np.asarray(b_nt, dtype=np.float64), axis=1)
    return (
        f"{n} samples {first[:19]}Z … {last[:19]}Z, {field_name}, "
        f"|B| {np.nanmin(norm):.0f}–{np.nanmax(norm):.0f} nT"
    )
