"""Reproductions of the seed papers (``orbitcal reproduce NAME``)."""

from __future__ import annotations

__all__: list[str] = []
