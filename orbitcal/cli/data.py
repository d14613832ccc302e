"""``orbitcal data``: keep the auxiliary tables current and see what is installed.

``orbitcal data update [--data-dir DIR] [--only KIND ...] [--url KIND=URL ...]`` fetches the
leap-second list, the IERS EOP, the RC index and Kp/Dst, validates each and installs it (a failed
or malformed download keeps the installed table); exit 1 when any kind failed.
``orbitcal data status [--data-dir DIR] [--json]`` shows the table in use per kind and until when it
is valid. Without ``--data-dir`` the directory is ``ORBITCAL_DATA_DIR`` or the user data directory.
"""

from __future__ import annotations

import argparse
import json
import sys

__all__ = ["register", "run_status", "run_update"]

_KINDS = ("leap_seconds", "eop", "rc_index", "kp", "dst")


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``data`` sub-command with ``update`` and ``status``."""
    p = sub.add_parser(
        "data",
        help="update / show the auxiliary tables (leap seconds, EOP, RC index, Kp, Dst)",
        description=(
            "Keep the leap-second list, IERS Earth-orientation parameters, the RC index and "
            "Kp/Dst current in the per-user data directory (ORBITCAL_DATA_DIR or --data-dir)."
        ),
    )
    actions = p.add_subparsers(dest="data_command", required=True, metavar="ACTION")
    up = actions.add_parser("update", help="download, validate and install the tables")
    st = actions.add_parser("status", help="what is installed and until when it is valid")
    for q in (up, st):
        q.add_argument("--data-dir", metavar="DIR", help="data directory (a mirror for offline)")
    up.add_argument(
        "--only", nargs="+", choices=_KINDS, metavar="KIND", help=f"only these: {', '.join(_KINDS)}"
    )
    up.add_argument(
        "--url",
        action="append",
        default=[],
        metavar="KIND=URL",
        help="source for a kind (a mirror; http, https or file URL); repeatable",
    )
    up.add_argument("--timeout", type=float, default=60.0, metavar="S", help="per request [s]")
    up.add_argument("--json", action="store_true", help="print the results as JSON")
    st.add_argument("--json", action="store_true", help="print the status as JSON")
    up.set_defaults(func=run_update)
    st.set_defaults(func=run_status)


def run_update(args: argparse.Namespace) -> int:
    """Execute ``orbitcal data update``."""
    from orbitcal.auxdata import update
    from orbitcal.cli import CliError

    urls: dict[str, str] = {}
    for item in args.url:
        kind, sep, url = item.partition("=")
        if not sep or kind not in _KINDS or not url:
            raise CliError(f"--url {item!r}: write KIND=URL with KIND one of {', '.join(_KINDS)}")
        urls[kind] = url
    results = update(
        directory=args.data_dir, kinds=args.only, urls=urls, timeout_s=float(args.timeout)
    )
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        for r in results:
            print(f"{r['kind']:<13} {r['status']:<9} {r.get('reason', '')}  [{r['url']}]")
    failed = [r["kind"] for r in results if r["status"] == "failed"]
    if failed:
        print(
            f"orbitcal data update: {', '.join(failed)} not updated (the tables in use are kept)",
            file=sys.stderr,
        )
        return 1
    return 0


def run_status(args: argparse.Namespace) -> int:
    """Execute ``orbitcal data status``."""
    from orbitcal.auxdata import status

    doc = status(directory=args.data_dir)
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(f"data directory: {doc['data_dir']}   (now {doc['now']})")
    for kind, entry in doc["tables"].items():
        active = entry["active"]
        if active is None:
            print(f"{kind:<13} none installed (run 'orbitcal data update')")
            continue
        flag = "EXPIRED" if entry["expired"] else "ok"
        fetched = active["retrieved_at"] or "shipped"
        line = (
            f"{kind:<13} {flag:<7} valid until {active['valid_until']}  {active['origin']}: "
            f"{active['file']} ({fetched})"
        )
        if active["predictions_from"]:
            line += f"  predictions from {active['predictions_from']}"
        print(line)
        if entry["problem"]:
            print(f"{'':<13} note: {entry['problem']}")
    return 0
