"""HTTP routes, one module per resource."""

from service.routes import calibrations, dashboard, jobs, keys, ops, spacecraft, telemetry

__all__ = ["calibrations", "dashboard", "jobs", "keys", "ops", "spacecraft", "telemetry"]
