"""docker/: this machine cannot build images, so check that the compose file's services run real
``orbitcal`` commands (parsed by the real CLI parser) against PostgreSQL and Redis."""

from __future__ import annotations

from pathlib import Path

import yaml

from orbitcal.cli import build_parser

DOCKER = Path(__file__).resolve().parents[2] / "docker"


def _entrypoint() -> list[str]:
    for line in (DOCKER / "Dockerfile").read_text().splitlines():
        if line.startswith("ENTRYPOINT"):
            return list(yaml.safe_load(line.removeprefix("ENTRYPOINT")))
    raise AssertionError("no ENTRYPOINT in docker/Dockerfile")


def test_compose_services_run_real_cli_commands() -> None:
    compose = yaml.safe_load((DOCKER / "compose.yaml").read_text())
    services = compose["services"]
    assert {"api", "scheduler", "worker", "postgres", "redis"} <= set(services)
    assert _entrypoint() == ["orbitcal"]
    parser = build_parser()
    modules = {}
    for name in ("api", "scheduler", "worker"):
        svc = services[name]
        args = parser.parse_args(svc["command"])  # exits (fails the test) on a bad command
        modules[name] = (args.command, getattr(args, "scheduler", False))
        env = svc["environment"]
        assert env["ORBITCAL_DATABASE_URL"].startswith("postgresql://")
        assert env["ORBITCAL_BROKER_URL"].startswith("redis://redis:")
        assert set(svc["depends_on"]) == {"postgres", "redis"}
    assert modules == {
        "api": ("serve", False),
        "scheduler": ("worker", True),  # the one fleet scheduler
        "worker": ("worker", False),
    }
    api_args = parser.parse_args(services["api"]["command"])
    assert api_args.host == "0.0.0.0" and api_args.job_backend == "celery"
    assert api_args.no_scheduler  # exactly one scheduler per deployment


def test_dockerfile_default_command_is_the_api() -> None:
    text = (DOCKER / "Dockerfile").read_text()
    cmd_line = next(line for line in text.splitlines() if line.startswith("CMD"))
    args = build_parser().parse_args(yaml.safe_load(cmd_line.removeprefix("CMD")))
    assert args.command == "serve" and args.port == 8000
    assert "torch==2.13.0" in text and "download.pytorch.org/whl/cpu" in text
