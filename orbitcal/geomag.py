"""Geomagnetic coordinates: the IGRF-14 centred dipole at 2020.0, its axis, magnetic latitude.

One home for the simulator (the ring-current axis, auroral field-aligned currents) and the
diagnosis (magnetic-latitude bands, the ring-current and FAC candidates).

The dipole is the degree-1 part of IGRF-14 at 2020.0 (IAGA Division V Working Group V-MOD,
"International Geomagnetic Reference Field: the fourteenth generation", 2024,
doi:10.5281/zenodo.14012302; the same file ``ppigrf/IGRF14.shc`` that :mod:`orbitcal.field.igrf`
reads): g10 = −29403.41, g11 = −1451.37, h11 = 4653.35 nT, a definitive (DGRF) epoch. Its north
geomagnetic pole (where the dipole axis leaves the northern hemisphere) lies at 80.59° N,
72.68° W. The pole moves by about 0.05° per year (80.31° N at 2015.0, 80.79° N at 2025.0). 2020.0
lies in the middle of the data this package is checked on (the 2016 Swarm storm pass, the
2022-23 real TLEs): there the real-data diagnosis is unchanged, while the 2025.0 dipole (0.20°
away) tips a marginal time_offset into that storm pass's answer (held-out 22.4 -> 21.7 nT,
measured). The magnetic-latitude bands (≥ 5° wide) and the ring-current axis need no finer epoch.

This is not the dipole of the SM/GSM frames of the CHAOS external field
(:data:`orbitcal.field.external.CHAOS_SM_DIPOLE_NT`, IGRF-12 at 2015.0), which is part of that
model's parameterisation.
"""

from __future__ import annotations

import numpy as np

from orbitcal.arrays import FloatArray

__all__ = [
    "DIPOLE_EPOCH_YEAR",
    "IGRF14_DIPOLE_2020_NT",
    "dipole_axis_itrs",
    "dipole_pole_deg",
    "magnetic_latitude_deg",
]

#: The epoch of the dipole [decimal year].
DIPOLE_EPOCH_YEAR = 2020.0

#: IGRF-14 degree-1 Gauss coefficients g10, g11, h11 at 2020.0 [nT] (definitive, DGRF).
IGRF14_DIPOLE_2020_NT: tuple[float, float, float] = (-29403.41, -1451.37, 4653.35)


def dipole_axis_itrs() -> FloatArray:
    """Unit vector towards the north geomagnetic pole (the centred dipole), ITRS.

    ``−(g11, h11, g10) / ‖·‖``: the Earth's dipole moment points the other way (south).

    Returns
    -------
    ndarray, shape (3,)
        ITRS x, y, z components [-].
    """
    g10, g11, h11 = IGRF14_DIPOLE_2020_NT
    v = -np.array([g11, h11, g10])
    return v / np.linalg.norm(v)


def dipole_pole_deg() -> tuple[float, float]:
    """Geographic latitude and longitude of the north geomagnetic pole [deg] (80.59, −72.68)."""
    x, y, z = dipole_axis_itrs()
    return float(np.degrees(np.arcsin(z))), float(np.degrees(np.arctan2(y, x)))


def magnetic_latitude_deg(r_itrs_km: FloatArray) -> FloatArray:
    """Centred-dipole magnetic latitude [deg] of ITRS positions.

    Parameters
    ----------
    r_itrs_km : ndarray, shape (..., 3)
        Positions, ITRS [km] (any length unit: only the direction counts).

    Returns
    -------
    ndarray, shape (...)
        Magnetic latitude [deg], −90 to 90.
    """
    r_hat = r_itrs_km / np.linalg.norm(r_itrs_km, axis=-1, keepdims=True)
    return np.degrees(np.arcsin(np.clip(r_hat @ dipole_axis_itrs(), -1.0, 1.0)))
