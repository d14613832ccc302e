"""Calibrations the ground segment can run: XTCE/Yamcs, COSMOS, on-board C, polynomials.

One public entry, :func:`export` (CONTRACT section 7), used by ``orbitcal export``, the
service's ``?format=F`` and the ``yamcs-push`` scheduler hook. The section-4 document is the
source of every export (:mod:`orbitcal.export.product`); :func:`evaluate_document` is the
reference evaluator in numpy alone that every generated consumer is tested against.
"""

from __future__ import annotations

from orbitcal.export.api import export, held_out_loss, hk_columns
from orbitcal.export.evaluate import evaluate, evaluate_document
from orbitcal.export.options import (
    DEFAULT_CAL_NAMES,
    DEFAULT_RAW_NAMES,
    FORMATS,
    ExportError,
    ExportOptions,
    ExportResult,
    HeldOutLoss,
    YamcsTarget,
    parse_hk_names,
    parse_names,
)
from orbitcal.export.product import (
    AffineForm,
    NetworkForm,
    ProductInfo,
    affine_part,
    calibration_form,
    document_sha256,
    product_info,
)

__all__ = [
    "DEFAULT_CAL_NAMES",
    "DEFAULT_RAW_NAMES",
    "FORMATS",
    "AffineForm",
    "ExportError",
    "ExportOptions",
    "ExportResult",
    "HeldOutLoss",
    "NetworkForm",
    "ProductInfo",
    "YamcsTarget",
    "affine_part",
    "calibration_form",
    "document_sha256",
    "evaluate",
    "evaluate_document",
    "export",
    "held_out_loss",
    "hk_columns",
    "parse_hk_names",
    "parse_names",
    "product_info",
]
