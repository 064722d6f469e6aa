"""A serial arm of revolute joints: kinematics, inertias and limits from a URDF (read with
Pinocchio), the joint dynamics MuJoCo simulates (armature, viscous damping, friction loss),
and the MJCF written from the same numbers.

The inertial parameters of link j are Pinocchio's ten "dynamic parameters" in the frame of
joint j: π_j = [m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz] (kg, kg m,
kg m²), the inertia taken about the joint frame's origin (not the centre of mass).

A URDF ``continuous`` joint is a revolute joint without position limits (lower and upper
±inf here). Pinocchio reads it as a unit-circle joint of two coordinates (cos q, sin q); the
model keeps one coordinate per joint by reading it as ``revolute`` (:func:`revolute_urdf`).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin  # type: ignore[import-untyped]
from numpy.typing import NDArray

from dampest_ros.core.physics.identity import Identity, arm_identity

FloatArray = NDArray[np.float64]

#: Names of the ten inertial parameters of a link, in Pinocchio's order.
INERTIAL_NAMES = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")

_AXES = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0),
         "JointModelRZ": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class ArmModel:
    """Kinematic tree, nominal inertial parameters and limits of an arm with n revolute joints.

    Attributes
    ----------
    names : tuple of str, length n
        Joint names, in the order of q.
    parents : ndarray of int, shape (n,)
        Index of each joint's parent joint; -1 for the base.
    rotation : ndarray, shape (n, 3, 3)
        Orientation of joint frame j in its parent's frame at q_j = 0.
    translation : ndarray, shape (n, 3)
        Origin of joint frame j in its parent's frame (m).
    axis : ndarray, shape (n, 3)
        Unit rotation axis of joint j in its own frame.
    inertial : ndarray, shape (n, 10)
        Nominal inertial parameters per link (see the module docstring).
    lower, upper : ndarray, shape (n,)
        Position limits (rad); ±inf for a continuous joint.
    velocity_limit : ndarray, shape (n,)
        |q̇| limits (rad/s).
    effort_limit : ndarray, shape (n,)
        |τ| limits (N m).
    gravity : ndarray, shape (3,)
        Gravity in the base frame (m/s²).
    urdf : str
        The URDF text the model was read from, continuous joints written as revolute ones
        (:func:`revolute_urdf`; Pinocchio's dynamics use it, one coordinate per joint).
    """

    names: tuple[str, ...]
    parents: NDArray[np.int64]
    rotation: FloatArray
    translation: FloatArray
    axis: FloatArray
    inertial: FloatArray
    lower: FloatArray
    upper: FloatArray
    velocity_limit: FloatArray
    effort_limit: FloatArray
    gravity: FloatArray
    urdf: str

    @property
    def n(self) -> int:
        """Number of joints."""
        return len(self.names)

    def pinocchio(self) -> tuple[object, object]:
        """A Pinocchio (model, data) pair built from :attr:`urdf`."""
        model = pin.buildModelFromXML(self.urdf)
        return model, model.createData()


@dataclass(frozen=True)
class JointDynamics:
    """What a joint adds to the rigid-body torque, per joint (shapes (n,)).

    τ_j = (rigid body)_j + armature_j q̈_j + damping_j q̇_j + frictionloss_j sign(q̇_j)
    (+ a torque-sensor offset, which belongs to the sensor, not the joint).

    Attributes
    ----------
    armature : ndarray
        Reflected rotor inertia (kg m²).
    damping : ndarray
        Viscous friction (N m s/rad).
    frictionloss : ndarray
        Coulomb (dry) friction (N m); MuJoCo enforces it as a soft constraint, which
        saturates at this value once the joint slides.
    """

    armature: FloatArray
    damping: FloatArray
    frictionloss: FloatArray


def revolute_urdf(urdf: str) -> tuple[str, frozenset[str]]:
    """URDF text with its continuous joints written as revolute ones, and their names.

    The limit element of such a joint carries no position limits (urdfdom reads [0, 0];
    :func:`arm_from_urdf` takes ±inf) and keeps its effort and velocity; one is added if the
    joint had none. A URDF without continuous joints is returned unchanged.

    Parameters
    ----------
    urdf : str
        URDF XML.

    Returns
    -------
    urdf : str
    continuous : frozenset of str
        Names of the joints rewritten.

    Raises
    ------
    ValueError
        If the text is not XML.
    """
    try:
        root = ET.fromstring(urdf)
    except ET.ParseError as exc:
        raise ValueError(f"URDF does not parse: {exc}") from None
    joints = [j for j in root.iter("joint") if j.get("type") == "continuous"]
    if not joints:
        return urdf, frozenset()
    for joint in joints:
        joint.set("type", "revolute")
        limit = joint.find("limit")
        if limit is None:
            limit = ET.SubElement(joint, "limit", effort="0", velocity="0")
        limit.attrib.pop("lower", None)
        limit.attrib.pop("upper", None)
    return ET.tostring(root, encoding="unicode"), frozenset(str(j.get("name")) for j in joints)


def fixed_joints(urdf: str, names: tuple[str, ...]) -> str:
    """URDF text with the named joints written as fixed ones, held at position 0 (a
    gripper's fingers, to identify the arm without them; their links' inertias join the
    link they hang from).

    Parameters
    ----------
    urdf : str
        URDF XML.
    names : tuple of str
        Joints to hold; none returns the text unchanged.

    Returns
    -------
    str

    Raises
    ------
    ValueError
        If the text is not XML or a name is not a joint of it (names the ones it has).
    """
    if not names:
        return urdf
    try:
        root = ET.fromstring(urdf)
    except ET.ParseError as exc:
        raise ValueError(f"URDF does not parse: {exc}") from None
    joints = {str(j.get("name")): j for j in root.findall("joint")}
    missing = [n for n in names if n not in joints]
    if missing:
        raise ValueError(f"no joint {', '.join(missing)} to lock; the URDF's joints are "
                         f"{', '.join(joints)}")
    for name in names:
        joints[name].set("type", "fixed")
    return ET.tostring(root, encoding="unicode")


def _require_ranges(urdf: str) -> None:
    """ValueError naming the first revolute joint whose <limit> lacks lower or upper: URDF
    reads a missing one as 0, so such a joint has no range to move in (the text parses: the
    caller has checked)."""
    for joint in ET.fromstring(urdf).iter("joint"):
        limit = joint.find("limit")
        if joint.get("type") != "revolute" or limit is None:
            continue
        missing = [k for k in ("lower", "upper") if limit.get(k) is None]
        if missing:
            raise ValueError(
                f"joint {joint.get('name')}: its <limit> has no {' or '.join(missing)}, which "
                "URDF reads as 0 (a range of [0, 0]: the joint cannot move); give its range "
                "in radians, or make it continuous if it has none")


def arm_from_urdf(urdf: str) -> ArmModel:
    """Read an arm of revolute (and continuous) joints from URDF text with Pinocchio.

    Parameters
    ----------
    urdf : str
        URDF XML; a fixed base (the root link is the world).

    Returns
    -------
    ArmModel
        Velocity and effort limits as the URDF gives them (inf where a continuous joint has
        none); a continuous joint's position limits ±inf.

    Raises
    ------
    ValueError
        If the URDF does not parse, has a joint other than a revolute or continuous one, or
        a revolute joint whose <limit> lacks lower or upper (URDF: 0).
    """
    text, continuous = revolute_urdf(urdf)
    _require_ranges(urdf)
    try:
        model = pin.buildModelFromXML(text)
        given = pin.buildModelFromXML(urdf) if continuous else model
    except Exception as exc:  # Pinocchio raises bare RuntimeErrors on bad XML
        raise ValueError(f"URDF does not parse: {exc}") from None
    n = model.njoints - 1
    axes = []
    for i in range(1, n + 1):
        joint = model.joints[i]
        kind = joint.shortname()
        if kind in _AXES:
            axes.append(_AXES[kind])
        elif kind == "JointModelRevoluteUnaligned":
            axes.append(tuple(np.asarray(joint.extract().axis, dtype=float)))
        else:
            raise ValueError(f"joint {model.names[i]} is a {kind}; only revolute and "
                             "continuous joints are supported: lock it (held at 0) to "
                             "identify the others")
    names = tuple(str(model.names[i]) for i in range(1, n + 1))
    free = np.array([name in continuous for name in names])
    place = [model.jointPlacements[i] for i in range(1, n + 1)]
    return ArmModel(
        names=names,
        parents=np.array([model.parents[i] - 1 for i in range(1, n + 1)], dtype=np.int64),
        rotation=np.array([p.rotation for p in place], dtype=float),
        translation=np.array([p.translation for p in place], dtype=float),
        axis=np.array(axes, dtype=float),
        inertial=np.array([model.inertias[i].toDynamicParameters() for i in range(1, n + 1)],
                          dtype=float),
        lower=np.where(free, -np.inf, np.asarray(model.lowerPositionLimit, dtype=float)),
        upper=np.where(free, np.inf, np.asarray(model.upperPositionLimit, dtype=float)),
        velocity_limit=np.array(given.velocityLimit, dtype=float),
        effort_limit=np.array(given.effortLimit, dtype=float),
        gravity=np.array(model.gravity.linear, dtype=float),
        urdf=text,
    )


def urdf_dynamics(arm: ArmModel) -> JointDynamics:
    """The joint dynamics a URDF states: ``<dynamics damping friction>`` per joint (0 where
    it gives none) and no armature (URDF has no element for it).

    Parameters
    ----------
    arm : ArmModel

    Returns
    -------
    JointDynamics
    """
    model = pin.buildModelFromXML(arm.urdf)
    return JointDynamics(armature=np.asarray(model.armature, dtype=np.float64),
                         damping=np.asarray(model.damping, dtype=np.float64),
                         frictionloss=np.asarray(model.friction, dtype=np.float64))


def _quat(R: FloatArray) -> FloatArray:
    """Unit quaternion [w, x, y, z] of a rotation matrix (Pinocchio's conversion)."""
    q = pin.Quaternion(np.asarray(R, dtype=float))
    return np.array([q.w, q.x, q.y, q.z])


def _num(values: FloatArray | float) -> str:
    """Numbers written exactly (shortest repr round-trips the float64)."""
    return " ".join(repr(float(v)) for v in np.ravel(values))


def mjcf(arm: ArmModel, dynamics: JointDynamics, timestep: float = 0.001,
         name: str = "arm") -> str:
    """The MJCF of an arm: the same joint frames and inertias as its URDF, every number
    written to full precision, plus the joint dynamics and a torque motor per joint.

    Parameters
    ----------
    arm : ArmModel
    dynamics : JointDynamics
        Per-joint armature, damping and friction loss of the simulated joints.
    timestep : float
        MuJoCo's integration step (s).
    name : str
        Model name.

    Returns
    -------
    str
        MJCF XML: contacts disabled (links pass through each other; no contact forces in
        the torques), no joint limits, gravity along the URDF's -z, motors without control
        limits (the commanded torque is the applied one). The friction loss is a soft
        constraint with MuJoCo's shortest time constant (two steps), so it reaches its
        Coulomb value within |q̇| ≈ 0.05 rad/s of a velocity reversal; the constraint solver
        runs to round-off (tolerance 1e-12), so a sliding joint's friction is exactly it.
    """
    lines = [f'<mujoco model="{name}">',
             '  <compiler angle="radian" autolimits="true"/>',
             f'  <option timestep="{timestep!r}" gravity="{_num(arm.gravity)}" '
             'tolerance="1e-12">',
             '    <flag contact="disable"/>',
             '  </option>',
             '  <worldbody>']
    children: dict[int, list[int]] = {}
    for j, p in enumerate(arm.parents.tolist()):
        children.setdefault(p, []).append(j)

    def body(j: int, depth: int) -> None:
        pad = "  " * depth
        m = arm.inertial[j]
        com = m[1:4] / m[0]
        # inertia about the centre of mass: I_c = I_o − m S(c)ᵀ S(c) (parallel axis); |c|² is
        # summed exactly (fsum), so the file does not depend on the CPU's SIMD summation order
        Io = np.array([[m[4], m[5], m[7]], [m[5], m[6], m[8]], [m[7], m[8], m[9]]])
        Ic = Io - m[0] * (math.fsum(com * com) * np.eye(3) - np.outer(com, com))
        full = np.array([Ic[0, 0], Ic[1, 1], Ic[2, 2], Ic[0, 1], Ic[0, 2], Ic[1, 2]])
        d = dynamics
        lines.extend([
            f'{pad}<body name="link_{arm.names[j]}" pos="{_num(arm.translation[j])}" '
            f'quat="{_num(_quat(arm.rotation[j]))}">',
            f'{pad}  <inertial pos="{_num(com)}" mass="{_num(m[0])}" fullinertia="{_num(full)}"/>',
            f'{pad}  <joint name="{arm.names[j]}" axis="{_num(arm.axis[j])}" '
            f'solreffriction="{_num(2.0 * timestep)} 1" armature="{_num(d.armature[j])}" '
            f'damping="{_num(d.damping[j])}" '
            f'frictionloss="{_num(d.frictionloss[j])}"/>'])
        for c in children.get(j, []):
            body(c, depth + 1)
        lines.append(f"{pad}</body>")

    for j in children.get(-1, []):
        body(j, 2)
    lines.append("  </worldbody>")
    lines.append("  <actuator>")
    lines.extend(f'    <motor name="{name}" joint="{name}" gear="1"/>' for name in arm.names)
    lines.extend(["  </actuator>", "</mujoco>", ""])
    return "\n".join(lines)


def joint_dynamics(mj_model: Any, names: tuple[str, ...]) -> JointDynamics:
    """The armature, damping and friction loss of the named joints of a MuJoCo model.

    Parameters
    ----------
    mj_model : mujoco.MjModel
    names : tuple of str, length n
        Joint names (one degree of freedom each).

    Returns
    -------
    JointDynamics

    Raises
    ------
    ValueError
        If a joint is missing from the MuJoCo model; names the ones it has.
    """
    import mujoco

    dofs = []
    for name in names:
        jid = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            have = [mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_JOINT, i)
                    for i in range(mj_model.njnt)]
            raise ValueError(f"joint {name!r} is not in the MuJoCo model; it has {have}")
        dofs.append(int(mj_model.jnt_dofadr[jid]))
    return JointDynamics(
        armature=np.array(mj_model.dof_armature[dofs], dtype=float),
        damping=np.array(mj_model.dof_damping[dofs], dtype=float),
        frictionloss=np.array(mj_model.dof_frictionloss[dofs], dtype=float))


def arm_model_identity(name: str, arm: ArmModel, base_names: list[str]) -> Identity:
    """The identity of an arm's base-parameter model: ``name`` and the hashes of the joints
    (names, parents, joint frames, axes) and of the base parameters' names
    (:func:`~dampest_ros.core.physics.identity.arm_identity`)."""
    return arm_identity(name, {"names": list(arm.names), "parents": arm.parents,
                               "rotation": arm.rotation, "translation": arm.translation,
                               "axis": arm.axis}, base_names)
