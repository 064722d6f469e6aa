"""Frame conventions: the one place where ROS (FLU body, ENU world) meets Fossen (FRD, NED).

The core works in Fossen's frames: body x forward, y starboard, z down (FRD) and world
north-east-down (NED). ROS messages follow REP-103/105: body x forward, y left, z up (FLU)
and world east-north-up (ENU). Every conversion between the two goes through this module.

Both conversions are reflections that are their own inverse, so each function converts in
either direction.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: FLU <-> FRD for a body-frame 3-vector (rotation by pi about x).
BODY_FLIP: FloatArray = np.diag([1.0, -1.0, -1.0])
#: ENU <-> NED for a world-frame 3-vector (swap x/y, negate z).
WORLD_SWAP: FloatArray = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def body_vec(v: FloatArray) -> FloatArray:
    """Convert body 3-vectors between FLU and FRD.

    Parameters
    ----------
    v : ndarray, shape (..., 3)
        Linear or angular body vectors (m/s, rad/s, N, N·m, m/s²).

    Returns
    -------
    ndarray, shape (..., 3)
    """
    # (x, y, z)_FRD = (x, -y, -z)_FLU; the same for angular vectors (proper rotation).
    return np.asarray(v, dtype=float) * np.array([1.0, -1.0, -1.0])


def body_twist(nu: FloatArray) -> FloatArray:
    """Convert 6-vectors [linear, angular] (velocity or wrench) between FLU and FRD.

    Parameters
    ----------
    nu : ndarray, shape (..., 6)

    Returns
    -------
    ndarray, shape (..., 6)
    """
    return np.asarray(nu, dtype=float) * np.array([1.0, -1.0, -1.0, 1.0, -1.0, -1.0])


def world_vec(p: FloatArray) -> FloatArray:
    """Convert world 3-vectors between ENU and NED.

    Parameters
    ----------
    p : ndarray, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3)
    """
    p = np.asarray(p, dtype=float)
    # (n, e, d) = (y_enu, x_enu, -z_enu)
    return np.stack([p[..., 1], p[..., 0], -p[..., 2]], axis=-1)


def rotation(R: FloatArray) -> FloatArray:
    """Convert body-to-world rotation matrices between (FRD→NED) and (FLU→ENU).

    Parameters
    ----------
    R : ndarray, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    # R_enu_flu = W R_ned_frd B with W, B the reflections above (both involutions).
    return WORLD_SWAP @ np.asarray(R, dtype=float) @ BODY_FLIP


