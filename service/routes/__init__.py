"""HTTP routes, one module per resource."""

from service.routes import (
    calibrations,
    dashboard,
    health,
    jobs,
    keys,
    ops,
    spacecraft,
    telemetry,
)

__all__ = ["calibrations", "dashboard", "health", "jobs", "keys", "ops", "spacecraft", "telemetry"]
