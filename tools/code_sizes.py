"""The largest functions and modules of the library and the service, in lines (issue 23).

A function's size is its ``def`` line to its last line, docstring included (nested functions are
counted inside their parent and on their own); a module's is its number of lines. Run from the
repository root, or give the root: ``python tools/code_sizes.py [ROOT] [--top N] [--over LINES]``.
"""

from __future__ import annotations

import argparse
import ast
from pathlib import Path

PACKAGES = ("orbitcal", "service")


def function_sizes(root: Path) -> list[tuple[int, str]]:
    """``(lines, "path:qualified.name")`` of every function under the packages."""
    out: list[tuple[int, str]] = []
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            tree = ast.parse(path.read_text(), filename=str(path))
            rel = path.relative_to(root).as_posix()
            out.extend(_walk(tree, rel, ""))
    return out


def _walk(node: ast.AST, rel: str, prefix: str) -> list[tuple[int, str]]:
    out: list[tuple[int, str]] = []
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
            start = min([child.lineno, *(d.lineno for d in child.decorator_list)])
            end = child.end_lineno or child.lineno
            out.append((end - start + 1, f"{rel}:{prefix}{child.name}"))
            out.extend(_walk(child, rel, f"{prefix}{child.name}."))
        elif isinstance(child, ast.ClassDef):
            out.extend(_walk(child, rel, f"{prefix}{child.name}."))
        else:
            out.extend(_walk(child, rel, prefix))
    return out


def module_sizes(root: Path) -> list[tuple[int, str]]:
    """``(lines, path)`` of every module under the packages."""
    return [
        (len(path.read_text().splitlines()), path.relative_to(root).as_posix())
        for package in PACKAGES
        for path in sorted((root / package).rglob("*.py"))
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", nargs="?", default=".", type=Path)
    parser.add_argument("--top", type=int, default=15)
    parser.add_argument("--over", type=int, default=100, help="count functions over this size")
    args = parser.parse_args()
    funcs = sorted(function_sizes(args.root), reverse=True)
    mods = sorted(module_sizes(args.root), reverse=True)
    over = [f for f in funcs if f[0] > args.over]
    print(f"functions over {args.over} lines: {len(over)}\n")
    print("| lines | function |\n|---:|---|")
    for n, name in funcs[: args.top]:
        print(f"| {n} | `{name}` |")
    print("\n| lines | module |\n|---:|---|")
    for n, name in mods[: args.top]:
        print(f"| {n} | `{name}` |")


if __name__ == "__main__":
    main()
