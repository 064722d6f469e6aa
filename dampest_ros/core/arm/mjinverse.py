"""The MuJoCo side of the arm regressor: a link's ten inertial parameters read from and
written to a MuJoCo model, inverse dynamics with ``mj_inverse``, and the regressor's columns
found numerically from it (inverse dynamics is linear in the parameters, so a finite
difference of one parameter is its column up to rounding).

MuJoCo's body frame of a link is its joint frame (the joint sits at the body origin), so
its parameters are the same ten numbers as Pinocchio's. MuJoCo's joint terms map to the
regressor's joint columns: ``armature`` → Ia (τ += Ia q̈), ``damping`` → Fv (τ += Fv q̇) and
``frictionloss`` → Fc (τ += Fc sign q̇ once the soft friction constraint saturates).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def body_parameters(model: Any, body: int) -> FloatArray:
    """The ten inertial parameters of a MuJoCo body in its own frame.

    Parameters
    ----------
    model : mujoco.MjModel
    body : int
        Body id.

    Returns
    -------
    ndarray, shape (10,)
        [m, m c, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz] about the body origin.
    """
    import mujoco

    m = float(model.body_mass[body])
    c = np.array(model.body_ipos[body], dtype=float)
    flat = np.empty(9)
    mujoco.mju_quat2Mat(flat, np.array(model.body_iquat[body], dtype=float))
    R = flat.reshape(3, 3)
    # I_o = R diag(I) Rᵀ + m (|c|² 1 − c cᵀ)  (principal inertia moved to the origin)
    Io = (R * np.array(model.body_inertia[body], dtype=float)) @ R.T
    Io += m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
    return np.array([m, *(m * c), Io[0, 0], Io[0, 1], Io[1, 1], Io[0, 2], Io[1, 2], Io[2, 2]])


def set_body_parameters(model: Any, data: Any, body: int, params: FloatArray) -> None:
    """Write ten inertial parameters into a MuJoCo body (mass, centre, principal inertia).

    Parameters
    ----------
    model : mujoco.MjModel
        Changed in place; its derived constants are recomputed (``mj_setConst``).
    data : mujoco.MjData
    body : int
    params : ndarray, shape (10,)
        As :func:`body_parameters` returns; the mass must be positive and the inertia about
        the centre positive definite.

    Raises
    ------
    ValueError
        If the parameters are not those of a physical body.
    """
    import mujoco

    p = np.asarray(params, dtype=float)
    m = p[0]
    if not m > 0:
        raise ValueError(f"body {body}: mass {m} is not positive")
    c = p[1:4] / m
    Io = np.array([[p[4], p[5], p[7]], [p[5], p[6], p[8]], [p[7], p[8], p[9]]])
    # I_c = I_o − m (|c|² 1 − c cᵀ)
    Ic = Io - m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
    vals, vecs = np.linalg.eigh(Ic)
    if not vals.min() > 0:
        raise ValueError(f"body {body}: inertia about the centre of mass is not positive "
                         f"definite (eigenvalues {vals})")
    if np.linalg.det(vecs) < 0:
        vecs[:, 2] = -vecs[:, 2]
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, vecs.ravel())
    model.body_mass[body] = m
    model.body_ipos[body] = c
    model.body_iquat[body] = quat
    model.body_inertia[body] = vals
    mujoco.mj_setConst(model, data)


def joint_bodies(model: Any, names: tuple[str, ...]) -> tuple[list[int], list[int]]:
    """Body id and dof index of each named joint.

    Raises
    ------
    ValueError
        If a joint is not in the model.
    """
    import mujoco

    bodies, dofs = [], []
    for name in names:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            raise ValueError(f"joint {name!r} is not in the MuJoCo model")
        bodies.append(int(model.jnt_bodyid[jid]))
        dofs.append(int(model.jnt_dofadr[jid]))
    return bodies, dofs


def inverse_dynamics(model: Any, q: FloatArray, qd: FloatArray, qdd: FloatArray
                     ) -> FloatArray:
    """τ from MuJoCo's ``mj_inverse`` per sample (rigid body, armature, damping, and the
    friction loss as MuJoCo's inverse soft constraint gives it).

    Parameters
    ----------
    model : mujoco.MjModel
    q, qd, qdd : ndarray, shape (N, nv)

    Returns
    -------
    ndarray, shape (N, nv)
        Generalised force (N m).
    """
    import mujoco

    data = mujoco.MjData(model)
    out = np.empty_like(np.asarray(q, dtype=float))
    for k in range(out.shape[0]):
        data.qpos[:], data.qvel[:], data.qacc[:] = q[k], qd[k], qdd[k]
        mujoco.mj_inverse(model, data)
        out[k] = data.qfrc_inverse
    return out


def numerical_regressor(mjcf_xml: str, names: tuple[str, ...], q: FloatArray, qd: FloatArray,
                        qdd: FloatArray, delta: float = 0.05) -> FloatArray:
    """The rigid-body regressor from ``mj_inverse``: one column per parameter, as the change
    of τ when that parameter takes a step (exact up to rounding, since τ is linear in the
    parameters).

    Parameters
    ----------
    mjcf_xml : str
        MuJoCo model; its joints' armature, damping and friction loss are set to zero here.
    names : tuple of str, length n
        Joint names, in the order of q (one dof each, nv = n).
    q, qd, qdd : ndarray, shape (N, n)
    delta : float
        Step relative to the link's own scales (mass, m r, m r² with r its smallest radius of
        gyration); small enough that the perturbed link stays physical.

    Returns
    -------
    ndarray, shape (N, n, 10 n)
        Same parameter order as :func:`dampest_ros.core.arm.regressor.rigid_regressor`.
    """
    import mujoco

    model = mujoco.MjModel.from_xml_string(mjcf_xml)
    data = mujoco.MjData(model)
    bodies, dofs = joint_bodies(model, names)
    if sorted(dofs) != list(range(model.nv)):
        raise ValueError("the named joints must be all of the model's degrees of freedom")
    model.dof_armature[:] = 0.0
    model.dof_damping[:] = 0.0
    model.dof_frictionloss[:] = 0.0

    def tau() -> FloatArray:
        full = np.zeros((q.shape[0], model.nv))
        full[:, dofs] = q
        vel = np.zeros_like(full)
        vel[:, dofs] = qd
        acc = np.zeros_like(full)
        acc[:, dofs] = qdd
        return inverse_dynamics(model, full, vel, acc)[:, dofs]

    base = tau()
    n = len(names)
    Y = np.empty((q.shape[0], n, 10 * n))
    for j, body in enumerate(bodies):
        p0 = body_parameters(model, body)
        # steps in the link's own units: mass m, first moment m r, inertia m r², with r² the
        # smallest principal inertia over the mass (the link stays physical for small delta)
        m, r2 = p0[0], float(model.body_inertia[body].min()) / p0[0]
        step = delta * np.array([m, *[m * np.sqrt(r2)] * 3, *[m * r2] * 6])
        for k in range(10):
            p = p0.copy()
            p[k] += step[k]
            set_body_parameters(model, data, body, p)
            # τ(π + δ e_k) − τ(π) = Y_k δ  (τ is linear in π)
            Y[:, :, 10 * j + k] = (tau() - base) / step[k]
        set_body_parameters(model, data, body, p0)
    return Y
