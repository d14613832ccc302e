"""Attitude profiles of simulated spacecraft, as ``q_wxyz`` in the contract convention.

Every profile gives the body's orientation in GCRS (the default attitude frame, CONTRACT
section 1): ``v_body = Rotation.from_quat([q_x, q_y, q_z, q_w]).inv().apply(v_gcrs)``.

* :class:`NadirLVLH` — local-vertical/local-horizontal pointing: body +z towards the Earth's centre
  (nadir), body +y along the negative orbit normal (−r × v), body +x completing the right-handed
  triad (along the velocity for a circular orbit).
* :class:`Inertial` — a fixed orientation in GCRS.
* :class:`Tumbling` — constant body rate ω (body axes) from an initial orientation:
  ``R_body→GCRS(t) = R_0 · exp([ω]× (t − t_0))``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from scipy.spatial.transform import Rotation

from orbitcal.arrays import FloatArray
from orbitcal.attitude import matrix_to_quat_wxyz, quat_normalize, wxyz_to_xyzw, xyzw_to_wxyz
from orbitcal.errors import BadInputError

__all__ = [
    "ATTITUDE_PROFILES",
    "AttitudeProfile",
    "Inertial",
    "NadirLVLH",
    "Tumbling",
    "attitude_profile",
]


class AttitudeProfile(Protocol):
    """Anything that gives the body's GCRS orientation along an orbit."""

    @property
    def name(self) -> str:
        """Profile name (``nadir``, ``inertial``, ``tumbling``)."""
        ...

    def q_wxyz(
        self, t_utc_s: FloatArray, r_gcrs_km: FloatArray, v_gcrs_km_s: FloatArray
    ) -> FloatArray:
        """Quaternions, shape (N, 4), body orientation in GCRS (contract convention)."""
        ...

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready name and parameters."""
        ...


def _unit(v: FloatArray) -> FloatArray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass(frozen=True)
class NadirLVLH:
    """Nadir pointing: body z → Earth centre, body y → −orbit normal, body x ≈ velocity."""

    name: str = field(default="nadir", init=False)

    def q_wxyz(
        self, t_utc_s: FloatArray, r_gcrs_km: FloatArray, v_gcrs_km_s: FloatArray
    ) -> FloatArray:
        """Quaternions, shape (N, 4), from positions [km] and velocities [km/s] in GCRS."""
        z_b = -_unit(np.asarray(r_gcrs_km, dtype=np.float64))
        y_b = -_unit(np.cross(r_gcrs_km, v_gcrs_km_s))
        x_b = np.cross(y_b, z_b)
        # Rows are the body axes in GCRS: v_body = R_frame_to_body @ v_gcrs.
        r_frame_to_body = np.stack([x_b, y_b, z_b], axis=-2)
        return matrix_to_quat_wxyz(r_frame_to_body)

    def to_dict(self) -> dict[str, Any]:
        return {"profile": self.name}


@dataclass(frozen=True)
class Inertial:
    """Fixed orientation in GCRS, ``q0_wxyz`` (identity by default)."""

    q0_wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    name: str = field(default="inertial", init=False)

    def q_wxyz(
        self, t_utc_s: FloatArray, r_gcrs_km: FloatArray, v_gcrs_km_s: FloatArray
    ) -> FloatArray:
        """Quaternions, shape (N, 4): the same orientation at every sample."""
        q = quat_normalize(np.asarray(self.q0_wxyz, dtype=np.float64))
        return np.tile(q, (np.asarray(t_utc_s).shape[0], 1))

    def to_dict(self) -> dict[str, Any]:
        return {"profile": self.name, "q0_wxyz": list(self.q0_wxyz)}


@dataclass(frozen=True)
class Tumbling:
    """Constant body rate from ``q0_wxyz`` at ``t0_utc_s`` (the first sample when None).

    Attributes
    ----------
    rate_body_deg_s : tuple of 3 float
        Angular velocity in body axes [deg/s]; default 2 °/s about a skew axis.
    q0_wxyz : tuple of 4 float
        Orientation in GCRS at ``t0_utc_s``.
    t0_utc_s : float or None
        Reference time, POSIX seconds of UTC [s].
    """

    rate_body_deg_s: tuple[float, float, float] = (0.6, -1.2, 1.5)
    q0_wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    t0_utc_s: float | None = None
    name: str = field(default="tumbling", init=False)

    def q_wxyz(
        self, t_utc_s: FloatArray, r_gcrs_km: FloatArray, v_gcrs_km_s: FloatArray
    ) -> FloatArray:
        """Quaternions, shape (N, 4): ``R_0 · exp([ω]× (t − t_0))`` (body → GCRS)."""
        t = np.asarray(t_utc_s, dtype=np.float64)
        t0 = float(t[0]) if self.t0_utc_s is None and t.size else float(self.t0_utc_s or 0.0)
        omega_rad_s = np.deg2rad(np.asarray(self.rate_body_deg_s, dtype=np.float64))
        r0 = Rotation.from_quat(wxyz_to_xyzw(quat_normalize(np.asarray(self.q0_wxyz))))
        rot = r0 * Rotation.from_rotvec(np.outer(t - t0, omega_rad_s))
        q = xyzw_to_wxyz(rot.as_quat())
        return np.asarray(q, dtype=np.float64).reshape(-1, 4)

    def to_dict(self) -> dict[str, Any]:
        return {
            "profile": self.name,
            "rate_body_deg_s": list(self.rate_body_deg_s),
            "q0_wxyz": list(self.q0_wxyz),
            "t0_utc_s": self.t0_utc_s,
        }


#: Profiles by name (``orbitcal simulate --attitude``).
ATTITUDE_PROFILES: dict[str, type[Any]] = {
    "nadir": NadirLVLH,
    "inertial": Inertial,
    "tumbling": Tumbling,
}


def attitude_profile(name: str, **params: Any) -> AttitudeProfile:
    """Build a profile by name (``nadir``, ``inertial``, ``tumbling``) with its parameters."""
    try:
        cls = ATTITUDE_PROFILES[name]
    except KeyError:
        raise BadInputError(
            f"unknown attitude profile {name!r}: use one of {', '.join(ATTITUDE_PROFILES)}"
        ) from None
    return cls(**params)  # type: ignore[no-any-return]
