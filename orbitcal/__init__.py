"""orbitcal: on-orbit calibration of spacecraft three-axis magnetometers."""

__version__ = "0.1.0"

__all__ = ["__version__"]
