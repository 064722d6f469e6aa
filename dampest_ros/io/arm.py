"""Arm descriptions and arm joint data on disk: the shipped arm presets (URDF for Pinocchio
and the MJCF written from it, ``dampest_ros/data/arm/``) and any URDF (its MJCF beside it or
written from it), ``sensor_msgs/JointState`` bags of
an arm's joints (position, velocity, effort) with the simulation's truth beside them, FFS
trajectory files, and the online estimate's model file.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from dampest_ros.core.arm.design import DesignLimits
from dampest_ros.core.arm.ffs import FourierTrajectory
from dampest_ros.core.arm.model import (
    ArmModel,
    JointDynamics,
    arm_from_urdf,
    fixed_joints,
    joint_dynamics,
    mjcf,
    urdf_dynamics,
)
from dampest_ros.core.arm.online import ArmEstimate
from dampest_ros.core.physics.identity import Identity
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.signals.measurements import JointSeries, Series
from dampest_ros.io.bag import bag_summary, read_bag, write_bag
from dampest_ros.io.schema import check, load_checked
from dampest_ros.io.strict_yaml import InputError, YamlDoc, load_yaml
from dampest_ros.io.yaml_io import atomic_write, located, model_mapping, model_section

FloatArray = NDArray[np.float64]


class ArmDataError(ValueError):
    """Arm files or joint data that cannot be used; the message says what and how to fix."""


@dataclass(frozen=True)
class ArmDescription:
    """An arm as both engines see it.

    Attributes
    ----------
    model : ArmModel
        Kinematics, nominal inertias and limits (from the URDF).
    mjcf : str
        The MuJoCo model (same numbers, plus the joint dynamics).
    dynamics : JointDynamics
        The MuJoCo model's armature, damping and friction loss per joint (the truth of
        simulated data).
    source : str
        Preset name or URDF path.
    """

    model: ArmModel
    mjcf: str
    dynamics: JointDynamics
    source: str


def arm_presets() -> list[str]:
    """Names of the shipped arms."""
    root = resources.files("dampest_ros") / "data" / "arm"
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".urdf"))


def arm_files(name_or_path: str | Path) -> tuple[str, str | None]:
    """The URDF text of an arm preset or URDF path, and the MJCF beside it (None if none).

    Raises
    ------
    ArmDataError
        If it is neither a preset nor an existing .urdf file.
    """
    text = str(name_or_path)
    if text in arm_presets():
        root = resources.files("dampest_ros") / "data" / "arm"
        return (root / f"{text}.urdf").read_text(), (root / f"{text}.xml").read_text()
    path = Path(text)
    if path.suffix != ".urdf" or not path.is_file():
        raise ArmDataError(f"arm {text!r} is neither a preset ({', '.join(arm_presets())}) "
                           "nor an existing .urdf file")
    mj = path.with_suffix(".xml")
    return path.read_text(), mj.read_text() if mj.is_file() else None


def joint_list(text: str) -> tuple[str, ...]:
    """The joints of a comma list (``--lock``, the node's ``lock``), in its order."""
    return tuple(j.strip() for j in text.split(",") if j.strip())


def load_arm(name_or_path: str | Path, lock: tuple[str, ...] = ()) -> ArmDescription:
    """Load an arm: a preset name (``ur5``) or a URDF path. An MJCF beside the URDF (same
    stem, ``.xml``) is the simulated arm; without one, the MJCF is written from the URDF
    (:func:`~dampest_ros.core.arm.model.mjcf`) with the joint dynamics the URDF states
    (``<dynamics damping friction>``, no armature: :func:`urdf_dynamics`).

    Parameters
    ----------
    name_or_path : str or Path
    lock : tuple of str
        Joints held fixed at 0 (a gripper's); the URDF's MJCF is then always written from it.

    Raises
    ------
    ArmDataError
        If the preset or a file is missing, a file does not describe a revolute arm, or
        joints are locked in an arm whose MJCF is a file.
    """
    import mujoco

    text = str(name_or_path)
    urdf, xml = arm_files(text)
    if lock and xml is not None:
        raise ArmDataError(f"arm {text}: cannot lock {', '.join(lock)} in its MJCF file; "
                           "give a URDF without an MJCF beside it (the MJCF is then written "
                           "from the URDF)")
    try:
        model = arm_from_urdf(fixed_joints(urdf, lock))
        if xml is None:
            dyn = urdf_dynamics(model)
            xml = mjcf(model, dyn, name=Path(text).stem)
        else:
            dyn = joint_dynamics(mujoco.MjModel.from_xml_string(xml), model.names)
    except ValueError as exc:
        raise ArmDataError(f"arm {text}: {exc}") from None
    return ArmDescription(model, xml, dyn, text)


# --- joint-state bags ----------------------------------------------------------------------

#: Topic of the measured joint states, and of the simulation's truth (true q, q̇ and the
#: applied torque).
JOINT_TOPIC = "joint_states"
TRUTH_TOPIC = "truth/joint_states"
_JOINT_STATE = "sensor_msgs/msg/JointState"


@dataclass(frozen=True)
class JointData:
    """Joint samples of a bag in a model's joint order.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Header stamps (s).
    position, velocity, effort : ndarray, shape (N, n)
        rad, rad/s, N m.
    topic : str
        The topic read.
    """

    t: FloatArray
    position: FloatArray
    velocity: FloatArray
    effort: FloatArray
    topic: str


def joint_series(t: FloatArray, names: tuple[str, ...], position: FloatArray,
                 velocity: FloatArray, effort: FloatArray, frame_id: str = "") -> JointSeries:
    """A ``sensor_msgs/JointState`` series of arm joints (shapes (N,) and (N, n))."""
    return JointSeries(stamp=np.asarray(t, dtype=float), frame_id=frame_id, names=names,
                       velocity=np.asarray(velocity, dtype=float),
                       effort=np.asarray(effort, dtype=float),
                       position=np.asarray(position, dtype=float))


def write_joint_bag(path: str | Path, measured: JointSeries,
                    truth: JointSeries | None = None) -> Path:
    """Write measured joint states (and the truth) as an MCAP rosbag2 bag.

    Parameters
    ----------
    path : str or Path
        Bag directory to create (must not exist).
    measured : JointSeries
        Published on :data:`JOINT_TOPIC`.
    truth : JointSeries, optional
        Published on :data:`TRUTH_TOPIC`.

    Returns
    -------
    Path
    """
    recording: dict[str, Series] = {JOINT_TOPIC: measured}
    if truth is not None:
        recording[TRUTH_TOPIC] = truth
    return write_bag(path, recording)


def read_joint_bag(path: str | Path, names: tuple[str, ...], topic: str | None = None,
                   ) -> tuple[JointData, JointData | None]:
    """Read an arm's joint states (and the truth, if the bag has it) in the model's order.

    Parameters
    ----------
    path : str or Path
        rosbag2 bag.
    names : tuple of str
        The model's joint names.
    topic : str, optional
        JointState topic; default :data:`JOINT_TOPIC`, or the bag's only JointState topic
        other than the truth.

    Returns
    -------
    measured, truth : JointData, JointData or None

    Raises
    ------
    ArmDataError
        If the bag has no JointState topic (or not the one named), its joints do not
        include the model's, or it carries no positions or efforts.
    """
    summary = bag_summary(path)
    found = {t.lstrip("/"): s.msgtype for t, s in summary.topics.items()}
    joint_topics = sorted(t for t, m in found.items() if m == _JOINT_STATE)
    if topic is None:
        mine = [t for t in joint_topics if t != TRUTH_TOPIC]
        topic = JOINT_TOPIC if JOINT_TOPIC in mine else (mine[0] if len(mine) == 1 else None)
    have = ", ".join(f"{t} ({m})" for t, m in sorted(found.items())) or "no topics"
    if topic is None or found.get(topic.lstrip("/")) != _JOINT_STATE:
        raise ArmDataError(f"bag {path}: no sensor_msgs/JointState topic "
                           f"{'to use' if topic is None else topic!r}; it has: {have}"
                           + ("; name one with --topic" if len(joint_topics) > 1 else ""))
    wanted = [topic.lstrip("/")] + ([TRUTH_TOPIC] if TRUTH_TOPIC in found else [])
    series = read_bag(path, wanted)
    out = [_in_order(path, t, series[t], names) for t in wanted]
    return out[0], (out[1] if len(out) > 1 else None)


def _in_order(path: str | Path, topic: str, s: Series, names: tuple[str, ...]) -> JointData:
    assert isinstance(s, JointSeries)
    missing = [n for n in names if n not in s.names]
    if missing:
        raise ArmDataError(f"bag {path}, topic {topic}: joints {missing} of the model are "
                           f"not in the messages (they name {list(s.names)}); record the "
                           "arm the model describes, or give its URDF with --arm")
    cols = [s.names.index(n) for n in names]
    for field_name in ("position", "effort"):
        arr = getattr(s, field_name)
        if arr.ndim != 2 or arr.shape[1] != len(s.names):
            raise ArmDataError(f"bag {path}, topic {topic}: the messages carry no "
                               f"{field_name} for each joint ({arr.shape[1]} values for "
                               f"{len(s.names)} joints); identification needs position "
                               "and effort")
    vel = s.velocity[:, cols] if s.velocity.shape[1] == len(s.names) else np.full(
        (len(s), len(cols)), np.nan)
    return JointData(np.asarray(s.stamp, dtype=float), s.position[:, cols], vel,
                     s.effort[:, cols], topic)


# --- trajectory files ----------------------------------------------------------------------


def save_trajectory(path: str | Path, trajectory: FourierTrajectory, limits: DesignLimits,
                    info: dict[str, Any]) -> Path:
    """Write an FFS trajectory and the limits it was designed within as YAML.

    Parameters
    ----------
    path : str or Path
    trajectory : FourierTrajectory
    limits : DesignLimits
    info : dict
        Extra entries (arm, condition numbers, ...), plain YAML types.

    Returns
    -------
    Path
    """
    doc = {**info, "base_frequency": float(trajectory.base_frequency),
           "q0": trajectory.q0.tolist(), "a": trajectory.a.tolist(), "b": trajectory.b.tolist(),
           "limits": {k: np.asarray(getattr(limits, k), dtype=float).tolist()
                      for k in ("lower", "upper", "velocity", "acceleration", "effort")}}
    path = Path(path)
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def load_trajectory(path: str | Path, n: int) -> tuple[FourierTrajectory, DesignLimits | None]:
    """Read a trajectory file of :func:`save_trajectory` for an arm of n joints.

    Raises
    ------
    InputError
        (a ValueError) naming the file, line and key: a duplicate or unknown key (the
        closest valid one suggested), a missing entry, a wrong type or range (the schema
        ``dampest_ros/schemas/arm_trajectory.schema.json``).
    ArmDataError
        If its shapes do not fit n joints.
    """
    doc = load_checked(path, "arm_trajectory").data
    try:
        a, b = np.asarray(doc["a"], dtype=float), np.asarray(doc["b"], dtype=float)
        traj = FourierTrajectory(np.asarray(doc["q0"], dtype=float), a, b,
                                 float(doc["base_frequency"]))
        lim = doc.get("limits")
        limits = None if lim is None else DesignLimits(
            *(np.asarray(lim[k], dtype=float)
              for k in ("lower", "upper", "velocity", "acceleration", "effort")))
    except (KeyError, TypeError, ValueError) as exc:
        raise ArmDataError(f"trajectory file {path}: not a dampest arm trajectory "
                           f"({type(exc).__name__}: {exc}); write one with 'dampest arm "
                           "design'") from None
    if a.shape != b.shape or a.ndim != 2 or a.shape[0] != n or traj.q0.shape != (n,):
        raise ArmDataError(f"trajectory file {path}: coefficients of shape {a.shape} and q0 "
                           f"of {traj.q0.shape} do not fit an arm of {n} joints")
    # limits may be ±inf (none), never NaN; the rest finite
    bad = [k for k, v in {"q0": traj.q0, "a": a, "b": b}.items() if not np.all(np.isfinite(v))]
    bad += [] if np.isfinite(traj.base_frequency) and traj.base_frequency > 0 else [
        "base_frequency"]
    bad += [f"limits.{k}" for k, v in vars(limits or {}).items() if np.any(np.isnan(v))]
    if bad:
        raise ArmDataError(f"trajectory file {path}: {', '.join(bad)} must be numbers (finite; "
                           "base_frequency > 0); write the file again with 'dampest arm "
                           "design'")
    return traj, limits


# --- the online estimate as a model file and as parameters ---------------------------------

#: ``model.kind`` of an arm's base-parameter model file (a vehicle's has none).
ARM_MODEL_KIND = "arm_base_parameters"


def arm_model_parameters(est: ArmEstimate, arm: str) -> dict[str, Any]:
    """The estimate as the ``model.*`` parameters a node holds (dotted name → value).

    Parameters
    ----------
    est : ArmEstimate
    arm : str
        The arm preset or URDF the estimate belongs to.

    Returns
    -------
    dict
        ``model.kind``, ``model.arm``, ``model.joint_names``, ``model.parameter_names``,
        ``model.theta``, ``model.theta_std``, ``model.identified``, ``model.mapping``,
        ``model.version``, ``model.coulomb_width`` and, when the estimate has one,
        ``model.identity.*`` (kind, name, hash, parts): what ``--params-file`` gives for the
        file of :func:`save_arm_model`.
    """
    identity = {} if est.identity is None else {
        f"model.identity.{k}": v for k, v in est.identity.as_dict().items() if k != "parts"}
    if est.identity is not None:
        identity.update({f"model.identity.parts.{k}": v for k, v in est.identity.parts})
    return {**identity, "model.kind": ARM_MODEL_KIND, "model.arm": str(arm),
            "model.joint_names": list(est.joint_names),
            "model.parameter_names": list(est.parameter_names),
            "model.theta": [float(x) for x in est.theta],
            "model.theta_std": [float(x) for x in est.theta_std],
            "model.identified": [bool(x) for x in est.identified],
            "model.mapping": list(est.mapping), "model.version": int(est.version),
            "model.coulomb_width": float(est.coulomb_width)}


def arm_model_text(est: ArmEstimate, arm: str, extra: dict[str, Any] | None = None) -> str:
    """The model file's text: a ROS 2 parameters file (``/**: ros__parameters: model:``);
    ``extra`` entries (plain YAML types, names other than the model's) are added to
    ``model``."""
    model = model_mapping(arm_model_parameters(est, arm))
    clash = sorted(set(extra or {}) & set(model))
    if clash:
        raise ValueError(f"extra entries {clash} would replace the model's own")
    model.update(extra or {})
    return ("# dampest_ros arm model: base parameters (each named by the full parameter it "
            "keeps;\n# mapping says what it combines), SI units; a ROS 2 parameters file.\n"
            + yaml.safe_dump({"/**": {"ros__parameters": {"model": model}}}, sort_keys=False,
                             default_flow_style=None, width=100))


def save_arm_model(path: str | Path, est: ArmEstimate, arm: str,
                   extra: dict[str, Any] | None = None) -> Path:
    """Write the estimate's model file atomically (``extra``: see :func:`arm_model_text`);
    returns the path."""
    path = Path(path)
    atomic_write(path, arm_model_text(est, arm, extra))
    return path


def load_arm_model(path: str | Path) -> ArmEstimate:
    """Read a model file of :func:`save_arm_model` (:func:`read_arm_model` without the arm's
    name)."""
    return read_arm_model(path)[0]


def read_arm_model(path: str | Path) -> tuple[ArmEstimate, str]:
    """Read a model file of :func:`save_arm_model`: the estimate and the arm it names
    (``model.arm``, a preset or URDF path).

    Raises
    ------
    ArmDataError
        ``<file>:<line>: model.<key>: <what>; <fix>``: the file is missing, not an arm model
        file, violates the arm model schema (``dampest_ros/schemas/arm_model.schema.json``:
        an unknown or misspelt key, a missing one, a wrong type), has lists of unequal
        lengths or non-finite numbers.
    """
    try:
        return _arm_model_from_doc(load_yaml(path))
    except OSError as exc:
        raise ArmDataError(f"arm model file {path}: cannot be read ({exc.strerror}); write one "
                           "with 'dampest arm identify --out' or arm_estimator_node's ~/save"
                           ) from None


def is_arm_model_file(path: str | Path) -> bool:
    """Whether ``path`` is a YAML file whose model says ``kind: arm_base_parameters`` (False
    for anything else, which the vehicle's reader then names)."""
    try:
        return model_section(load_yaml(path))[1].get("kind") == ARM_MODEL_KIND
    except (ValueError, OSError):  # InputError, ConfigError
        return False


def arm_model_from_parameters(values: dict[str, Any]) -> tuple[ArmEstimate, str]:
    """:func:`read_arm_model` for the ``model.*`` parameters of a node (dotted name → value,
    as :func:`arm_model_parameters` gives them); errors name the source ``<parameters>``."""
    return _arm_model_from_doc(YamlDoc({"/**": {"ros__parameters": {
        "model": model_mapping(values)}}}, "<parameters>"))


def _arm_model_from_doc(doc: YamlDoc) -> tuple[ArmEstimate, str]:
    """The estimate and arm name of a parsed arm model file, checked (see
    :func:`read_arm_model`)."""
    try:
        where, m = model_section(doc)
        if m.get("kind") != ARM_MODEL_KIND:
            raise located(doc, where, ConfigError(
                "model.kind", f"{m.get('kind')!r}, not {ARM_MODEL_KIND!r}: not an arm's model "
                              "file; write one with 'dampest arm identify --out' or "
                              "arm_estimator_node's ~/save"))
        check(doc, "arm_model", skip=2)
        names = [str(x) for x in m["parameter_names"]]
        for key in ("theta", "theta_std", "identified", "mapping"):
            if len(m[key]) != len(names):
                raise located(doc, where, ConfigError(
                    f"model.{key}", f"has {len(m[key])} entries for {len(names)} "
                                    "parameter_names; give one per parameter"))
        theta, std = np.asarray(m["theta"], dtype=float), np.asarray(m["theta_std"], dtype=float)
        bad = next((k for k, v in (("theta", theta), ("theta_std", std))
                    if not np.all(np.isfinite(v))), "theta_std" if np.any(std < 0) else None)
        if bad is not None:
            raise located(doc, where, ConfigError(
                f"model.{bad}", "must be finite (the std >= 0); correct the value or save the "
                                "model again"))
        try:
            identity = Identity.from_dict(m["identity"]) if "identity" in m else None
        except ConfigError as exc:
            raise located(doc, where, exc) from None
        return ArmEstimate(tuple(str(x) for x in m["joint_names"]), names, theta, std,
                           np.asarray(m["identified"], dtype=bool),
                           [str(x) for x in m["mapping"]], int(m["version"]), identity,
                           float(m.get("coulomb_width", 0.0))), str(m["arm"])
    except InputError as exc:
        raise ArmDataError(str(exc)) from None
