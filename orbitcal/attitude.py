"""Attitude quaternions in the contract's convention (CONTRACT section 1).

The telemetry columns ``q_w, q_x, q_y, q_z`` give the body's orientation in the attitude frame
(GCRS by default, or ITRS). Inside orbitcal they are ``q_wxyz``, shape ``(N, 4)``, scalar first, and
mean exactly::

    v_body = scipy.spatial.transform.Rotation.from_quat([q_x, q_y, q_z, q_w]).inv().apply(v_frame)

so ``R(q)`` (the matrix of ``Rotation.from_quat``) maps body components to frame components, and
its transpose maps frame components to body components. Every function here is plain numpy,
vectorised over rows; a single quaternion ``(4,)`` or vector ``(3,)`` broadcasts against
``(N, ...)``.
Quaternions are normalised before use, as scipy does.

Other conventions must be converted explicitly. Example (GRACE/VirES ``q_NEC_CRF``, scalar last,
with ``Rotation.from_quat(q_NEC_CRF).inv().apply(B_FGM) == B_NEC``): with NEC as the attitude frame
the contract quaternion is its inverse, ``quat_conjugate(xyzw_to_wxyz(q_NEC_CRF))``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from orbitcal.arrays import FloatArray

__all__ = [
    "body_to_frame",
    "frame_to_body",
    "matrix_to_quat_wxyz",
    "quat_conjugate",
    "quat_multiply",
    "quat_norm_error",
    "quat_normalize",
    "quat_wxyz_to_matrix",
    "wxyz_to_xyzw",
    "xyzw_to_wxyz",
]


def _q(q: npt.ArrayLike) -> FloatArray:
    arr = np.asarray(q, dtype=np.float64)
    if arr.shape[-1:] != (4,):
        raise ValueError(f"quaternions must have shape (..., 4), got {arr.shape}")
    return arr


def _v(v: npt.ArrayLike) -> FloatArray:
    arr = np.asarray(v, dtype=np.float64)
    if arr.shape[-1:] != (3,):
        raise ValueError(f"vectors must have shape (..., 3), got {arr.shape}")
    return arr


def wxyz_to_xyzw(q_wxyz: npt.ArrayLike) -> FloatArray:
    """Scalar first ``(w, x, y, z)`` → scalar last ``(x, y, z, w)`` (scipy's), shape (..., 4)."""
    q = _q(q_wxyz)
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def xyzw_to_wxyz(q_xyzw: npt.ArrayLike) -> FloatArray:
    """Scalar-last ``(x, y, z, w)`` → scalar-first ``(w, x, y, z)``, shape (..., 4)."""
    q = _q(q_xyzw)
    return np.concatenate([q[..., 3:], q[..., :3]], axis=-1)


def quat_norm_error(q_wxyz: npt.ArrayLike) -> FloatArray:
    """``| |q| − 1 |`` per row, shape (...,); the contract rejects rows above 1e-3."""
    return np.abs(np.linalg.norm(_q(q_wxyz), axis=-1) - 1.0)


def quat_normalize(q_wxyz: npt.ArrayLike) -> FloatArray:
    """Unit quaternions, shape (..., 4) (rows of zero norm become NaN)."""
    q = _q(q_wxyz)
    with np.errstate(invalid="ignore", divide="ignore"):
        return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_conjugate(q_wxyz: npt.ArrayLike) -> FloatArray:
    """Conjugate ``(w, −x, −y, −z)``: the inverse rotation of a unit quaternion, shape (..., 4)."""
    q = _q(q_wxyz).copy()
    q[..., 1:] *= -1.0
    return q


def quat_multiply(p_wxyz: npt.ArrayLike, q_wxyz: npt.ArrayLike) -> FloatArray:
    """Hamilton product ``p ⊗ q``, scalar first, shape (..., 4) (broadcasting).

    Its rotation is ``R(p ⊗ q) = R(p) @ R(q)``, as scipy's ``Rotation.from_quat(p) *
    Rotation.from_quat(q)``: e.g. with ``p`` the orientation of frame B in frame A and ``q`` the
    body's orientation in frame B, ``p ⊗ q`` is the body's orientation in frame A.
    """
    p = _q(p_wxyz)
    q = _q(q_wxyz)
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def _rotate(v: FloatArray, q_unit: FloatArray, *, inverse: bool) -> FloatArray:
    """Rotate ``v`` by ``R(q)`` (or its transpose): ``v + 2w (u × v) + 2 u × (u × v)``.

    Written per component (no ``np.cross`` temporaries); about as fast as scipy's ``apply``.
    """
    w = q_unit[..., 0]
    sign = -1.0 if inverse else 1.0
    ux, uy, uz = sign * q_unit[..., 1], sign * q_unit[..., 2], sign * q_unit[..., 3]
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    tx = 2.0 * (uy * vz - uz * vy)
    ty = 2.0 * (uz * vx - ux * vz)
    tz = 2.0 * (ux * vy - uy * vx)
    shape = np.broadcast_shapes(v.shape, (*q_unit.shape[:-1], 3))
    out = np.empty(shape, dtype=np.float64)
    out[..., 0] = vx + w * tx + (uy * tz - uz * ty)
    out[..., 1] = vy + w * ty + (uz * tx - ux * tz)
    out[..., 2] = vz + w * tz + (ux * ty - uy * tx)
    return out


def frame_to_body(v_frame: npt.ArrayLike, q_wxyz: npt.ArrayLike) -> FloatArray:
    """Frame components → body components: ``Rotation.from_quat(xyzw).inv().apply(v_frame)``.

    Parameters
    ----------
    v_frame : array_like, shape (N, 3) or (3,)
        Vectors in the attitude frame (e.g. ``b_gcrs_nt`` [nT]).
    q_wxyz : array_like, shape (N, 4) or (4,)
        The body's orientation in that frame, scalar first (contract columns ``q_w..q_z``).

    Returns
    -------
    ndarray, shape (N, 3)
        The same vectors in body axes (same unit).
    """
    return _rotate(_v(v_frame), quat_normalize(q_wxyz), inverse=True)


def body_to_frame(v_body: npt.ArrayLike, q_wxyz: npt.ArrayLike) -> FloatArray:
    """Body components → frame components: ``Rotation.from_quat(xyzw).apply(v_body)``.

    Inverse of :func:`frame_to_body`; shapes as there.
    """
    return _rotate(_v(v_body), quat_normalize(q_wxyz), inverse=False)


def quat_wxyz_to_matrix(q_wxyz: npt.ArrayLike) -> FloatArray:
    """Quaternion → the matrix ``R_frame_to_body`` with ``v_body = R_frame_to_body @ v_frame``.

    That is the transpose of scipy's ``Rotation.from_quat(xyzw).as_matrix()``; shape (..., 3, 3).
    """
    q = quat_normalize(q_wxyz)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    # R(q) (body -> frame), written row by row, then transposed.
    r_body_to_frame = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )
    return np.swapaxes(r_body_to_frame, -1, -2)


def matrix_to_quat_wxyz(R_frame_to_body: npt.ArrayLike) -> FloatArray:
    """``R_frame_to_body`` (``v_body = R @ v_frame``) → ``q_wxyz`` with ``w ≥ 0``, shape (..., 4).

    Inverse of :func:`quat_wxyz_to_matrix` (up to the sign of ``q``).
    """
    from scipy.spatial.transform import Rotation

    m = np.asarray(R_frame_to_body, dtype=np.float64)
    if m.shape[-2:] != (3, 3):
        raise ValueError(f"matrices must have shape (..., 3, 3), got {m.shape}")
    lead = m.shape[:-2]
    flat = np.swapaxes(m, -1, -2).reshape(-1, 3, 3)
    q = xyzw_to_wxyz(Rotation.from_matrix(flat).as_quat())
    q = np.where(q[:, :1] < 0.0, -q, q)
    return q.reshape(*lead, 4)
