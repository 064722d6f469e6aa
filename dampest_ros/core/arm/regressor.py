"""The arm's regressor τ = Y(q, q̇, q̈) π, vectorised over samples, with the friction columns.

Rigid body: the Newton–Euler recursion of :class:`~dampest_ros.core.arm.model.ArmModel`
run on all samples at once (joint by joint, numpy over samples), with every link's wrench
written linearly in its ten inertial parameters (Pinocchio's order and frame) and projected
on the joint axes. It equals Pinocchio's ``computeJointTorqueRegressor``
(:func:`pinocchio_regressor`, one call per sample) and the columns MuJoCo's ``mj_inverse``
gives (:mod:`dampest_ros.core.arm.mjinverse`) to rounding.

Joint columns, four per joint j, acting on τ_j only: armature q̈_j (kg m²), viscous q̇_j
(N m s/rad), Coulomb s(q̇_j) (N m) and offset 1 (N m), where s is sign or, with a width
w > 0, the smooth tanh(q̇/w).

Full parameter vector: π = [π_1 … π_n (ten each, link by link), then per joint
(Ia, Fv, Fc, off)], length 14 n.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.arm.model import INERTIAL_NAMES, ArmModel, JointDynamics

FloatArray = NDArray[np.float64]

#: Names of the four joint parameters, in column order.
JOINT_NAMES = ("Ia", "Fv", "Fc", "off")


def parameter_names(arm: ArmModel) -> list[str]:
    """Names of the full parameter vector, ``<joint>.<name>`` (length 14 n)."""
    return ([f"{j}.{p}" for j in arm.names for p in INERTIAL_NAMES]
            + [f"{j}.{p}" for j in arm.names for p in JOINT_NAMES])


def full_parameters(arm: ArmModel, dynamics: JointDynamics,
                    offset: FloatArray | None = None) -> FloatArray:
    """The full parameter vector of an arm's nominal inertias and the given joint dynamics.

    Parameters
    ----------
    arm : ArmModel
    dynamics : JointDynamics
    offset : ndarray, shape (n,), optional
        Torque offsets (N m); zero by default.

    Returns
    -------
    ndarray, shape (14 n,)
    """
    off = np.zeros(arm.n) if offset is None else np.asarray(offset, dtype=float)
    joint = np.stack([dynamics.armature, dynamics.damping, dynamics.frictionloss, off], axis=1)
    return np.concatenate([arm.inertial.ravel(), joint.ravel()])


def _rot(axis: FloatArray, angle: FloatArray) -> FloatArray:
    """Rotations about one unit axis by N angles (Rodrigues), shape (N, 3, 3)."""
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                  [-axis[1], axis[0], 0.0]])
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    # R = I + sin θ K + (1 − cos θ) K²
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """a × b over the last axis (broadcast), without numpy.cross's axis handling."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


#: The six symmetric unit matrices of (I_xx, I_xy, I_yy, I_xz, I_yz, I_zz), shape (6, 3, 3).
_SYM = np.zeros((6, 3, 3))
for _k, (_r, _c) in enumerate(((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))):
    _SYM[_k, _r, _c] = _SYM[_k, _c, _r] = 1.0
#: x @ _SYM_FLAT, reshaped (N, 6, 3): the six products E_k x of a batch of vectors x.
_SYM_FLAT = _SYM.transpose(1, 0, 2).reshape(3, 18)


