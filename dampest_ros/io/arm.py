"""Arm descriptions and arm joint data on disk: the shipped arm presets (URDF for Pinocchio
and the MJCF written from it, ``dampest_ros/data/arm/``), and ``sensor_msgs/JointState``
bags of an arm's joints (position, velocity, effort) with the simulation's truth beside them.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.arm.model import ArmModel, JointDynamics, arm_from_urdf, joint_dynamics

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


def load_arm(name_or_path: str | Path) -> ArmDescription:
    """Load an arm: a preset name (``ur5``) or a URDF path with its MJCF beside it
    (``arm.urdf`` and ``arm.xml``).

    Raises
    ------
    ArmDataError
        If the preset or a file is missing, or a file does not describe a revolute arm.
    """
    import mujoco

    text = str(name_or_path)
    if text in arm_presets():
        root = resources.files("dampest_ros") / "data" / "arm"
        urdf, xml = (root / f"{text}.urdf").read_text(), (root / f"{text}.xml").read_text()
    else:
        path = Path(text)
        mj = path.with_suffix(".xml")
        if path.suffix != ".urdf" or not path.is_file():
            raise ArmDataError(f"arm {text!r} is neither a preset ({', '.join(arm_presets())}) "
                               "nor an existing .urdf file")
        if not mj.is_file():
            raise ArmDataError(f"arm {path}: no MJCF {mj} beside the URDF; MuJoCo needs it "
                               "(same joints, with armature, damping and frictionloss)")
        urdf, xml = path.read_text(), mj.read_text()
    try:
        model = arm_from_urdf(urdf)
        dyn = joint_dynamics(mujoco.MjModel.from_xml_string(xml), model.names)
    except ValueError as exc:
        raise ArmDataError(f"arm {text}: {exc}") from None
    return ArmDescription(model, xml, dyn, text)
