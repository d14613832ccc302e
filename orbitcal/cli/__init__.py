"""The ``orbitcal`` command: one module per sub-command, each exposing ``register(subparsers)``.

A sub-command module defines ``register(sub: argparse._SubParsersAction) -> None`` which adds
its parser and sets ``func=<callable(args) -> int>`` as default. The library's commands are the
modules of :data:`COMMAND_MODULES`; other installed packages add theirs through the entry-point
group ``orbitcal.commands`` (the service's ``serve``, ``worker`` and ``demo``: the library never
imports the service). ``register`` functions import nothing heavy, so ``orbitcal --help`` and
``orbitcal X --help`` answer at once; each command imports what it needs when it runs.

Errors: bad input exits non-zero with a one-line reason on stderr (CONTRACT section 2); the exit
status comes from :attr:`orbitcal.errors.OrbitcalError.exit_code`, mapped in one place
(:func:`exit_code_for`). Warnings print as one line each (:func:`_one_line_warning`).
"""

from __future__ import annotations

import argparse
import errno
import importlib
import sys
import warnings
from collections.abc import Callable, Sequence
from importlib.metadata import entry_points
from typing import Any

from orbitcal import __version__
from orbitcal.errors import BadInputError, OrbitcalError

__all__ = [
    "COMMAND_MODULES",
    "ENTRY_POINT_GROUP",
    "EXIT_INTERRUPTED",
    "CliError",
    "Interrupted",
    "build_parser",
    "exit_code_for",
    "main",
]

# Module names under orbitcal.cli, in help order.
COMMAND_MODULES: tuple[str, ...] = (
    "truth",
    "simulate",
    "calibrate",
    "apply",
    "export",
    "reproduce",
    "diagnose",
    "bench",
    "data",
    "ingest",
)

#: Entry-point group through which other packages add sub-commands (``name = "module:register"``).
ENTRY_POINT_GROUP = "orbitcal.commands"


class CliError(BadInputError):
    """Bad input or a failed precondition of a command: one line on stderr, exit status 2."""


def _plugin_commands() -> list[tuple[str, Callable[[Any], None]]]:
    """``(name, register)`` of the installed ``orbitcal.commands`` entry points, in name order."""
    found = []
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        if ep.name in COMMAND_MODULES:
            continue  # the library's own commands cannot be replaced
        found.append((ep.name, ep.load()))
    # The service's commands in the order a newcomer meets them.
    order = {"serve": 0, "worker": 1, "demo": 2}
    found.sort(key=lambda item: (order.get(item[0], len(order)), item[0]))
    return found


