"""orbitcal: on-orbit calibration of spacecraft three-axis magnetometers.

The notebook surface (lazy: ``import orbitcal`` imports none of numpy's heavy neighbours until a
function runs; see ``docs/tutorial.md``)::

    import orbitcal
    tel = orbitcal.read_table("telemetry.csv")            # or a pandas DataFrame
    orbit = orbitcal.load_orbit("sats.tle", norad_id=39452, near_utc_s=tel.t_utc_s[0])
    truth = orbitcal.reference_field(tel, orbit=orbit)    # IGRF-14 at each sample [nT]
    run = orbitcal.calibrate_table(tel, orbit=orbit, method="linear")
    b_cal = orbitcal.apply_calibration(run.document, tel)
    report = orbitcal.diagnose_table(tel, orbit=orbit)

Also re-exported: :class:`Telemetry`, :class:`Orbit` and the error base :class:`OrbitcalError`.
"""

from typing import TYPE_CHECKING

from orbitcal._lazy import lazy_exports

__version__ = "0.1.0"

if TYPE_CHECKING:
    from orbitcal.api import (
        apply_calibration,
        calibrate_table,
        diagnose_table,
        load_orbit,
        read_table,
        reference_field,
    )
    from orbitcal.errors import OrbitcalError
    from orbitcal.orbit import Orbit
    from orbitcal.telemetry import Telemetry

__all__ = [
    "Orbit",
    "OrbitcalError",
    "Telemetry",
    "__version__",
    "apply_calibration",
    "calibrate_table",
    "diagnose_table",
    "load_orbit",
    "read_table",
    "reference_field",
]

_EXPORTS = {
    **dict.fromkeys(
        (
            "apply_calibration",
            "calibrate_table",
            "diagnose_table",
            "load_orbit",
            "read_table",
            "reference_field",
        ),
        "orbitcal.api",
    ),
    "Orbit": "orbitcal.orbit",
    "OrbitcalError": "orbitcal.errors",
    "Telemetry": "orbitcal.telemetry",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
