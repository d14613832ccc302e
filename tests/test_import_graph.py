"""Imports run one way (issue 13): the library never imports the service, and no cycles.

The graph is drawn from the source by ``tools/import_graph.py`` (every import statement, those
inside functions and under ``TYPE_CHECKING`` included).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

REPO = Path(__file__).resolve().parents[1]


def _tool() -> ModuleType:
    path = REPO / "tools" / "import_graph.py"
    spec = importlib.util.spec_from_file_location("import_graph", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["import_graph"] = module
    spec.loader.exec_module(module)
    return module


def test_the_library_never_imports_the_service() -> None:
    graph = _tool()
    edges = graph.import_edges(REPO)
    assert ("service.commands.serve", "service.app") in edges  # the graph sees real imports
    assert graph.forbidden_edges(edges) == []


def test_no_import_cycles_between_modules() -> None:
    graph = _tool()
    assert graph.cycles(graph.import_edges(REPO)) == []


def test_no_import_cycles_between_packages() -> None:
    graph = _tool()
    assert graph.cycles(graph.package_graph(graph.import_edges(REPO))) == []


def test_the_cycle_finder_finds_a_cycle() -> None:
    graph = _tool()
    found = graph.cycles({("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")})
    assert found == [["a", "b", "c"]]


def test_no_source_line_imports_the_service() -> None:
    offenders = [
        f"{path.relative_to(REPO)}:{k}"
        for path in (REPO / "orbitcal").rglob("*.py")
        for k, line in enumerate(path.read_text().splitlines(), 1)
        if "import service" in line or "from service" in line
    ]
    assert offenders == []