def _link_wrench_columns(v: FloatArray, w: FloatArray, a: FloatArray, al: FloatArray
                         ) -> tuple[FloatArray, FloatArray]:
    """Columns of a link's wrench in its ten inertial parameters, in the link frame.

    Parameters
    ----------
    v, w : ndarray, shape (N, 3)
        Linear velocity of the frame origin and angular velocity (m/s, rad/s).
    a, al : ndarray, shape (N, 3)
        Spatial linear acceleration (gravity included as a base acceleration) and angular
        acceleration (m/s², rad/s²).

    Returns
    -------
    f, n : ndarray, shape (N, 10, 3)
        Force (N) and moment about the frame origin (N m) per unit parameter.
    """
    N = v.shape[0]
    f = np.zeros((N, 10, 3))
    n = np.zeros((N, 10, 3))
    acc = a + _cross(w, v)  # acceleration of the origin (classical): a + ω × v
    f[:, 0] = acc  # f = m (a + ω × v) + ...
    eye = np.eye(3)[None]  # (1, 3, 3): row k = e_k
    # f += α × (m c) + ω × (ω × (m c));  n += (m c) × (a + ω × v)
    f[:, 1:4] = _cross(al[:, None], eye) + _cross(w[:, None], _cross(w[:, None], eye))
    n[:, 1:4] = _cross(eye, acc[:, None])
    # n += I α + ω × (I ω), I = Σ_k I_k E_k
    n[:, 4:] = (al @ _SYM_FLAT).reshape(N, 6, 3) + _cross(w[:, None],
                                                          (w @ _SYM_FLAT).reshape(N, 6, 3))
    return f, n


def rigid_regressor(arm: ArmModel, q: FloatArray, qd: FloatArray, qdd: FloatArray
                    ) -> FloatArray:
    """Rigid-body regressor: τ_rb = Y_rb π_inertial, vectorised over samples.

    Parameters
    ----------
    arm : ArmModel
    q, qd, qdd : ndarray, shape (N, n)
        Joint positions (rad), velocities (rad/s), accelerations (rad/s²).

    Returns
    -------
    ndarray, shape (N, n, 10 n)
        Row i of sample k: the joint torque τ_i (N m) per inertial parameter.
    """
    q, qd, qdd = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, qd, qdd))
    N, n = q.shape
    # forward pass: velocities/accelerations in each joint frame and its world pose
    Rw = np.empty((n, N, 3, 3))
    pw = np.empty((n, N, 3))
    screw = np.empty((N, 6, n))  # world screw of each joint axis: (p × z, z)
    wrench = []
    state: dict[int, tuple[FloatArray, FloatArray, FloatArray, FloatArray]] = {}
    for j in range(n):
        R = arm.rotation[j] @ _rot(arm.axis[j], q[:, j])  # joint j in its parent at q_j
        p = arm.translation[j]
        s = arm.axis[j]
        par = int(arm.parents[j])
        if par < 0:
            zero = np.zeros((N, 3))
            v0, w0, a0, al0 = zero, zero, np.broadcast_to(-arm.gravity, (N, 3)), zero
            Rw[j], pw[j] = R, np.broadcast_to(p, (N, 3))
        else:
            v0, w0, a0, al0 = state[par]
            Rw[j] = Rw[par] @ R
            pw[j] = pw[par] + Rw[par] @ p
        Rt = np.swapaxes(R, 1, 2)
        sq, sqq = s * qd[:, j:j + 1], s * qdd[:, j:j + 1]
        # motion transform to the child origin: ω_j = Rᵀ ω + s q̇, v_j = Rᵀ (v + ω × p)
        w = (Rt @ w0[:, :, None])[:, :, 0] + sq
        v = (Rt @ (v0 + _cross(w0, p))[:, :, None])[:, :, 0]
        # spatial acceleration: α_j = Rᵀ α + s q̈ + ω_j × s q̇, a_j = Rᵀ(a + α × p) + v_j × s q̇
        al = (Rt @ al0[:, :, None])[:, :, 0] + sqq + _cross(w, sq)
        a = (Rt @ (a0 + _cross(al0, p))[:, :, None])[:, :, 0] + _cross(v, sq)
        state[j] = (v, w, a, al)
        z = Rw[j] @ s  # joint axis in the world
        screw[:, :3, j] = _cross(pw[j], z)
        screw[:, 3:, j] = z
        f, m = _link_wrench_columns(v, w, a, al)
        # to the world frame: f_w = R f, n_w (about the world origin) = R n + p × f_w, on the
        # rows that are not zero (the inertias exert no force, the mass no moment)
        RwT = np.swapaxes(Rw[j], 1, 2)
        fw = f[:, :4] @ RwT
        wj = np.zeros((N, 10, 6))
        wj[:, :4, :3] = fw
        wj[:, :4, 3:] = _cross(pw[j][:, None], fw)
        wj[:, 1:, 3:] += m[:, 1:] @ RwT
        wrench.append(wj)
    # τ_i = z_i · n + (p_i × z_i) · f, every link's columns at once (the screws (n, 6) times
    # the wrench columns (6, 10 n) per sample), kept for the joints i between link j and the
    # base
    Y = np.matmul(np.swapaxes(screw, 1, 2), np.swapaxes(np.concatenate(wrench, axis=1), 1, 2))
    Y *= _loaded(arm)
    return Y


