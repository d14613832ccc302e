"""The reference ("truth") field along track, in ITRS and in the body frame.

Pipeline per sample (each at its own time): position in ITRS [km] → geocentric spherical
coordinates → field model in geocentric NEC [nT] → ITRS (``orbitcal.frames.nec_to_itrs``) →
the attitude frame (GCRS via ``orbitcal.frames.itrs_to_gcrs``, or ITRS itself) → body axes with
the contract's quaternion convention (``orbitcal.attitude.frame_to_body``:
``v_body = Rotation.from_quat([q_x, q_y, q_z, q_w]).inv().apply(v_frame)``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray
from orbitcal.attitude import frame_to_body
from orbitcal.errors import BadInputError
from orbitcal.field import DEFAULT_FIELD, FieldModel, get_field
from orbitcal.frames import itrs_to_gcrs, itrs_to_spherical, nec_to_itrs
from orbitcal.orbit import Propagator, require_valid

if TYPE_CHECKING:
    import pandas as pd

    from orbitcal.telemetry import Telemetry

__all__ = [
    "ATTITUDE_FRAMES",
    "Truth",
    "reference_field_itrs_nt",
    "reference_field_nec_nt",
    "truth_body_nt",
    "truth_for_telemetry",
]


#: Attitude frames the quaternions may refer to (CONTRACT section 1).
ATTITUDE_FRAMES: tuple[str, ...] = ("GCRS", "ITRS")


def _model(field: str | FieldModel) -> FieldModel:
    return get_field(field) if isinstance(field, str) else field


def _frame(attitude_frame: str) -> str:
    frame = attitude_frame.strip().upper()
    if frame not in ATTITUDE_FRAMES:
        raise BadInputError(
            f"unknown attitude frame {attitude_frame!r}; use one of {', '.join(ATTITUDE_FRAMES)}"
        )
    return frame


def _inputs(t_utc_s: npt.ArrayLike, r_itrs_km: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    t = np.asarray(t_utc_s, dtype=np.float64).reshape(-1)
    r = np.asarray(r_itrs_km, dtype=np.float64).reshape(-1, 3)
    if r.shape[0] != t.shape[0]:
        raise BadInputError(f"{t.shape[0]} times but {r.shape[0]} positions")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(r))):
        raise BadInputError("times and positions must be finite")
    return t, r


def reference_field_nec_nt(
    t_utc_s: npt.ArrayLike,
    r_itrs_km: npt.ArrayLike,
    *,
    field: str | FieldModel = DEFAULT_FIELD,
) -> FloatArray:
    """Reference field in geocentric North, East, Centre at each sample.

    Parameters
    ----------
    t_utc_s : array_like, shape (N,)
        POSIX seconds of UTC [s].
    r_itrs_km : array_like, shape (N, 3)
        Positions in ITRS [km].
    field : str or FieldModel, keyword-only
        Model name for :func:`orbitcal.field.get_field` (default ``"IGRF-14"``) or a model.

    Returns
    -------
    ndarray, shape (N, 3)
        ``(N, E, C)`` [nT], C positive down.
    """
    t, r = _inputs(t_utc_s, r_itrs_km)
    radius_km, colat_deg, lon_deg = itrs_to_spherical(r)
    return _model(field).b_nec_nt(t, radius_km, colat_deg, lon_deg)


def reference_field_itrs_nt(
    t_utc_s: npt.ArrayLike,
    r_itrs_km: npt.ArrayLike,
    *,
    field: str | FieldModel = DEFAULT_FIELD,
) -> FloatArray:
    """Reference field in ITRS Cartesian components at each sample.

    Parameters
    ----------
    t_utc_s : array_like, shape (N,)
        POSIX seconds of UTC [s].
    r_itrs_km : array_like, shape (N, 3)
        Positions in ITRS [km].
    field : str or FieldModel, keyword-only
        Model name (default ``"IGRF-14"``) or a model.

    Returns
    -------
    ndarray, shape (N, 3)
        ``b_itrs_nt`` [nT], ITRS x, y, z.
    """
    t, r = _inputs(t_utc_s, r_itrs_km)
    return nec_to_itrs(reference_field_nec_nt(t, r, field=field), r)


def _itrs_to_body(
    t: FloatArray, b_itrs_nt: FloatArray, q_wxyz: npt.ArrayLike, frame: str
) -> FloatArray:
    q = np.asarray(q_wxyz, dtype=np.float64).reshape(-1, 4)
    if q.shape[0] != t.shape[0]:
        raise BadInputError(f"{t.shape[0]} times but {q.shape[0]} quaternions")
    b_frame = itrs_to_gcrs(b_itrs_nt, t) if frame == "GCRS" else b_itrs_nt
    return frame_to_body(b_frame, q)


def truth_body_nt(
    t_utc_s: npt.ArrayLike,
    r_itrs_km: npt.ArrayLike,
    q_wxyz: npt.ArrayLike,
    *,
    attitude_frame: str = "GCRS",
    field: str | FieldModel = DEFAULT_FIELD,
) -> FloatArray:
    """Reference field in body axes at each sample.

    Parameters
    ----------
    t_utc_s : array_like, shape (N,)
        POSIX seconds of UTC [s].
    r_itrs_km : array_like, shape (N, 3)
        Positions in ITRS [km].
    q_wxyz : array_like, shape (N, 4)
        Body orientation in ``attitude_frame``, scalar first (contract convention).
    attitude_frame : {"GCRS", "ITRS"}, keyword-only
        Frame the quaternions refer to.
    field : str or FieldModel, keyword-only
        Model name (default ``"IGRF-14"``) or a model.

    Returns
    -------
    ndarray, shape (N, 3)
        ``b_body_nt`` [nT], body x, y, z.
    """
    frame = _frame(attitude_frame)
    t, r = _inputs(t_utc_s, r_itrs_km)
    return _itrs_to_body(t, reference_field_itrs_nt(t, r, field=field), q_wxyz, frame)


@dataclass(frozen=True)
class Truth:
    """The reference field along a telemetry table.

    Attributes
    ----------
    t_utc_s : ndarray, shape (N,)
        Sample times, POSIX seconds of UTC [s].
    b_body_nt : ndarray, shape (N, 3) or None
        Field in body axes [nT]; None when the table has no quaternions.
    b_itrs_nt : ndarray, shape (N, 3)
        Field in ITRS [nT].
    b_nec_nt : ndarray, shape (N, 3)
        Field in geocentric North, East, Centre [nT].
    r_itrs_km : ndarray, shape (N, 3)
        Positions used [km], ITRS.
    field_name : str
        Full model name with its generation (e.g. ``"IGRF-14"``).
    attitude_frame : str
        Frame of the quaternions used for ``b_body_nt``.
    position_source : str
        ``"telemetry"`` (the table's ``r_x, r_y, r_z``) or ``"sgp4"``.
    eop_status : str
        How UT1 − UTC and polar motion entered the frames over the span (``observed``,
        ``predicted`` — Bulletin A predictions, the only values yet for those dates — or
        ``past_end``, extrapolated), from :func:`orbitcal.auxdata.table_status`.
    """

    t_utc_s: FloatArray
    b_body_nt: FloatArray | None
    b_itrs_nt: FloatArray
    b_nec_nt: FloatArray
    r_itrs_km: FloatArray
    field_name: str
    attitude_frame: str
    position_source: str
    eop_status: str = "observed"

    def to_frame(self) -> pd.DataFrame:
        """The field in every frame and the positions by UTC time
        (:func:`orbitcal.notebook.truth_frame`)."""
        from orbitcal.notebook import truth_frame

        return truth_frame(self)

    def to_xarray(self) -> Any:
        """:meth:`to_frame` as an xarray Dataset (needs the optional xarray)."""
        from orbitcal.notebook import frame_to_xarray

        return frame_to_xarray(self.to_frame(), attrs={"field": self.field_name})

    def __repr__(self) -> str:
        from orbitcal.notebook import truth_repr

        return truth_repr(self)


def _eop_status(t: FloatArray) -> str:
    from orbitcal.auxdata import table_status

    finite = t[np.isfinite(t)]
    if finite.size == 0:
        return "observed"
    return str(table_status("eop", float(finite.min()), float(finite.max()))["status"])


def _positions_from_orbit(orbit: Propagator, t: FloatArray) -> FloatArray:
    """Propagate ``orbit``; raise ``PropagationError`` naming the rows SGP4 flagged."""
    eph = require_valid(orbit.propagate(t))
    return np.asarray(eph.r_itrs_km, dtype=np.float64)


def truth_for_telemetry(
    telemetry: Telemetry,
    *,
    orbit: Propagator | None = None,
    attitude_frame: str = "GCRS",
    field: str | FieldModel = DEFAULT_FIELD,
) -> Truth:
    """Reference field for every sample of a telemetry table.

    Positions come from the table's ``r_x, r_y, r_z`` when present, otherwise from ``orbit``
    (an :class:`orbitcal.orbit.Orbit`, propagated with SGP4 at each sample's time).

    Parameters
    ----------
    telemetry : Telemetry
        Validated table (times in UTC).
    orbit : Propagator (e.g. orbitcal.orbit.Orbit), optional, keyword-only
        Needed when the table has no positions.
    attitude_frame : {"GCRS", "ITRS"}, keyword-only
        Frame of the table's quaternions.
    field : str or FieldModel, keyword-only
        Model name (default ``"IGRF-14"``) or a model.

    Returns
    -------
    Truth

    Raises
    ------
    ValueError
        No positions and no orbit, or an unknown frame or field name.
    orbitcal.orbit.PropagationError
        SGP4 failed for some rows (they are named; none is silently used).
    orbitcal.field.FieldRangeError
        A sample lies outside the model's validity.
    """
    frame = _frame(attitude_frame)
    model = _model(field)
    t = np.asarray(telemetry.t_utc_s, dtype=np.float64)
    if telemetry.r_itrs_km is not None:
        r = np.asarray(telemetry.r_itrs_km, dtype=np.float64)
        source = "telemetry"
    elif orbit is not None:
        r = _positions_from_orbit(orbit, t)
        source = "sgp4"
    else:
        raise BadInputError(
            "the telemetry has no positions (r_x, r_y, r_z): give the spacecraft's TLE (--tle)",
            field="r_x",
        )
    b_nec = reference_field_nec_nt(t, r, field=model)
    b_itrs = nec_to_itrs(b_nec, r)
    b_body = None
    if telemetry.q_wxyz is not None:
        b_body = _itrs_to_body(t, b_itrs, telemetry.q_wxyz, frame)
    return Truth(
        t_utc_s=t,
        b_body_nt=b_body,
        b_itrs_nt=b_itrs,
        b_nec_nt=b_nec,
        r_itrs_km=r,
        field_name=model.name,
        attitude_frame=frame,
        position_source=source,
        eop_status=_eop_status(t),
    )
