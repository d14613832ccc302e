"""The CLI surface of CONTRACT section 2: every command exists and answers --help."""

from __future__ import annotations

import importlib

import pytest

from orbitcal.cli import COMMAND_MODULES, build_parser


@pytest.mark.parametrize("name", COMMAND_MODULES)
def test_every_command_module_imports_and_registers(name: str) -> None:
    module = importlib.import_module(f"orbitcal.cli.{name}")
    assert callable(module.register)


def test_contract_commands_are_registered() -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    choices = set(sub.choices)  # type: ignore[arg-type]
    assert {"truth", "calibrate", "apply", "diagnose", "reproduce", "serve"} <= choices