def _loaded(arm: ArmModel) -> FloatArray:
    """Mask of the rigid regressor's columns, shape (n, 10 n): 1 where link j (columns
    10 j … 10 j + 9) loads joint i (row i), i.e. joint i is j or one of its ancestors."""
    mask = np.zeros((arm.n, arm.n))
    for j in range(arm.n):
        mask[_ancestors(arm, j), j] = 1.0
    return np.repeat(mask, 10, axis=1)


def _ancestors(arm: ArmModel, j: int) -> list[int]:
    """Joint j and the joints between it and the base (whose torques link j loads)."""
    out = []
    while j >= 0:
        out.append(j)
        j = int(arm.parents[j])
    return out


def joint_columns(qd: FloatArray, qdd: FloatArray, coulomb_width: float = 0.0) -> FloatArray:
    """The four columns per joint (armature, viscous, Coulomb, offset) on that joint's row.

    Parameters
    ----------
    qd, qdd : ndarray, shape (N, n)
        Joint velocities (rad/s) and accelerations (rad/s²).
    coulomb_width : float
        0 for sign(q̇); w > 0 for tanh(q̇ / w) (rad/s).

    Returns
    -------
    ndarray, shape (N, n, 4 n)
    """
    qd, qdd = np.atleast_2d(qd), np.atleast_2d(qdd)
    N, n = qd.shape
    sgn = np.sign(qd) if coulomb_width <= 0 else np.tanh(qd / coulomb_width)
    per = np.stack([qdd, qd, sgn, np.ones_like(qd)], axis=2)  # (N, n, 4)
    out = np.zeros((N, n, n, 4))
    idx = np.arange(n)
    out[:, idx, idx, :] = per
    return out.reshape(N, n, 4 * n)


def regressor(arm: ArmModel, q: FloatArray, qd: FloatArray, qdd: FloatArray,
              coulomb_width: float = 0.0) -> FloatArray:
    """Full regressor τ = Y π: rigid body then joint columns.

    Parameters
    ----------
    arm : ArmModel
    q, qd, qdd : ndarray, shape (N, n)
    coulomb_width : float
        See :func:`joint_columns`.

    Returns
    -------
    ndarray, shape (N, n, 14 n)
    """
    return np.concatenate([rigid_regressor(arm, q, qd, qdd),
                           joint_columns(qd, qdd, coulomb_width)], axis=2)


def pinocchio_regressor(arm: ArmModel, q: FloatArray, qd: FloatArray, qdd: FloatArray
                        ) -> FloatArray:
    """The rigid-body regressor from Pinocchio's analytic ``computeJointTorqueRegressor``,
    one call per sample: the reference :func:`rigid_regressor` is checked against.

    Parameters
    ----------
    arm : ArmModel
    q, qd, qdd : ndarray, shape (N, n)

    Returns
    -------
    ndarray, shape (N, n, 10 n)
    """
    import pinocchio as pin  # type: ignore[import-untyped]

    model, data = arm.pinocchio()
    return np.array([pin.computeJointTorqueRegressor(model, data, a, b, c)
                     for a, b, c in zip(np.atleast_2d(q), np.atleast_2d(qd),
                                        np.atleast_2d(qdd), strict=True)], dtype=float)
