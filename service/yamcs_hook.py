"""The ``yamcs-push`` scheduler hook (issue 21): after a promotion, set the new calibration's
coefficients on a running Yamcs when ``ORBITCAL_YAMCS_PUSH_URL`` is configured.

A calibration the health check found stale (service/health.py) is never pushed.
A failed push never fails the retraining (the calibration is in service either way): it is
logged and reported in the job's result under ``yamcs_push`` with its reason.
"""

from __future__ import annotations

import logging
from typing import Any

from orbitcal.errors import OrbitcalError
from service.settings import Settings

__all__ = ["push_after_promotion"]

log = logging.getLogger("orbitcal.service.yamcs")


def push_after_promotion(
    settings: Settings, document: dict[str, Any], *, transport: Any = None, stale: bool = False
) -> dict[str, Any] | None:
    """Push ``document`` (just promoted) to the configured Yamcs; ``None`` when none is.

    Returns the export's report (what was set), or ``{"error": reason}``; a ``stale`` document
    is not pushed (``{"skipped": reason}``).
    """
    if not settings.yamcs_push_url:
        return None
    if stale:
        log.warning("yamcs push skipped: stale", extra={"version": document.get("version")})
        return {"skipped": "the calibration is stale (the health check found a change)"}
    from orbitcal.plausibility import document_problem

    implausible = document_problem(document)
    if implausible is not None:  # never reaches the ground system, whatever promoted it
        log.warning(
            "yamcs push refused", extra={"version": document.get("version"), "reason": implausible}
        )
        return {"error": f"not pushed: implausible for a magnetometer in nT: {implausible}"}
    from orbitcal.export import ExportOptions, YamcsTarget, export

    target = YamcsTarget(
        url=settings.yamcs_push_url,
        instance=settings.yamcs_push_instance,
        processor=settings.yamcs_push_processor,
        username=settings.yamcs_push_user or None,
        password=None
        if settings.yamcs_push_password is None
        else settings.yamcs_push_password.get_secret_value(),
    )
    try:
        options = ExportOptions(
            format="yamcs-push", space_system=settings.yamcs_push_space_system, yamcs=target
        )
        report = export(document, options, transport=transport).report
    except OrbitcalError as exc:
        log.warning(
            "yamcs push failed",
            extra={"version": document.get("version"), "reason": str(exc)},
        )
        return {"error": str(exc)}
    log.info(
        "yamcs push",
        extra={
            "version": document.get("version"),
            "n_set": None if report is None else report["n_set"],
        },
    )
    return report
