"""Auxiliary tables that keep time scales, Earth orientation and space weather current.

Leap seconds (IERS), Earth-orientation parameters (IERS finals2000A: UT1 − UTC, polar motion),
the RC index (DTU, as ChaosMagPy reads it) and Kp/Dst (GFZ, WDC Kyoto) for quiet-time selection.

* :func:`update` fetches and validates them into the per-user data directory (``orbitcal data
  update``); :func:`status` says what is installed and until when (``orbitcal data status``).
* :func:`active_table` serves the installed copy, or the shipped one (see
  ``orbitcal/auxdata/shipped/README.md``) when that is valid longer.
* :func:`tables_provenance` is the tables' part of the block every result carries
  (:func:`orbitcal.provenance.result_provenance`): which file, valid until when, retrieved when,
  and whether the data run past it.
* :func:`storm_mask` flags storm-time samples for retraining.
"""

from __future__ import annotations

from orbitcal.auxdata.formats import ParsedTable, TableFormatError
from orbitcal.auxdata.provenance import table_status, tables_provenance
from orbitcal.auxdata.quiet import StormMask, quiet_selection, storm_mask
from orbitcal.auxdata.tables import (
    DEFAULT_URLS,
    KINDS,
    ActiveTable,
    active_table,
    data_dir,
    generation,
    reload,
    shipped_table,
    status,
    update,
    using,
)

__all__ = [
    "DEFAULT_URLS",
    "KINDS",
    "ActiveTable",
    "ParsedTable",
    "StormMask",
    "TableFormatError",
    "active_table",
    "data_dir",
    "generation",
    "quiet_selection",
    "reload",
    "shipped_table",
    "status",
    "storm_mask",
    "table_status",
    "tables_provenance",
    "update",
    "using",
]
