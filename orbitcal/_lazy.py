"""Lazy re-exports for package ``__init__`` modules (PEP 562 module ``__getattr__``).

A package that re-exports names from heavy submodules (torch, scipy, pandas, numba) lists them
here instead of importing them, so ``import orbitcal`` and ``orbitcal --help`` stay light and a
name's submodule is imported on first access. Type checkers see the names through an
``if TYPE_CHECKING:`` import block beside the table; ``tests/test_public_api.py`` checks that
every name of each ``__all__`` resolves.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(
    package: str, exports: Mapping[str, str], namespace: dict[str, Any]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """Module ``__getattr__`` and ``__dir__`` for a package's lazily imported names.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    exports : mapping of str to str
        Public name → absolute name of the submodule that defines it.
    namespace : dict
        The package's ``globals()``: a resolved name is stored there, so the next access is a
        plain attribute lookup.

    Returns
    -------
    (__getattr__, __dir__)
    """

    def getattr_(name: str) -> Any:
        try:
            module = exports[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    def dir_() -> list[str]:
        return sorted({*namespace, *exports})

    return getattr_, dir_
