"""orbitcal.attitude against scipy (the contract's definition) and the GRACE-A rows (VirES)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from orbitcal import attitude as att

AUTHORITIES = Path(__file__).resolve().parent / "authorities"


def _grace() -> dict[str, np.ndarray]:
    """The 4 GRACE-A rows; columns as documented in the file's header."""
    rows = [
        line.split(",")
        for line in (AUTHORITIES / "GRACE_A_MAG_20100101_4rows.csv").read_text().splitlines()
        if line and not line.startswith("#")
    ]
    num = np.array([[float(x) for x in r[1:]] for r in rows])
    # Timestamp, Latitude, Longitude, Radius, B_FGM[3], B_NEC_raw[3], B_NEC[3], F, q_NEC_CRF[4], ...
    return {"B_FGM": num[:, 3:6], "B_NEC_raw": num[:, 6:9], "q_NEC_CRF": num[:, 13:17]}


def _random_q(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_frame_to_body_is_the_contract_formula() -> None:
    rng = np.random.default_rng(1)
    q = _random_q(rng, 1000)
    v = rng.normal(size=(1000, 3)) * 4e4
    expected = Rotation.from_quat(q[:, [1, 2, 3, 0]]).inv().apply(v)
    np.testing.assert_allclose(att.frame_to_body(v, q), expected, atol=1e-9)
    np.testing.assert_allclose(
        att.body_to_frame(v, q), Rotation.from_quat(att.wxyz_to_xyzw(q)).apply(v), atol=1e-9
    )


def test_frame_to_body_round_trip_and_broadcasting() -> None:
    rng = np.random.default_rng(2)
    q = _random_q(rng, 50)
    v = rng.normal(size=(50, 3))
    np.testing.assert_allclose(att.body_to_frame(att.frame_to_body(v, q), q), v, atol=1e-14)
    one = att.frame_to_body(v, q[0])
    np.testing.assert_allclose(one, att.frame_to_body(v, np.tile(q[0], (50, 1))), atol=1e-15)
    assert att.frame_to_body(v[0], q).shape == (50, 3)


def test_quaternion_is_normalised_like_scipy() -> None:
    q = np.array([2.0, 0.0, 0.0, 2.0])  # 90 deg about z, not unit
    np.testing.assert_allclose(att.frame_to_body([1.0, 0.0, 0.0], q), [0.0, -1.0, 0.0], atol=1e-15)


def test_sign_90_degrees_about_z() -> None:
    # Body rotated +90 deg about frame z: body x points along frame y, so frame y reads +x in body.
    q = np.array([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)])
    np.testing.assert_allclose(att.frame_to_body([0.0, 1.0, 0.0], q), [1.0, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(att.body_to_frame([1.0, 0.0, 0.0], q), [0.0, 1.0, 0.0], atol=1e-15)


def test_order_conversions_round_trip() -> None:
    q = np.arange(8.0).reshape(2, 4)
    np.testing.assert_array_equal(att.xyzw_to_wxyz(att.wxyz_to_xyzw(q)), q)
    np.testing.assert_array_equal(att.wxyz_to_xyzw(q)[0], [1.0, 2.0, 3.0, 0.0])


def test_norm_error() -> None:
    np.testing.assert_allclose(
        att.quat_norm_error([[1.0, 0, 0, 0], [1.002, 0, 0, 0], [0.0, 0, 0.6, 0.8]]),
        [0.0, 0.002, 0.0],
        atol=1e-15,
    )


def test_multiply_and_conjugate_match_scipy() -> None:
    rng = np.random.default_rng(3)
    p, q = _random_q(rng, 20), _random_q(rng, 20)
    pq = att.quat_multiply(p, q)
    expected = Rotation.from_quat(p[:, [1, 2, 3, 0]]) * Rotation.from_quat(q[:, [1, 2, 3, 0]])
    np.testing.assert_allclose(
        Rotation.from_quat(att.wxyz_to_xyzw(pq)).as_matrix(), expected.as_matrix(), atol=1e-14
    )
    ident = att.quat_multiply(q, att.quat_conjugate(q))
    np.testing.assert_allclose(ident, np.tile([1.0, 0, 0, 0], (20, 1)), atol=1e-15)
    np.testing.assert_array_equal(att.quat_conjugate(att.quat_conjugate(q)), q)


def test_matrix_round_trip_and_meaning() -> None:
    rng = np.random.default_rng(4)
    q = _random_q(rng, 30)
    q = np.where(q[:, :1] < 0, -q, q)
    m = att.quat_wxyz_to_matrix(q)
    v = rng.normal(size=(30, 3))
    np.testing.assert_allclose(np.einsum("nij,nj->ni", m, v), att.frame_to_body(v, q), atol=1e-14)
    np.testing.assert_allclose(att.matrix_to_quat_wxyz(m), q, atol=1e-14)
    np.testing.assert_allclose(att.quat_wxyz_to_matrix(att.matrix_to_quat_wxyz(m)), m, atol=1e-14)


def test_grace_rows_through_the_contract_convention() -> None:
    """GRACE-A: Rotation.from_quat(q_NEC_CRF).inv().apply(B_FGM) == B_NEC_raw (VirES).

    In the contract's convention with NEC as the frame and the FGM axes as the body, the GRACE
    quaternion enters as its inverse.
    """
    g = _grace()
    q_contract = att.quat_conjugate(att.xyzw_to_wxyz(g["q_NEC_CRF"]))
    b_body = att.frame_to_body(g["B_NEC_raw"], q_contract)
    assert np.max(np.abs(b_body - g["B_FGM"])) < 1e-6
    b_nec = att.body_to_frame(g["B_FGM"], q_contract)
    assert np.max(np.abs(b_nec - g["B_NEC_raw"])) < 1e-6
    # The authority's own statement, for the record.
    direct = Rotation.from_quat(g["q_NEC_CRF"]).inv().apply(g["B_FGM"])
    assert np.max(np.abs(direct - g["B_NEC_raw"])) < 1e-6
    # Using the GRACE quaternion as if it were already the contract's is wrong by thousands of nT.
    wrong = att.frame_to_body(g["B_NEC_raw"], att.xyzw_to_wxyz(g["q_NEC_CRF"]))
    assert np.min(np.linalg.norm(wrong - g["B_FGM"], axis=1)) > 1000.0


def test_shape_errors() -> None:
    with pytest.raises(ValueError, match="shape"):
        att.frame_to_body(np.zeros((2, 2)), [1.0, 0, 0, 0])
    with pytest.raises(ValueError, match="shape"):
        att.frame_to_body(np.zeros((2, 3)), [1.0, 0, 0])
