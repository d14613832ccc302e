"""The ``orbitcal`` command: one module per sub-command, each exposing ``register(subparsers)``.

A sub-command module defines ``register(sub: argparse._SubParsersAction) -> None`` which adds
its parser and sets ``func=<callable(args) -> int>`` as default. Bad input exits non-zero with a
one-line reason on stderr (CONTRACT section 2).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from orbitcal import __version__

# Module names under orbitcal.cli, in help order.
COMMAND_MODULES: tuple[str, ...] = (
    "truth",
    "simulate",
    "calibrate",
    "apply",
    "reproduce",
    "diagnose",
    "bench",
    "serve",
    "worker",
    "demo",
)


class CliError(Exception):
    """Bad input or a failed precondition: printed as one line on stderr, exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="orbitcal",
        description="On-orbit magnetometer calibration and sim-to-real gap diagnosis.",
    )
    parser.add_argument("--version", action="version", version=f"orbitcal {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(f"orbitcal.cli.{name}")
        except ModuleNotFoundError as exc:
            # Only while a command is being written; tests/test_cli_surface.py requires every one.
            if exc.name != f"orbitcal.cli.{name}":
                raise
            continue
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except CliError as exc:
        print(f"orbitcal {args.command}: {exc}", file=sys.stderr)
        return 2
    except (ValueError, OSError, KeyError) as exc:
        # Library errors are typed ValueError/OSError subclasses carrying a full sentence.
        print(f"orbitcal {args.command}: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