def build_parser() -> argparse.ArgumentParser:
    """The full ``orbitcal`` parser: the library's commands, then the installed plugins'."""
    parser = argparse.ArgumentParser(
        prog="orbitcal",
        description="On-orbit magnetometer calibration and sim-to-real gap diagnosis.",
    )
    parser.add_argument("--version", action="version", version=f"orbitcal {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(f"orbitcal.cli.{name}").register(sub)
    for _, register in _plugin_commands():
        register(sub)
    return parser


def exit_code_for(exc: BaseException) -> int | None:
    """The exit status for an error a command raised, or None when it is a bug (re-raised).

    The one place where errors become exit codes: an :class:`~orbitcal.errors.OrbitcalError`
    carries its own ``exit_code`` (bad input, orbit problems and model ranges 2, not enough
    data 3, stale auxiliary tables 4, conflicts 5); an unreadable file (``OSError``) is bad
    input, 2; so are the ``ValueError``s of code written before the error tree.
    """
    if isinstance(exc, OrbitcalError):
        return int(exc.exit_code)
    if isinstance(exc, OSError | ValueError | KeyError):
        return BadInputError.exit_code
    return None


#: errno values that mean the storage is full, and how the CLI names each.
_STORAGE_FULL = {
    errno.ENOSPC: "the disk is full",
    errno.EDQUOT: "the disk quota is exhausted",
    errno.EFBIG: "the file-size limit (ulimit -f) is reached",
}


def _describe(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.errno in _STORAGE_FULL:
        where = f" {exc.filename}" if exc.filename is not None else ""
        return f"cannot write{where}: {_STORAGE_FULL[exc.errno]} ({exc.strerror or exc})"
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        return f"cannot read {exc.filename}: {exc.strerror}"
    text = str(exc) if not isinstance(exc, KeyError) else str(exc.args[0] if exc.args else exc)
    return " ".join(text.split())  # one line


def _one_line_warning(command: str) -> Callable[..., str]:
    """A ``warnings.formatwarning`` giving ``orbitcal CMD: warning: <message>`` on one line.

    Only the text printed on stderr changes: warnings recorded by callers (``pytest.warns``,
    ``catch_warnings(record=True)``) are untouched.
    """

    def format_warning(
        message: Warning | str,
        category: type[Warning],
        filename: str,
        lineno: int,
        line: str | None = None,
    ) -> str:
        text = " ".join(str(message).split())
        return f"orbitcal {command}: warning: {text}\n"

    return format_warning


def _subparser(parser: argparse.ArgumentParser, command: str) -> argparse.ArgumentParser:
    """The parser of sub-command ``command``."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            found: argparse.ArgumentParser = action.choices[command]
            return found
    return parser


def unknown_arguments_message(parser: argparse.ArgumentParser, extra: Sequence[str]) -> str:
    """``unrecognized arguments: …``, with the option meant for each unknown ``-x``/``--xyz``
    when one of ``parser``'s options is close (difflib)."""
    import difflib

    options = [o for a in parser._actions for o in a.option_strings]
    hints = []
    for token in extra:
        if not token.startswith("-"):
            continue
        flag = token.split("=", 1)[0]
        close = difflib.get_close_matches(flag, options, n=1, cutoff=0.6)
        if close:
            hints.append(f"{flag}: did you mean {close[0]}?")
    text = "unrecognized arguments: " + " ".join(extra)
    return text + (" (" + "; ".join(hints) + ")" if hints else "")


#: Exit status after Ctrl-C (128 + SIGINT), as shells report it.
EXIT_INTERRUPTED = 130


class Interrupted(KeyboardInterrupt):
    """Ctrl-C in a command that saved what it finished; the message says where."""


class _SigintSeen:
    """A SIGINT handler that raises ``KeyboardInterrupt`` (as Python's own) and remembers it.

    An extension module interrupted while it initialises (numpy, torch) may turn the
    ``KeyboardInterrupt`` into ``ImportError: initialization failed``: :func:`main` reads such an
    error as the interrupt it is when this handler has seen one.
    """

    def __init__(self) -> None:
        self.seen = False

    def __call__(self, signum: int, frame: Any) -> None:
        self.seen = True
        raise KeyboardInterrupt


def _interrupted(command: str, exc: BaseException | None) -> int:
    note = str(exc) if isinstance(exc, Interrupted) and str(exc) else "nothing saved"
    print(f"orbitcal {command}: interrupted (Ctrl-C); {note}", file=sys.stderr)
    return EXIT_INTERRUPTED


def main(argv: Sequence[str] | None = None) -> int:
    """Run one ``orbitcal`` command; Ctrl-C anywhere (imports included) gives one line and 130."""
    import signal

    sigint = _SigintSeen()
    try:
        previous_handler = signal.signal(signal.SIGINT, sigint)
    except ValueError:  # not the main thread (a test calling main in a worker): leave it
        previous_handler = None
    command = "orbitcal"
    try:
        parser = build_parser()
        args, extra = parser.parse_known_args(argv)
        command = args.command
        return _run(parser, args, extra)
    except KeyboardInterrupt as exc:
        return _interrupted(command, exc)
    except ImportError:
        if sigint.seen:
            return _interrupted(command, None)
        raise
    finally:
        if previous_handler is not None:
            signal.signal(signal.SIGINT, previous_handler)


def _run(parser: argparse.ArgumentParser, args: argparse.Namespace, extra: list[str]) -> int:
    if extra:
        # the sub-command's usage and the flag meant, not the top-level usage
        sub = _subparser(parser, args.command)
        sub.error(unknown_arguments_message(sub, extra))
    previous = warnings.formatwarning
    warnings.formatwarning = _one_line_warning(args.command)
    try:
        return int(args.func(args) or 0)
    except Exception as exc:
        code = exit_code_for(exc)
        if code is None:
            raise
        print(f"orbitcal {args.command}: {_describe(exc)}", file=sys.stderr)
        return code
    finally:
        warnings.formatwarning = previous


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
