"""Frame conventions (dampest_ros.core.physics.frames): FRD/NED (Fossen) against FLU/ENU
(REP-103)."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.physics.frames import (
    body_twist,
    body_vec,
    euler_from_matrix,
    matrix_from_euler,
    matrix_to_quat,
    quat_frd_ned_to_flu_enu,
    quat_to_matrix,
    roll_pitch,
    rotation,
    world_vec,
)


def random_quats(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniformly distributed unit quaternions [w, x, y, z] with w ≥ 0."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q * np.where(q[:, :1] < 0, -1.0, 1.0)


def axis_angle_quat(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Quaternions of rotations by ``angle`` (N,) about unit ``axis`` (N, 3)."""
    return np.concatenate([np.cos(angle / 2)[:, None], np.sin(angle / 2)[:, None] * axis], 1)


def same_rotation(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Distance between quaternions up to the sign ambiguity q ≡ −q, shape (N,)."""
    return np.minimum(np.linalg.norm(q1 - q2, axis=-1), np.linalg.norm(q1 + q2, axis=-1))


# --- body and world vectors -----------------------------------------------------------------


def test_forward_surge_is_plus_x_in_flu() -> None:
    np.testing.assert_array_equal(body_twist([1.5, 0, 0, 0, 0, 0]), [1.5, 0, 0, 0, 0, 0])


def test_starboard_sway_is_minus_y_in_flu() -> None:
    np.testing.assert_array_equal(body_twist([0, 0.4, 0, 0, 0, 0]), [0, -0.4, 0, 0, 0, 0])
    np.testing.assert_array_equal(body_vec([0, 0.4, 0]), [0, -0.4, 0])


def test_heave_down_is_minus_z_in_flu() -> None:
    np.testing.assert_array_equal(body_twist([0, 0, 0.3, 0, 0, 0]), [0, 0, -0.3, 0, 0, 0])


def test_angular_rates_follow_the_same_flip() -> None:
    # roll rate about the shared forward axis is unchanged; pitch and yaw rates flip with
    # the y and z axes: (p, q, r)_FLU = (p, −q, −r)_FRD.
    np.testing.assert_array_equal(body_twist([0, 0, 0, 0.1, 0.2, 0.3]),
                                  [0, 0, 0, 0.1, -0.2, -0.3])


def test_body_conversion_is_an_involution() -> None:
    x = np.random.default_rng(1).normal(size=(50, 6))
    np.testing.assert_array_equal(body_twist(body_twist(x)), x)
    np.testing.assert_array_equal(body_vec(body_vec(x[:, :3])), x[:, :3])


def test_ned_north_is_enu_plus_y() -> None:
    np.testing.assert_array_equal(world_vec([1.0, 0.0, 0.0]), [0.0, 1.0, 0.0])


def test_ned_east_is_enu_plus_x() -> None:
    np.testing.assert_array_equal(world_vec([0.0, 1.0, 0.0]), [1.0, 0.0, 0.0])


def test_ned_down_is_enu_minus_z() -> None:
    np.testing.assert_array_equal(world_vec([0.0, 0.0, 2.0]), [0.0, 0.0, -2.0])


def test_world_conversion_is_an_involution_and_vectorised() -> None:
    p = np.random.default_rng(2).normal(size=(4, 5, 3))
    np.testing.assert_array_equal(world_vec(world_vec(p)), p)
    assert world_vec(p).shape == (4, 5, 3)


def test_rotation_conversion_commutes_with_vector_conversions() -> None:
    # R_enu_flu · v_flu must be the ENU form of R_ned_frd · v_frd for every vector.
    rng = np.random.default_rng(3)
    R = quat_to_matrix(random_quats(rng, 200))
    v = rng.normal(size=(200, 3))
    lhs = np.einsum("nij,nj->ni", rotation(R), body_vec(v))
    rhs = world_vec(np.einsum("nij,nj->ni", R, v))
    np.testing.assert_allclose(lhs, rhs, rtol=0, atol=1e-14)
    # and the result is a proper rotation again
    Rr = rotation(R)
    np.testing.assert_allclose(np.linalg.det(Rr), 1.0, atol=1e-12)
    np.testing.assert_allclose(Rr @ np.swapaxes(Rr, -1, -2), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-12)


# --- quaternions -----------------------------------------------------------------------------


def test_quaternion_round_trip_random() -> None:
    rng = np.random.default_rng(4)
    q = random_quats(rng, 1000)
    R = quat_to_matrix(q)
    q_back = matrix_to_quat(R)
    assert np.all(q_back[:, 0] >= 0)
    np.testing.assert_allclose(q_back, q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(quat_to_matrix(q_back), R, rtol=0, atol=1e-12)


@pytest.mark.parametrize("epsilon", [0.0, 1e-12, 1e-8, 1e-4])
def test_quaternion_round_trip_near_180_degrees(epsilon: float) -> None:
    # rotations by π − ε: w = sin(ε/2) ≈ 0, where a trace-based formula loses all precision
    rng = np.random.default_rng(5)
    n = 1000
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    q = axis_angle_quat(axis, np.full(n, np.pi - epsilon))
    R = quat_to_matrix(q)
    q_back = matrix_to_quat(R)
    np.testing.assert_allclose(np.linalg.norm(q_back, axis=1), 1.0, atol=1e-14)
    assert same_rotation(q_back, q).max() < 1e-12
    np.testing.assert_allclose(quat_to_matrix(q_back), R, rtol=0, atol=1e-12)


def test_quaternion_of_known_rotations() -> None:
    # 90° yaw (about +z): x → y
    q = np.array([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)])
    np.testing.assert_allclose(quat_to_matrix(q) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(matrix_to_quat(matrix_from_euler([0.0, 0.0, np.pi / 2])), q,
                               atol=1e-15)
    # 180° about x: y → −y, z → −z
    np.testing.assert_allclose(matrix_to_quat(np.diag([1.0, -1.0, -1.0])), [0, 1, 0, 0],
                               atol=1e-15)


def test_quaternion_input_is_normalised() -> None:
    q = np.array([0.3, -0.2, 0.5, 0.7])
    np.testing.assert_allclose(quat_to_matrix(5.0 * q), quat_to_matrix(q), atol=1e-15)


# --- Euler angles ------------------------------------------------------------------------------


def test_euler_round_trip_and_zyx_order() -> None:
    rng = np.random.default_rng(6)
    ang = np.column_stack([rng.uniform(-np.pi, np.pi, 500), rng.uniform(-1.5, 1.5, 500),
                           rng.uniform(-np.pi, np.pi, 500)])
    R = matrix_from_euler(ang)
    np.testing.assert_allclose(euler_from_matrix(R), ang, atol=1e-12)

    def rx(a: float) -> np.ndarray:
        return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])

    def ry(a: float) -> np.ndarray:
        return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])

    def rz(a: float) -> np.ndarray:
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])

    for phi, theta, psi in ang[:20]:
        np.testing.assert_allclose(matrix_from_euler([phi, theta, psi]),
                                   rz(psi) @ ry(theta) @ rx(phi), atol=1e-15)


# --- attitude quaternion FRD/NED ↔ FLU/ENU --------------------------------------------------


def test_identity_attitude_heading_north_in_enu() -> None:
    q_enu = quat_frd_ned_to_flu_enu(np.array([1.0, 0.0, 0.0, 0.0]))
    R = quat_to_matrix(q_enu)
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-15)  # body x → north (+y)
    np.testing.assert_allclose(R @ [0, 0, 1], [0, 0, 1], atol=1e-15)  # body z (up) → up
    np.testing.assert_allclose(R @ [0, 1, 0], [-1, 0, 0], atol=1e-15)  # body left → west
    # i.e. a yaw of +90° in ENU: [cos 45°, 0, 0, sin 45°]
    np.testing.assert_allclose(q_enu, [np.sqrt(0.5), 0, 0, np.sqrt(0.5)], atol=1e-15)


def test_heading_east_in_ned_is_enu_identity() -> None:
    q_ned = matrix_to_quat(matrix_from_euler([0.0, 0.0, np.pi / 2]))
    np.testing.assert_allclose(quat_frd_ned_to_flu_enu(q_ned), [1, 0, 0, 0], atol=1e-15)


def test_attitude_conversion_is_an_involution() -> None:
    q = random_quats(np.random.default_rng(7), 500)
    back = quat_frd_ned_to_flu_enu(quat_frd_ned_to_flu_enu(q))
    assert same_rotation(back, q).max() < 1e-12


def test_roll_pitch_is_the_euler_angles_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    q = rng.normal(size=(2000, 4)) * rng.uniform(0.5, 1.5, size=(2000, 1))  # not normalised
    angles = euler_from_matrix(quat_to_matrix(q))
    for k in range(len(q)):
        assert roll_pitch(q[k]) == (float(angles[k, 0]), float(angles[k, 1]))
    # known truth: roll 0.3, pitch −0.2, yaw 1.1 rad
    R = matrix_from_euler(np.array([0.3, -0.2, 1.1]))
    np.testing.assert_allclose(roll_pitch(matrix_to_quat(R)), (0.3, -0.2), rtol=0, atol=1e-15)
