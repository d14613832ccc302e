"""Scoring any calibration document through its *full* calibration (network and housekeeping
included), in the vocabulary of :mod:`orbitcal.metrics`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from orbitcal.arrays import BoolArray, FloatArray
from orbitcal.calibrate import Calibration, FitData
from orbitcal.calibrate.document import calibration_from_document
from orbitcal.errors import BadInputError
from orbitcal.metrics import norm_rms_nt, rms_nt, scalar_rms_nt
from orbitcal.pipeline.inputs import fit_data_for_telemetry
from orbitcal.telemetry import Telemetry

__all__ = ["Scores", "apply_document", "regressors_for", "residuals", "score"]


@dataclass(frozen=True)
class Scores:
    """Accuracy of a calibration on some rows, in the vocabulary of :mod:`orbitcal.metrics` [nT].

    ``rms_nt`` and ``norm_rms_nt`` are None without attitude (no body-frame reference).
    """

    n: int
    scalar_rms_nt: float
    rms_nt: float | None = None
    norm_rms_nt: float | None = None

    def primary(self, *, vector: bool) -> float:
        """The figure a method is judged by (:func:`orbitcal.metrics.primary_key`)."""
        if vector and self.rms_nt is not None:
            return self.rms_nt
        return self.scalar_rms_nt

    def as_dict(self) -> dict[str, float]:
        out = {"n": float(self.n), "scalar_rms_nt": self.scalar_rms_nt}
        if self.rms_nt is not None and self.norm_rms_nt is not None:
            out["rms_nt"] = self.rms_nt
            out["norm_rms_nt"] = self.norm_rms_nt
        return out


def regressors_for(cal: Calibration, telemetry: Telemetry) -> FloatArray | None:
    """The table's housekeeping columns in the order the calibration needs (``None`` if none).

    Raises
    ------
    BadInputError
        When the table lacks a column the calibration was fitted with.
    """
    if not cal.hk_names:
        return None
    x_hk, names = telemetry.regressors()
    return _columns(cal, x_hk, names)


def _columns(cal: Calibration, x_hk: FloatArray | None, names: list[str]) -> FloatArray | None:
    if not cal.hk_names:
        return None
    missing = [n for n in cal.hk_names if n not in names]
    if missing or x_hk is None:
        raise BadInputError(
            f"the {cal.method} calibration needs housekeeping columns {', '.join(missing)}, "
            "which the telemetry lacks",
            field=missing[0] if missing else None,
        )
    out: FloatArray = x_hk[:, [names.index(n) for n in cal.hk_names]]
    return out


def apply_document(doc: dict[str, Any], telemetry: Telemetry) -> FloatArray:
    """Calibrated field ``(N, 3)`` [nT, body frame] for each row of ``telemetry`` (table order),
    through the document's full calibration (network and housekeeping terms included).

    Raises
    ------
    DocumentError
        A malformed document or unknown method.
    BadInputError
        The table lacks a housekeeping column the calibration uses.
    """
    cal = calibration_from_document(doc)
    return cal.apply(
        np.asarray(telemetry.b_raw_nt, dtype=np.float64), regressors_for(cal, telemetry)
    )


def _as_calibration(document: dict[str, Any] | Calibration) -> Calibration:
    return document if isinstance(document, Calibration) else calibration_from_document(document)


def residuals(
    document: dict[str, Any] | Calibration,
    truth: FitData,
    rows: BoolArray | NDArray[np.intp] | None = None,
) -> tuple[FloatArray, FloatArray | None, FloatArray]:
    """``(b_cal, b_cal − b_ref_body, ‖b_cal‖ − |B_ref|)`` on ``rows`` of ``truth`` [nT].

    The calibration is the document's full one (network and housekeeping terms included). The
    vector residual is None without attitude.
    """
    cal = _as_calibration(document)
    data = truth if rows is None else truth.subset(rows)
    b_cal = cal.apply(data.b_raw_nt, _columns(cal, data.x_hk, list(data.hk_names)))
    vec = None if data.b_ref_body_nt is None else b_cal - data.b_ref_body_nt
    assert data.b_ref_mag_nt is not None
    return b_cal, vec, np.linalg.norm(b_cal, axis=1) - data.b_ref_mag_nt


def score(
    document: dict[str, Any] | Calibration,
    telemetry: Telemetry | None = None,
    rows: BoolArray | NDArray[np.intp] | None = None,
    *,
    truth: FitData | None = None,
    orbit: Any = None,
    field: str | None = None,
    attitude_frame: str = "GCRS",
) -> Scores:
    """Scores of a calibration document on ``rows`` of ``telemetry`` (all rows by default).

    Parameters
    ----------
    document
        A section-4 document (or a fitted :class:`Calibration`), applied in full.
    telemetry
        The table; not needed when ``truth`` is given.
    rows
        Boolean mask or index array of the rows to score.
    truth
        The reference field along ``telemetry`` (:func:`fit_data_for_telemetry`), when already
        computed; otherwise computed here from ``orbit``, ``field`` (default: the document's
        ``reference_field``) and ``attitude_frame``.
    """
    if truth is None:
        if telemetry is None:
            raise TypeError("score() needs the telemetry or its truth")
        if field is None:
            field = (
                str(document.get("reference_field") or "IGRF-14")
                if isinstance(document, dict)
                else "IGRF-14"
            )
        if rows is not None:
            telemetry, rows = telemetry.select(rows), None
        truth, _ = fit_data_for_telemetry(
            telemetry, orbit=orbit, field=field, attitude_frame=attitude_frame
        )
    cal = _as_calibration(document)
    data = truth if rows is None else truth.subset(rows)
    b_cal = cal.apply(data.b_raw_nt, _columns(cal, data.x_hk, list(data.hk_names)))
    assert data.b_ref_mag_nt is not None
    b_ref = data.b_ref_body_nt
    return Scores(
        n=int(b_cal.shape[0]),
        scalar_rms_nt=scalar_rms_nt(b_cal, data.b_ref_mag_nt),
        rms_nt=None if b_ref is None else rms_nt(b_cal, b_ref),
        norm_rms_nt=None if b_ref is None else norm_rms_nt(b_cal, b_ref),
    )
