"""Arguments and input loading shared by the commands that read telemetry (CONTRACT section 2).

Every command that reads telemetry accepts the section-1 formats by extension,
``--attitude-frame GCRS|ITRS`` (default GCRS) and ``--time-scale UTC|TAI|GPS`` (default UTC);
``--tle`` may be left out when the table carries positions.

``--tle`` reads a TLE file (one set, or many sets of many spacecraft) or a CCSDS OMM file (XML,
JSON or CSV); ``--norad ID`` picks the spacecraft and, of its sets, the one nearest in epoch to
the data. Elements further than :data:`orbitcal.orbit.DEFAULT_MAX_AGE_DAYS` (14 days) from any
sample are refused (exit 2) unless ``--allow-stale-elements`` is given.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from orbitcal.orbit import Orbit
    from orbitcal.telemetry import Telemetry

__all__ = [
    "add_field_argument",
    "add_orbit_arguments",
    "add_table_arguments",
    "load_orbit",
    "load_table",
    "read_orbit_file",
]


def add_table_arguments(
    p: argparse.ArgumentParser, *, tle: bool = True, attitude_help: str | None = None
) -> None:
    """Add ``TELEMETRY`` and the options every telemetry-reading command shares."""
    p.add_argument(
        "telemetry", metavar="TELEMETRY", help="telemetry table (.csv/.parquet/.ndjson/.json)"
    )
    if tle:
        add_orbit_arguments(p)
    p.add_argument(
        "--attitude-frame",
        default="GCRS",
        choices=("GCRS", "ITRS"),
        help=attitude_help or "frame the quaternions refer to (default GCRS)",
    )
    p.add_argument(
        "--time-scale",
        default="UTC",
        choices=("UTC", "TAI", "GPS"),
        help="time scale of the table's times (default UTC)",
    )


def add_orbit_arguments(p: argparse.ArgumentParser, *, required: bool = False) -> None:
    """Add ``--tle``, ``--norad`` and ``--allow-stale-elements``."""
    p.add_argument(
        "--tle",
        metavar="TLE",
        required=required,
        help="element sets: a TLE file (one or many sets) or an OMM file (XML, JSON or CSV)"
        + ("" if required else "; needed without r_x,r_y,r_z"),
    )
    p.add_argument(
        "--norad",
        type=int,
        metavar="ID",
        help="NORAD catalogue number when the file holds several spacecraft (of its sets, the "
        "one nearest in epoch to the data is used)",
    )
    p.add_argument(
        "--allow-stale-elements",
        action="store_true",
        help="use elements whose epoch is more than 14 days from the data (refused by default: "
        "SGP4 errors grow by km per day)",
    )


def add_field_argument(p: argparse.ArgumentParser) -> None:
    """Add ``--field NAME`` (default IGRF-14)."""
    p.add_argument(
        "--field",
        default="IGRF-14",
        metavar="NAME",
        help="reference field, terms joined by '+', e.g. IGRF-14, IGRF-13, CHAOS-8.1+LCS-1+RC "
        "(default IGRF-14)",
    )


def load_table(
    args: argparse.Namespace, command: str, *, need_attitude: str | None = None
) -> Telemetry:
    """Read the table, report rejected rows on stderr, and refuse an empty or unusable one.

    ``need_attitude`` is the reason the command needs quaternions (None: it does not).
    """
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
    if need_attitude and tel.q_wxyz is None:
        raise CliError(
            f"{args.telemetry}: no quaternion columns q_w, q_x, q_y, q_z: {need_attitude}"
        )
    return tel


def load_orbit(args: argparse.Namespace, tel: Telemetry) -> Orbit | None:
    """The orbit from ``--tle`` (None when the table carries positions and no TLE is given)."""
    from orbitcal.cli import CliError

    tle = getattr(args, "tle", None)
    if not tle:
        if tel.r_itrs_km is None:
            raise CliError(
                f"{args.telemetry} has no positions (r_x, r_y, r_z): give the spacecraft's --tle"
            )
        return None
    return read_orbit_file(
        tle,
        norad_id=getattr(args, "norad", None),
        span_utc_s=(float(tel.t_utc_s.min()), float(tel.t_utc_s.max())),
        allow_stale=getattr(args, "allow_stale_elements", False),
    )


def read_orbit_file(
    path: str,
    *,
    norad_id: int | None,
    span_utc_s: tuple[float, float],
    allow_stale: bool = False,
    prefer_past: bool = False,
) -> Orbit:
    """The element set for the data from a TLE or OMM file (nearest epoch of that spacecraft).

    Raises
    ------
    CliError
        The file cannot be read.
    orbitcal.orbit.OrbitError
        Malformed or unphysical elements, several spacecraft without ``--norad``, or elements
        further than 14 days from the data without ``allow_stale``.
    """
    from orbitcal.cli import CliError
    from orbitcal.orbit import check_epoch_near, read_orbits, select_orbit

    try:
        text = Path(path).read_text()
    except (OSError, UnicodeDecodeError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise CliError(f"cannot read element file {path}: {reason}") from None
    orbit = select_orbit(
        read_orbits(text, path=path),
        norad_id=norad_id,
        at_utc_s=span_utc_s,
        prefer_past=prefer_past,
    )
    if not allow_stale:
        check_epoch_near(orbit, list(span_utc_s))
    return orbit
