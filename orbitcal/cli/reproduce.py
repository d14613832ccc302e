"""``orbitcal reproduce wang2020 [--json]``: the seed paper's numbers beside ours.

With ``--json`` prints exactly the CONTRACT section-6 document; without, a table with the paper's
figure beside each of ours.
"""

from __future__ import annotations

import argparse
import json

__all__ = ["register", "run"]

PAPERS = ("wang2020",)


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``reproduce`` sub-command."""
    p = sub.add_parser(
        "reproduce",
        help="reproduce a seed paper's numbers (wang2020)",
        description="Re-run a seed paper's scenario and print its figures beside ours.",
    )
    p.add_argument("paper", choices=PAPERS, help="which paper")
    p.add_argument("--json", action="store_true", help="print the CONTRACT section-6 JSON")
    p.add_argument("--seed", type=int, default=2020, help="noise and weight seed (default 2020)")
    p.set_defaults(func=run)


def _table(result: object) -> str:
    from orbitcal.reproduce.wang2020 import PAPER, Wang2020Result

    assert isinstance(result, Wang2020Result)
    rows: list[tuple[str, str, str]] = []
    for h, r in result.table1:
        rows.append((f"Table 1: R, {h} hidden nodes", f"{PAPER['table1'][h]}", f"{r:.5f}"))
    for h, r in result.table1_eq16:
        rows.append((f"  (on eq. 16's planar field, {h} nodes)", "-", f"{r:.5f}"))
    rows += [
        (
            "LM epochs to MSE < 1e-3 (H = 3)",
            str(PAPER["lm_epochs_to_mse_1e-3"]),
            str(result.lm_epochs_to_mse_1e3),
        ),
        (
            "ground max error [nT]",
            PAPER["ground_max_error_nt"],
            f"{result.ground_max_error_nt:.2f}",
        ),
        (
            "after t = 15 s, no retraining: max error [nT]",
            PAPER["max_error_without_retraining_nt"],
            f"{result.max_error_without_retraining_nt:.2f}",
        ),
        (
            "after periodic retraining: max error [nT]",
            PAPER["max_error_after_retraining_nt"],
            f"{result.max_error_after_retraining_nt:.2f}",
        ),
    ]
    w = max(len(r[0]) for r in rows)
    lines = [f"{'Wang et al. 2020':<{w}}  {'paper':>8}  {'orbitcal':>9}", "-" * (w + 21)]
    lines += [f"{a:<{w}}  {b:>8}  {c:>9}" for a, b, c in rows]
    lines.append(
        "Table 1 uses eq. 16 with a third independent component (see "
        "orbitcal.reproduce.wang2020): on eq. 16 itself two nodes suffice."
    )
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Execute ``orbitcal reproduce``."""
    import torch

    from orbitcal.reproduce.wang2020 import reproduce_wang2020

    torch.set_num_threads(1)
    result = reproduce_wang2020(seed=args.seed)
    if args.json:
        print(json.dumps(result.to_json(), indent=2))
    else:
        print(_table(result))
    return 0
