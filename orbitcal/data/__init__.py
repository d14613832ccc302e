"""Reference data shipped with the package (provenance in this folder's README.md)."""

from __future__ import annotations

from importlib import resources

__all__ = ["REAL_TLES_FILE", "real_tles_text"]

#: 56 real CelesTrak element sets of Swarm A/B/C and the ISS (2022-08, 2023-07…11).
REAL_TLES_FILE = "swarm_iss_real_tles.tle"


def real_tles_text() -> str:
    """The text of the shipped real TLE file (3-line sets, many spacecraft)."""
    return resources.files(__name__).joinpath(REAL_TLES_FILE).read_text("utf-8")
