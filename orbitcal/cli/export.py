"""``orbitcal export CAL.json --format F --out PATH``: a calibration for a ground tool or on
board (CONTRACT sections 2 and 7).

Formats: ``json`` (the document), ``xtce`` (Yamcs), ``yamcs-push`` (set a running Yamcs's
coefficients; ``--out`` gets the report), ``yamcs-instance`` (a folder Yamcs 5.12 runs as it
is, docs/yamcs.md), ``cosmos`` (each a folder, or a zip when ``PATH`` ends in ``.zip``),
``c-header``, ``polynomial``. ``--telemetry`` (with ``--tle`` when the table has no positions)
measures what the reduced forms drop on the table's held-out later blocks and writes it into
the files. The Yamcs password is read from ``ORBITCAL_YAMCS_PASSWORD``, never from the
command line.
"""

from __future__ import annotations

import argparse
import json
import os

from orbitcal.cli._inputs import add_orbit_arguments

__all__ = ["register", "run"]

_FORMATS = ("json", "xtce", "yamcs-push", "yamcs-instance", "cosmos", "c-header", "polynomial")


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``export`` sub-command."""
    p = sub.add_parser(
        "export",
        help="export a calibration for Yamcs/XTCE, COSMOS, on-board C or polynomials",
        description="Export a calibration document (CONTRACT section 4) for a ground tool or "
        "on board (section 7).",
    )
    p.add_argument("calibration", metavar="CAL.json", help="calibration document")
    p.add_argument("--format", default="json", choices=_FORMATS, help="export format")
    p.add_argument(
        "--out",
        required=True,
        metavar="PATH",
        help="output file (cosmos, yamcs-instance: a folder, or a zip when PATH ends in .zip; "
        "yamcs-push: the report)",
    )
    p.add_argument(
        "--raw-names",
        metavar="X,Y,Z",
        help="raw axis parameters [nT] (default MAG_X_RAW,MAG_Y_RAW,MAG_Z_RAW)",
    )
    p.add_argument(
        "--cal-names",
        metavar="X,Y,Z",
        help="calibrated axis parameters [nT] (default MAG_X_CAL,MAG_Y_CAL,MAG_Z_CAL)",
    )
    p.add_argument(
        "--hk-names",
        metavar="COLUMN=NAME,...",
        help="housekeeping parameters by table column, e.g. temperature=MAG_TEMP,mtq_x=MTQ_X "
        "(a column left out keeps its name upper-cased)",
    )
    p.add_argument(
        "--space-system",
        default="MAGCAL",
        metavar="NAME",
        help="XTCE SpaceSystem name and coefficient prefix (default MAGCAL)",
    )
    p.add_argument(
        "--cosmos-target",
        default="INST",
        metavar="TARGET",
        help="cosmos: default target variable (default INST)",
    )
    p.add_argument(
        "--cosmos-packet",
        default="MAG",
        metavar="PACKET",
        help="cosmos: default packet variable (default MAG)",
    )
    g = p.add_argument_group("held-out loss of the reduced forms")
    g.add_argument(
        "--telemetry",
        metavar="TABLE",
        help="telemetry table whose later blocks measure what reduced forms drop",
    )
    g.add_argument(
        "--time-scale",
        default="UTC",
        choices=("UTC", "TAI", "GPS"),
        help="time scale of the table's times (default UTC)",
    )
    g.add_argument(
        "--attitude-frame",
        choices=("GCRS", "ITRS"),
        help="frame of the table's quaternions (default: the calibration's)",
    )
    add_orbit_arguments(g)
    y = p.add_argument_group("Yamcs (xtce, yamcs-instance, yamcs-push)")
    y.add_argument(
        "--yamcs-inputs",
        default="local",
        choices=("local", "telemetered", "qualified"),
        help="how the raw and housekeeping inputs reach Yamcs: local parameters settable over "
        "REST (default), telemetered ones fed by a parameter link, or qualified references "
        "(--raw-names /MYSAT/MAG_X,...) to the mission MDB's parameters",
    )
    y.add_argument("--yamcs-url", metavar="URL", help="Yamcs base URL, e.g. http://host:8090")
    y.add_argument(
        "--yamcs-instance",
        metavar="NAME",
        help="Yamcs instance (yamcs-push: required; yamcs-instance: its name, default magcal)",
    )
    y.add_argument(
        "--yamcs-processor",
        default="realtime",
        metavar="NAME",
        help="Yamcs processor (default realtime)",
    )
    y.add_argument(
        "--yamcs-user", metavar="USER", help="Yamcs user (password from ORBITCAL_YAMCS_PASSWORD)"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``orbitcal export``."""
    from orbitcal.calibrate.document import read_document
    from orbitcal.cli import CliError
    from orbitcal.export import (
        DEFAULT_CAL_NAMES,
        DEFAULT_RAW_NAMES,
        ExportOptions,
        YamcsTarget,
        export,
        held_out_loss,
        parse_hk_names,
        parse_names,
    )

    try:
        doc = read_document(args.calibration)
    except OSError as exc:
        raise CliError(f"cannot read {args.calibration}: {exc.strerror}") from None
    loss = None
    if args.telemetry:
        from orbitcal.cli._inputs import load_orbit, load_table

        tel = load_table(args, "export")
        orbit = None if tel.r_itrs_km is not None and not args.tle else load_orbit(args, tel)
        loss = held_out_loss(doc, tel, orbit=orbit, attitude_frame=args.attitude_frame)
    yamcs = None
    if args.format == "yamcs-push":
        if not args.yamcs_url or not args.yamcs_instance:
            raise CliError("yamcs-push needs --yamcs-url and --yamcs-instance")
        yamcs = YamcsTarget(
            url=args.yamcs_url,
            instance=args.yamcs_instance,
            processor=args.yamcs_processor,
            username=args.yamcs_user,
            password=os.environ.get("ORBITCAL_YAMCS_PASSWORD"),
        )
    options = ExportOptions(
        format=args.format,
        raw_names=parse_names(args.raw_names, DEFAULT_RAW_NAMES, "--raw-names"),
        cal_names=parse_names(args.cal_names, DEFAULT_CAL_NAMES, "--cal-names"),
        hk_names=parse_hk_names(args.hk_names),
        space_system=args.space_system,
        loss=loss,
        yamcs=yamcs,
        cosmos_target=args.cosmos_target,
        cosmos_packet=args.cosmos_packet,
        yamcs_inputs=args.yamcs_inputs,
        yamcs_instance=args.yamcs_instance or "magcal",
    )
    result = export(doc, options)
    written = result.write(args.out)
    info = result.info
    what = f"{len(written)} files under {args.out}" if len(written) > 1 else str(written[0])
    print(
        f"export: {info['spacecraft']} version {info['version']} ({info['method']}) as "
        f"{args.format}, document SHA-256 {info['document_sha256'][:16]}…; wrote {what}"
    )
    if loss is not None:
        print(
            f"export: held-out RMS on {loss.n_samples} samples: whole calibration "
            f"{loss.full_rms_nt:.4f} nT, affine part {loss.affine_rms_nt:.4f} nT, diagonal "
            f"polynomials {loss.diagonal_rms_nt:.4f} nT"
        )
    if args.format == "yamcs-instance":
        from orbitcal.export.yamcs_instance import START_COMMAND

        print(f"export: start it with: cd {args.out} && {START_COMMAND}")
    if loss is None and args.format == "polynomial" and result.content is not None:
        # the file's own notes: what the polynomials drop, and what is known of the loss
        for note in json.loads(result.content)["notes"]:
            print(f"export: {note}")
    if result.report is not None:
        print(
            f"export: set {result.report['n_set']} parameters on {args.yamcs_url} "
            f"({args.yamcs_instance}/{args.yamcs_processor}); previous version "
            f"{result.report['previous_version']}"
        )
    return 0
