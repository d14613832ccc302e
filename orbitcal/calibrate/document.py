"""The calibration document of CONTRACT section 4, to and from JSON-ready dicts.

Floats are written with Python's shortest round-trip representation, so a document read back gives
the same float64 values and :meth:`Calibration.apply` the same output, bit for bit.
"""

from __future__ import annotations

import json
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from orbitcal.calibrate.base import Calibration
from orbitcal.calibrate.errors import DocumentError

__all__ = [
    "REQUIRED_KEYS",
    "calibration_from_document",
    "calibration_to_document",
    "iso_utc",
    "read_document",
    "write_document",
]

REQUIRED_KEYS = (
    "spacecraft",
    "version",
    "method",
    "created_at",
    "reference_field",
    "data",
    "metrics",
    "linear",
    "model",
)


def iso_utc(t_utc_s: float) -> str:
    """ISO-8601 UTC with ``Z`` and microseconds."""
    return (
        datetime.fromtimestamp(float(t_utc_s), tz=UTC)
        .isoformat(timespec="microseconds")
        .replace("+00:00", "Z")
    )


def calibration_to_document(
    cal: Calibration,
    *,
    spacecraft: str,
    version: int,
    reference_field: str,
    t_start_utc_s: float,
    t_end_utc_s: float,
    n_samples: int,
    metrics: dict[str, float],
    created_at: str | None = None,
    provenance: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Build the section-4 document for a fitted calibration.

    ``metrics`` must contain ``holdout_rms_nt`` [nT]; ``created_at`` defaults to now (UTC).
    ``provenance`` (default: computed by :func:`orbitcal.provenance.result_provenance` over the data
    span) names the leap-second, EOP and RC tables behind the reference field and the reference
    model's generation, and warns when the data run past a table's end; it is an extra key beside
    those of CONTRACT section 4.
    """
    if "holdout_rms_nt" not in metrics:
        raise ValueError("metrics must contain holdout_rms_nt")
    M, o = cal.linear()
    if provenance is None:
        from orbitcal.provenance import result_provenance

        provenance = result_provenance(
            [float(t_start_utc_s), float(t_end_utc_s)],
            reference_field=reference_field,
            kinds=("leap_seconds", "eop", "rc_index")
            if "RC" in reference_field.replace(" ", "").split("+")
            else ("leap_seconds", "eop"),
        )
    return {
        "spacecraft": spacecraft,
        "version": int(version),
        "method": cal.method,
        "created_at": created_at
        or datetime.now(tz=UTC).isoformat(timespec="seconds").replace("+00:00", "Z"),
        "reference_field": reference_field,
        "data": {
            "start": iso_utc(t_start_utc_s),
            "end": iso_utc(t_end_utc_s),
            "n": int(n_samples),
        },
        "metrics": {k: float(v) for k, v in metrics.items()},
        "linear": {"M": np.asarray(M).tolist(), "o": np.asarray(o).tolist()},
        "model": cal.to_model(),
        "provenance": provenance,
    }


def calibration_from_document(doc: dict[str, Any]) -> Calibration:
    """Rebuild the calibration of a section-4 document.

    Raises
    ------
    DocumentError
        Missing keys or an unknown method.
    """
    from orbitcal.calibrate import calibration_class

    missing = [k for k in ("method", "linear", "model") if k not in doc]
    if missing:
        raise DocumentError(f"calibration document lacks {', '.join(missing)}")
    method = str(doc["method"])
    cls = calibration_class(method)
    cal = cls.from_model(method, doc["model"])
    lin = doc["linear"]
    if hasattr(cal, "set_linear") and isinstance(lin, dict):
        cal.set_linear(
            np.asarray(lin["M"], dtype=np.float64), np.asarray(lin["o"], dtype=np.float64)
        )
    return cal


def write_document(path: str | Path, doc: dict[str, Any]) -> None:
    """Write a document as indented JSON (UTF-8)."""
    Path(path).write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")


def read_document(path: str | Path) -> dict[str, Any]:
    """Read a document; raise :class:`DocumentError` when it is not a JSON object with the keys."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise DocumentError(f"{path} is not JSON: {exc}") from exc
    if not isinstance(doc, dict):
        raise DocumentError(f"{path} is not a JSON object")
    missing = [k for k in REQUIRED_KEYS if k not in doc]
    if missing:
        raise DocumentError(f"{path} is not a calibration document: lacks {', '.join(missing)}")
    return doc
