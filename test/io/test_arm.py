"""Arm joint-state bags: positions survive the JointState round trip, and bags that cannot
serve an arm are refused with a line naming what is wrong."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.signals.measurements import JointSeries, WrenchSeries
from dampest_ros.io.arm import (
    ArmDataError,
    joint_series,
    load_arm,
    read_joint_bag,
    write_joint_bag,
)
from dampest_ros.io.bag import read_bag, write_bag

NAMES = ("j1", "j2", "j3")


def _series(n: int = 50, names: tuple[str, ...] = NAMES) -> JointSeries:
    rng = np.random.default_rng(0)
    t = np.arange(n) * 1e-3
    return joint_series(t, names, *(rng.normal(size=(n, len(names))) for _ in range(3)))


def test_round_trip_in_model_order(tmp_path) -> None:  # type: ignore[no-untyped-def]
    measured = _series()
    truth = _series()
    write_joint_bag(tmp_path / "b", measured, truth)
    # the model lists the joints in another order: columns follow the model
    got, got_truth = read_joint_bag(tmp_path / "b", ("j3", "j1", "j2"))
    assert got.topic == "joint_states" and got_truth is not None
    assert np.array_equal(got.position, measured.position[:, [2, 0, 1]])
    assert np.array_equal(got.effort, measured.effort[:, [2, 0, 1]])
    assert np.array_equal(got_truth.velocity, truth.velocity[:, [2, 0, 1]])
    assert np.allclose(got.t, measured.stamp, atol=1e-9)


def test_thruster_joint_states_still_have_no_position(tmp_path) -> None:  # type: ignore[no-untyped-def]
    s = JointSeries(np.arange(5) * 0.1, "", ("t1",), np.ones((5, 1)), np.ones((5, 1)))
    assert s.position.shape == (5, 0)
    write_bag(tmp_path / "t", {"thrusters/state": s})
    back = read_bag(tmp_path / "t")["thrusters/state"]
    assert isinstance(back, JointSeries) and back.position.shape == (5, 0)


def test_refusals(tmp_path) -> None:  # type: ignore[no-untyped-def]
    t = np.arange(5) * 0.1
    write_bag(tmp_path / "w", {"wrench": WrenchSeries(t, "", np.ones((5, 3)), np.ones((5, 3)))})
    with pytest.raises(ArmDataError, match=r"no sensor_msgs/JointState topic .* it has: "
                                           r"wrench \(geometry_msgs/msg/WrenchStamped\)"):
        read_joint_bag(tmp_path / "w", NAMES)
    write_joint_bag(tmp_path / "b", _series())
    with pytest.raises(ArmDataError, match=r"joints \['shoulder_pan_joint'\] of the model are "
                                           r"not in the messages"):
        read_joint_bag(tmp_path / "b", ("j1", "shoulder_pan_joint"))
    s = JointSeries(t, "", NAMES, np.ones((5, 3)), np.ones((5, 3)))  # no positions
    write_bag(tmp_path / "np", {"joint_states": s})
    with pytest.raises(ArmDataError, match="carry no position"):
        read_joint_bag(tmp_path / "np", NAMES)


def test_a_urdf_alone_loads_with_the_mjcf_written_from_it(outside_arm) -> None:  # type: ignore[no-untyped-def]
    """A URDF without an MJCF beside it was refused; now MuJoCo's model is written from it,
    with the joint terms the URDF states (the Z1's <dynamics damping friction>, armature 0),
    and a gripper joint can be held fixed."""
    import mujoco

    from dampest_ros.core.arm.model import joint_dynamics

    path, lock = outside_arm("z1")
    assert load_arm(path).model.names[-1] == "jointGripper"  # a seventh revolute joint
    arm = load_arm(path, lock=lock)
    assert arm.model.n == 6 and arm.model.names[-1] == "joint6"
    assert arm.dynamics.damping.tolist() == [1.0, 2.0, 1.0, 1.0, 1.0, 1.0]
    assert arm.dynamics.frictionloss.tolist() == [1.0, 2.0, 1.0, 1.0, 1.0, 1.0]
    assert arm.dynamics.armature.tolist() == [0.0] * 6
    mj = mujoco.MjModel.from_xml_string(arm.mjcf)
    assert mj.nv == 6
    got = joint_dynamics(mj, arm.model.names)
    assert np.array_equal(got.damping, arm.dynamics.damping)
    assert np.array_equal(got.frictionloss, arm.dynamics.frictionloss)
    with pytest.raises(ArmDataError, match="no joint nothere to lock; the URDF's joints are"):
        load_arm(path, lock=("nothere",))
    with pytest.raises(ArmDataError, match="cannot lock wrist_3_joint in its MJCF file"):
        load_arm("ur5", lock=("wrist_3_joint",))


def test_locking_a_joint_that_a_transmission_names_holds_the_joint(outside_arm) -> None:  # type: ignore[no-untyped-def]
    """The Kinova URDF names each joint again in a <transmission>; the lock found that
    element (the last of the name) and held nothing. Now the robot's own joint is fixed."""
    path, _ = outside_arm("kinova")
    arm = load_arm(path, lock=("j2s6s200_joint_6",)).model
    assert arm.n == 5 and "j2s6s200_joint_6" not in arm.names
