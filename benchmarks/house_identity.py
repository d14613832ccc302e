"""Field-by-field comparison of two ``orbitcal bench diagnose --out DIR`` results (issue 23).

``python benchmarks/house_identity.py BEFORE_DIR AFTER_DIR [--tol 1e-9]`` reads each directory's
``diagnose_results.json`` (``diagnose_compound_results.json`` for ``--compound``) and compares
every field of every case and of the summary: strings, booleans, integers and lists of names
exactly, numbers to ``tol`` (absolute, or relative for values above 1; NaN equals NaN). Timing
fields (``seconds*``, ``wall_seconds``, the machine) are left out. Prints the number of fields
compared and every difference; exits 1 when any.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

#: The results file of ``bench diagnose`` and of ``bench diagnose --compound``.
RESULT_FILES = ("diagnose_results.json", "diagnose_compound_results.json")

#: Keys that time the run, not its result.
TIMING_KEYS = frozenset({"seconds", "seconds_total", "wall_seconds", "machine"})


def differences(a: Any, b: Any, path: str, tol: float) -> Iterator[str]:
    """Every difference between ``a`` and ``b`` below ``path`` (none when equal)."""
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            if key in TIMING_KEYS:
                continue
            if key not in a or key not in b:
                yield f"{path}.{key}: only in {'after' if key not in a else 'before'}"
                continue
            yield from differences(a[key], b[key], f"{path}.{key}", tol)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            yield f"{path}: {len(a)} items before, {len(b)} after"
            return
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            yield from differences(x, y, f"{path}[{k}]", tol)
    elif isinstance(a, float | int) and isinstance(b, float | int) and not isinstance(a, bool):
        if isinstance(b, bool) or not _close(float(a), float(b), tol):
            yield f"{path}: {a!r} before, {b!r} after"
    elif a != b:
        yield f"{path}: {a!r} before, {b!r} after"


def _close(x: float, y: float, tol: float) -> bool:
    if math.isnan(x) or math.isnan(y):
        return math.isnan(x) and math.isnan(y)
    return abs(x - y) <= tol * max(1.0, abs(x), abs(y))


def count_fields(a: Any) -> int:
    """Number of leaf fields compared (timing left out)."""
    if isinstance(a, dict):
        return sum(count_fields(v) for k, v in a.items() if k not in TIMING_KEYS)
    if isinstance(a, list):
        return sum(count_fields(v) for v in a)
    return 1


def _results_file(directory: Path) -> Path:
    """The benchmark's results file in ``directory`` (single-effect or compound run)."""
    for name in RESULT_FILES:
        if (directory / name).exists():
            return directory / name
    raise FileNotFoundError(f"none of {', '.join(RESULT_FILES)} in {directory}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("--tol", type=float, default=1e-9)
    args = parser.parse_args()
    before = json.loads(_results_file(args.before).read_text())
    after = json.loads(_results_file(args.after).read_text())
    diffs = list(differences(before, after, "results", args.tol))
    cases = before.get("cases", [])
    print(
        f"{len(cases)} cases, {count_fields(before)} fields compared (tol {args.tol:g}): "
        f"{len(diffs)} differences"
    )
    for line in diffs:
        print("  " + line)
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main())
