"""The CLI surface of CONTRACT section 2: every command exists, answers --help, and starts light."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys

import pytest

from orbitcal.cli import COMMAND_MODULES, build_parser

SERVICE_COMMANDS = ("serve", "worker", "demo")
#: Imported only by the commands that use them (issue 11: instant commands).
HEAVY_MODULES = (
    "torch",
    "matplotlib",
    "chaosmagpy",
    "skyfield",
    "numba",
    "pandas",
    "pyarrow",
    "scipy",
    "fastapi",
    "sqlalchemy",
    "service.app",
)


@pytest.mark.parametrize("name", COMMAND_MODULES)
def test_every_command_module_imports_and_registers(name: str) -> None:
    module = importlib.import_module(f"orbitcal.cli.{name}")
    assert callable(module.register)


def test_contract_commands_are_registered() -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    choices = set(sub.choices)  # type: ignore[arg-type]
    assert {"truth", "calibrate", "apply", "diagnose", "reproduce", "serve"} <= choices
    assert set(SERVICE_COMMANDS) <= choices  # registered by the service's entry points


def _modules_after(code: str) -> list[str]:
    probe = (
        "import sys, json\n"
        + code
        + f"\nprint(json.dumps(sorted(m for m in {HEAVY_MODULES!r} if m in sys.modules)))"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, timeout=120
    )
    return list(json.loads(out.stdout.strip().splitlines()[-1]))


def test_import_orbitcal_is_light() -> None:
    assert _modules_after("import orbitcal") == []


@pytest.mark.parametrize("name", [None, *COMMAND_MODULES, *SERVICE_COMMANDS])
def test_help_imports_nothing_heavy(name: str | None) -> None:
    """``orbitcal --help`` and ``orbitcal X --help`` import none of the heavy packages."""
    argv = ["--help"] if name is None else [name, "--help"]
    code = (
        "import contextlib, io\n"
        "from orbitcal.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    try:\n"
        f"        main({argv!r})\n"
        "    except SystemExit:\n"
        "        pass"
    )
    assert _modules_after(code) == []


def test_serve_help_documents_the_admin_key() -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    text = sub.choices["serve"].format_help()  # type: ignore[index]
    assert "ORBITCAL_ADMIN_KEY" in text
