"""What ``docs/CONTRACT.md`` says, read from the document itself.

The contract tests compare the library with these values, so the names live in one place (the
contract) and a change on either side fails a test instead of editing a copy.
"""

from __future__ import annotations

import re
from pathlib import Path

CONTRACT_MD = Path(__file__).resolve().parents[1] / "docs" / "CONTRACT.md"


def contract_effect_names() -> tuple[str, ...]:
    """The section-5 ``EFFECT`` names in the document's order, ``none`` first."""
    text = CONTRACT_MD.read_text(encoding="utf-8")
    found = re.search(r"`EFFECT` is one of:(.*?)\.\s", text, re.S)
    assert found is not None, "docs/CONTRACT.md no longer lists the EFFECT names"
    return tuple(re.findall(r"`([a-z_]+)`", found.group(1)))


#: Every verdict the contract allows (the effect names and ``none``).
CONTRACT_VERDICTS = frozenset(contract_effect_names())
#: The effects proper (what a simulated world can inject, what the diagnosis can name).
CONTRACT_EFFECTS = CONTRACT_VERDICTS - {"none"}
