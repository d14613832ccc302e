"""The dependency graph of orbitcal's packages and the service, drawn from the imports.

Run:  python tools/import_graph.py [--level package|module] [--dot OUT.dot]

Every ``import``/``from … import`` in ``orbitcal/`` and ``service/`` is read with :mod:`ast`
(imports inside functions count: they run when the function does; imports under
``if TYPE_CHECKING:`` count too, as a type is a dependency; ``--runtime-only`` leaves them
out). At the ``package`` level a node is a top-level unit
(``orbitcal.orbit``, ``orbitcal.simulate``, ``service``); at the ``module`` level every module is a
node. Prints the edges and the cycles (strongly connected components with more than one node);
exits 1 when there is a cycle or an edge from ``orbitcal`` to ``service``. ``--dot`` writes a
Graphviz file. ``tests/test_import_graph.py`` holds the repository to that.
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections.abc import Iterable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ROOTS = ("orbitcal", "service")

__all__ = ["cycles", "forbidden_edges", "import_edges", "module_name", "package_graph"]


def module_name(path: Path, repo: Path = REPO) -> str:
    """``orbitcal/simulate/world.py`` → ``orbitcal.simulate.world`` (``__init__`` → the package)."""
    parts = list(path.relative_to(repo).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports(
    tree: ast.AST, module: str, is_package: bool, *, type_checking: bool = True
) -> Iterable[str]:
    """Absolute names imported by a module (``from a import b`` gives ``a.b``)."""
    stack: list[ast.AST] = [tree]
    while stack:
        node = stack.pop()
        if not type_checking and isinstance(node, ast.If) and _is_type_checking(node.test):
            stack.extend(node.orelse)
            continue
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".") if is_package else module.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                source = ".".join([*base, node.module] if node.module else base)
            else:
                source = node.module or ""
            # ``from a import b``: the module ``a.b`` when b is one, else ``a`` (resolved by the
            # caller, which keeps the longest known module name).
            for alias in node.names:
                yield f"{source}.{alias.name}"
        stack.extend(ast.iter_child_nodes(node))


def import_edges(repo: Path = REPO, *, type_checking: bool = True) -> set[tuple[str, str]]:
    """(importer, imported) module pairs within ``orbitcal`` and ``service``.

    ``type_checking=False`` leaves out the imports under ``if TYPE_CHECKING:``.
    """
    files = [p for root in ROOTS for p in sorted((repo / root).rglob("*.py"))]
    modules = {module_name(p, repo): p for p in files}
    edges: set[tuple[str, str]] = set()
    for name, path in modules.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        is_package = path.name == "__init__.py"
        for target in _imports(tree, name, is_package, type_checking=type_checking):
            # The longest known module the name refers to (``a.b.func`` → ``a.b``).
            parts = target.split(".")
            while parts and ".".join(parts) not in modules:
                parts.pop()
            if parts and ".".join(parts) != name:
                edges.add((name, ".".join(parts)))
    return edges


def _unit(module: str) -> str:
    parts = module.split(".")
    return parts[0] if parts[0] == "service" else ".".join(parts[:2])


def package_graph(edges: set[tuple[str, str]]) -> set[tuple[str, str]]:
    """Edges between top-level units (``orbitcal.X``, ``service``), self-loops dropped."""
    return {(_unit(a), _unit(b)) for a, b in edges if _unit(a) != _unit(b)}


def cycles(edges: set[tuple[str, str]]) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan), each sorted."""
    graph: dict[str, list[str]] = {}
    for a, b in sorted(edges):
        graph.setdefault(a, []).append(b)
        graph.setdefault(b, [])
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: list[list[str]] = []
    counter = 0

    def visit(v: str) -> None:
        nonlocal counter
        index[v] = low[v] = counter
        counter += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    sys.setrecursionlimit(max(10_000, sys.getrecursionlimit()))
    for v in graph:
        if v not in index:
            visit(v)
    return sorted(found)


def forbidden_edges(edges: set[tuple[str, str]]) -> list[tuple[str, str]]:
    """Edges from the library to the service (STYLE: the service imports the library only)."""
    return sorted((a, b) for a, b in edges if a.startswith("orbitcal") and b.startswith("service"))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--level", choices=("package", "module"), default="package")
    parser.add_argument("--dot", type=Path, help="write a Graphviz file")
    parser.add_argument(
        "--runtime-only", action="store_true", help="leave out imports under TYPE_CHECKING"
    )
    args = parser.parse_args()
    edges = import_edges(type_checking=not args.runtime_only)
    graph = package_graph(edges) if args.level == "package" else edges
    for a, b in sorted(graph):
        print(f"{a} -> {b}")
    found = cycles(graph)
    bad = forbidden_edges(edges)
    print(f"{len(graph)} edges; {len(found)} cycles; {len(bad)} orbitcal -> service edges")
    for component in found:
        print("cycle:", " <-> ".join(component))
    for a, b in bad:
        print(f"forbidden: {a} -> {b}")
    if args.dot:
        lines = ["digraph imports {", "  rankdir=LR;"]
        lines += [f'  "{a}" -> "{b}";' for a, b in sorted(graph)]
        args.dot.write_text("\n".join([*lines, "}"]) + "\n")
    return 1 if found or bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
