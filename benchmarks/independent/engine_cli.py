"""``orbitcal`` on the command line with the engine chosen: ``DiagnosisOptions.model.engine``.

    python benchmarks/independent/engine_cli.py ENGINE diagnose TABLE --out REPORT.json [...]

runs ``python -m orbitcal diagnose TABLE ...`` exactly as a user does, except that the options
the command line builds reach :func:`orbitcal.diagnose.api.diagnose` with ``engine=ENGINE``
(``rules``: the stepwise, rule-reviewed engine; ``model``: the model-based core of issue 43).
The harness (``run_worlds.py``, ``real_pass.py``) calls it once per engine on the same table.

``DiagnosisOptions`` gains its ``engine`` field with issue 43's core. Without it, ``rules`` runs
the only engine there is (which is the rules) and says so on stderr; any other engine is refused
with a message naming the missing field (:func:`engine_support`).
"""

from __future__ import annotations

import dataclasses
import sys
from typing import Any

ENGINES = ("rules", "model")
ENGINE_FIELD = "engine"


def engine_support() -> bool:
    """Whether the diagnosis options choose an engine (``DiagnosisOptions.model.engine``)."""
    from orbitcal.diagnose import options

    model_options = getattr(options, "ModelOptions", None)
    if model_options is None:
        return False
    return ENGINE_FIELD in {f.name for f in dataclasses.fields(model_options)}


def options_with_engine(options: Any, engine: str) -> Any:
    """``options`` (a ``DiagnosisOptions``) with the engine ``engine``."""
    return dataclasses.replace(
        options, model=dataclasses.replace(options.model, **{ENGINE_FIELD: engine})
    )


def missing_engine_message(engine: str) -> str:
    return (
        f"cannot run the diagnosis with engine={engine!r}: orbitcal.diagnose.options."
        f"ModelOptions has no field {ENGINE_FIELD!r} (issue 43's model-based core is not in "
        "this checkout); only --engine rules runs, as the default engine"
    )


def _with_engine(engine: str) -> None:
    """Make every diagnosis the CLI starts use ``engine``."""
    import orbitcal.diagnose.api as api

    original = api.diagnose

    def diagnose(*args: Any, **kwargs: Any) -> Any:
        options = kwargs.get("options")
        if options is None:
            from orbitcal.diagnose.options import DiagnosisOptions

            options = DiagnosisOptions()
        kwargs["options"] = options_with_engine(options, engine)
        return original(*args, **kwargs)

    api.diagnose = diagnose  # type: ignore[assignment]
    import orbitcal.diagnose as package

    if getattr(package, "diagnose", None) is original:  # a door importing it from the package
        package.diagnose = diagnose  # type: ignore[attr-defined]


def main(argv: list[str]) -> int:
    if len(argv) < 2 or argv[0] not in ENGINES:
        print(__doc__, file=sys.stderr)
        return 2
    engine, rest = argv[0], argv[1:]
    if engine_support():
        _with_engine(engine)
    elif engine == "rules":
        print("engine_cli: no engine option; the default (rules) engine runs", file=sys.stderr)
    else:
        print(missing_engine_message(engine), file=sys.stderr)
        return 2
    from orbitcal.cli import main as cli_main

    return cli_main(rest)


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