def quat_to_matrix(q: FloatArray) -> FloatArray:
    """Rotation matrices from unit quaternions in scalar-first order [w, x, y, z].

    Parameters
    ----------
    q : ndarray, shape (..., 4)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty((*q.shape[:-1], 3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def matrix_to_quat(R: FloatArray) -> FloatArray:
    """Unit quaternions [w, x, y, z] (w ≥ 0) from rotation matrices.

    Parameters
    ----------
    R : ndarray, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (..., 4)
    """
    R = np.asarray(R, dtype=float)
    # Shepperd's method, vectorised: pick the largest of the four diagonal combinations.
    tr = R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2]
    cand = np.stack(
        [tr, R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]], axis=-1
    )
    k = np.argmax(cand, axis=-1)
    q = np.empty((*R.shape[:-2], 4))
    s0 = np.sqrt(np.maximum(1.0 + tr, 1e-300)) * 2
    s1 = np.sqrt(np.maximum(1.0 + R[..., 0, 0] - R[..., 1, 1] - R[..., 2, 2], 1e-300)) * 2
    s2 = np.sqrt(np.maximum(1.0 - R[..., 0, 0] + R[..., 1, 1] - R[..., 2, 2], 1e-300)) * 2
    s3 = np.sqrt(np.maximum(1.0 - R[..., 0, 0] - R[..., 1, 1] + R[..., 2, 2], 1e-300)) * 2
    options = [
        np.stack([0.25 * s0, (R[..., 2, 1] - R[..., 1, 2]) / s0,
                  (R[..., 0, 2] - R[..., 2, 0]) / s0, (R[..., 1, 0] - R[..., 0, 1]) / s0], -1),
        np.stack([(R[..., 2, 1] - R[..., 1, 2]) / s1, 0.25 * s1,
                  (R[..., 0, 1] + R[..., 1, 0]) / s1, (R[..., 0, 2] + R[..., 2, 0]) / s1], -1),
        np.stack([(R[..., 0, 2] - R[..., 2, 0]) / s2, (R[..., 0, 1] + R[..., 1, 0]) / s2,
                  0.25 * s2, (R[..., 1, 2] + R[..., 2, 1]) / s2], -1),
        np.stack([(R[..., 1, 0] - R[..., 0, 1]) / s3, (R[..., 0, 2] + R[..., 2, 0]) / s3,
                  (R[..., 1, 2] + R[..., 2, 1]) / s3, 0.25 * s3], -1),
    ]
    for i, opt in enumerate(options):
        mask = k == i
        q[mask] = opt[mask]
    q *= np.where(q[..., :1] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_frd_ned_to_flu_enu(q: FloatArray) -> FloatArray:
    """Convert attitude quaternions [w, x, y, z] between FRD→NED and FLU→ENU.

    Parameters
    ----------
    q : ndarray, shape (..., 4)

    Returns
    -------
    ndarray, shape (..., 4)
    """
    return matrix_to_quat(rotation(quat_to_matrix(q)))


def euler_from_matrix(R: FloatArray) -> FloatArray:
    """ZYX Euler angles [φ, θ, ψ] (roll, pitch, yaw, rad) of body-to-world matrices.

    Parameters
    ----------
    R : ndarray, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (..., 3)
    """
    R = np.asarray(R, dtype=float)
    phi = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    theta = -np.arcsin(np.clip(R[..., 2, 0], -1.0, 1.0))
    psi = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([phi, theta, psi], axis=-1)


def roll_pitch(q: FloatArray) -> tuple[float, float]:
    """Roll φ and pitch θ (rad) of one attitude quaternion [w, x, y, z], shape (4,).

    The numbers of ``euler_from_matrix(quat_to_matrix(q))[:2]``, computed on Python floats
    (a controller asks once per tick: numpy's per-call overhead would dominate); the arc
    functions stay numpy's, whose results can differ from :mod:`math`'s in the last bit.
    """
    w, x, y, z = np.asarray(q, dtype=float).tolist()
    n = math.sqrt(((w * w + x * x) + y * y) + z * z)  # np.linalg.norm's order
    w, x, y, z = w / n, x / n, y / n, z / n
    r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return (float(np.arctan2(r21, r22)), float(-np.arcsin(min(max(r20, -1.0), 1.0))))


def matrix_from_euler(angles: FloatArray) -> FloatArray:
    """Body-to-world matrices R = Rz(ψ) Ry(θ) Rx(φ) from ZYX Euler angles.

    Parameters
    ----------
    angles : ndarray, shape (..., 3)
        [φ, θ, ψ] in rad.

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    a = np.asarray(angles, dtype=float)
    cf, sf = np.cos(a[..., 0]), np.sin(a[..., 0])
    ct, st = np.cos(a[..., 1]), np.sin(a[..., 1])
    cp, sp = np.cos(a[..., 2]), np.sin(a[..., 2])
    R = np.empty((*a.shape[:-1], 3, 3))
    R[..., 0, 0] = cp * ct
    R[..., 0, 1] = -sp * cf + cp * st * sf
    R[..., 0, 2] = sp * sf + cp * cf * st
    R[..., 1, 0] = sp * ct
    R[..., 1, 1] = cp * cf + sf * st * sp
    R[..., 1, 2] = -cp * sf + st * sp * cf
    R[..., 2, 0] = -st
    R[..., 2, 1] = ct * sf
    R[..., 2, 2] = ct * cf
    return R


def wxyz_to_xyzw(q: FloatArray) -> FloatArray:
    """Quaternions [w, x, y, z] (M, 4) reordered as ROS stores them, [x, y, z, w]."""
    return q[:, [1, 2, 3, 0]]


def quat_mul(a: FloatArray, b: FloatArray) -> FloatArray:
    """Hamilton products a ⊗ b of quaternions [w, x, y, z], shapes (M, 4)."""
    aw, av = a[:, :1], a[:, 1:]
    bw, bv = b[:, :1], b[:, 1:]
    # (a_w b_w − a_v·b_v, a_w b_v + b_w a_v + a_v × b_v)
    w = aw * bw - np.sum(av * bv, axis=1, keepdims=True)
    v = aw * bv + bw * av + np.cross(av, bv)
    return np.concatenate([w, v], axis=1)


def small_rotation(dtheta: FloatArray) -> FloatArray:
    """Unit quaternions [w, x, y, z] (M, 4) of rotation vectors (M, 3) (rad)."""
    angle = np.linalg.norm(dtheta, axis=1, keepdims=True)
    # exp(δθ/2) = [cos(|δθ|/2), sin(|δθ|/2) δθ/|δθ|]; sin(a/2)/a = ½ sinc(a / 2π), safe at 0
    return np.concatenate([np.cos(angle / 2.0), 0.5 * np.sinc(angle / (2.0 * np.pi)) * dtheta],
                          axis=1)


def continuous(q: FloatArray) -> FloatArray:
    """Flip quaternion signs so that consecutive ones have a non-negative dot product."""
    if len(q) < 2:
        return q
    flip = np.where(np.einsum("ni,ni->n", q[1:], q[:-1]) < 0.0, -1.0, 1.0)
    # sign_k = Π_{j ≤ k} sign(q_{j−1} · q_j): the running product of the flips
    sign = np.concatenate([[1.0], np.cumprod(flip)])
    return q * sign[:, None]


def body_rates(q: FloatArray, q_dot: FloatArray) -> FloatArray:
    """Body angular velocity from attitude quaternions and their time derivatives.

    Parameters
    ----------
    q : ndarray, shape (M, 4)
        Body-to-world unit quaternions [w, x, y, z] (as :func:`quat_to_matrix` reads them),
        sign-continuous (:func:`continuous`).
    q_dot : ndarray, shape (M, 4)
        Their time derivatives (1/s).

    Returns
    -------
    ndarray, shape (M, 3)
        ω in the body frame of ``q`` (rad/s): FRD for an FRD→NED attitude.
    """
    conj = q * np.array([1.0, -1.0, -1.0, -1.0])
    # q̇ = ½ q ⊗ [0, ω_body]  ⇒  ω_body = 2 vec(q* ⊗ q̇) / |q|² (|q| = 1 up to interpolation)
    w = quat_mul(conj, q_dot)[:, 1:]
    return np.asarray(2.0 * w / np.sum(q * q, axis=1, keepdims=True), dtype=float)


def cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """a × b over the last axis (shapes (..., 3), broadcast): np.cross (the same products and
    differences, so the same bits) without its ~20 µs of overhead per call, which the online
    preprocessing pays per message and the regressors per chunk."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.ndim == 1 and b.ndim == 1:  # one vector each: Python floats are faster still
        (a1, a2, a3), (b1, b2, b3) = a.tolist(), b.tolist()
        # (a₂b₃ − a₃b₂, a₃b₁ − a₁b₃, a₁b₂ − a₂b₁)
        return np.array([a2 * b3 - a3 * b2, a3 * b1 - a1 * b3, a1 * b2 - a2 * b1])
    # the same, per row
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)
