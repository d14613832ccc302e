"""orbitcal's HTTP service: ingest, durable storage, scheduled retraining, calibration over REST.

The service imports the library (``orbitcal``), never the reverse. Build the app with
:func:`service.app.create_app`; nothing runs at import time.
"""

__all__: list[str] = []
