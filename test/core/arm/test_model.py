"""The shipped UR5-class arm: URDF (Pinocchio) and MJCF (MuJoCo) are the same arm, and the
three regressors (vectorised, Pinocchio's analytic one, MuJoCo's mj_inverse) agree."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from dampest_ros.core.arm.ffs import random_trajectory
from dampest_ros.core.arm.mjinverse import inverse_dynamics, numerical_regressor
from dampest_ros.core.arm.model import mjcf
from dampest_ros.core.arm.regressor import (
    full_parameters,
    pinocchio_regressor,
    regressor,
    rigid_regressor,
)
from dampest_ros.core.arm.simulate import simulate_arm
from dampest_ros.io.arm import ArmDataError, arm_presets, load_arm


@pytest.fixture(scope="module")
def ur5():  # type: ignore[no-untyped-def]
    return load_arm("ur5")


def _states(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return (rng.uniform(-np.pi, np.pi, (n, 6)), rng.uniform(-3, 3, (n, 6)),
            rng.uniform(-10, 10, (n, 6)))


def test_presets_and_shipped_mjcf_is_written_from_the_urdf(ur5) -> None:  # type: ignore[no-untyped-def]
    assert "ur5" in arm_presets()
    assert ur5.model.names[0] == "shoulder_pan_joint" and ur5.model.n == 6
    assert np.allclose(ur5.dynamics.damping, [2.0, 2.0, 1.5, 0.5, 0.5, 0.3])
    assert mjcf(ur5.model, ur5.dynamics, name="ur5") == ur5.mjcf


def test_mass_matrices_agree(ur5) -> None:  # type: ignore[no-untyped-def]
    m = mujoco.MjModel.from_xml_string(ur5.mjcf)
    d = mujoco.MjData(m)
    pm, pd = ur5.model.pinocchio()
    M = np.zeros((6, 6))
    for q in _states(20, 1)[0]:
        d.qpos[:] = q
        mujoco.mj_forward(m, d)
        mujoco.mj_fullM(m, d, M)
        Mp = pin.crba(pm, pd, q)
        Mp = np.triu(Mp) + np.triu(Mp, 1).T + np.diag(ur5.dynamics.armature)
        assert np.abs(M - Mp).max() < 1e-8


def test_regressors_agree(ur5) -> None:  # type: ignore[no-untyped-def]
    q, qd, qdd = _states(12, 2)
    Y = rigid_regressor(ur5.model, q, qd, qdd)
    assert np.abs(Y - pinocchio_regressor(ur5.model, q, qd, qdd)).max() < 1e-10
    assert np.abs(Y - numerical_regressor(ur5.mjcf, ur5.model.names, q, qd, qdd)).max() < 1e-8
    # the full regressor with MuJoCo's armature and damping as joint columns is mj_inverse
    m = mujoco.MjModel.from_xml_string(ur5.mjcf)
    m.dof_frictionloss[:] = 0.0
    pi = full_parameters(ur5.model, ur5.dynamics)
    pi[6 * 10 + 2::4] = 0.0  # no Coulomb term: MuJoCo's friction loss is switched off
    tau = inverse_dynamics(m, q, qd, qdd)
    assert np.abs(regressor(ur5.model, q, qd, qdd) @ pi - tau).max() < 1e-8


def test_bad_arm_is_refused(tmp_path) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ArmDataError, match="neither a preset"):
        load_arm("ur6")
    urdf = tmp_path / "a.urdf"
    urdf.write_text("<robot name='x'/>")
    # without an MJCF beside it the URDF alone is read (and refused here for what it is)
    with pytest.raises(ArmDataError, match=r"a\.urdf: URDF does not parse"):
        load_arm(urdf)


Z1LIKE = Path(__file__).parents[2] / "data" / "z1like.urdf"


def _continuous(tmp_path: Path) -> Path:
    """The Z1-like arm with joint 1 continuous without a limit element and joint 6
    continuous with one that still names a range (ignored), its MJCF beside it."""
    text = Z1LIKE.read_text()
    text = text.replace('<joint name="joint1" type="revolute">',
                        '<joint name="joint1" type="continuous">').replace(
        '<limit lower="-2.618" upper="2.618" effort="30.0" velocity="3.1415"/>', "")
    text = text.replace('<joint name="joint6" type="revolute">',
                        '<joint name="joint6" type="continuous">')
    path = tmp_path / "cont.urdf"
    path.write_text(text)
    path.with_suffix(".xml").write_text(Z1LIKE.with_suffix(".xml").read_text())
    return path


def test_continuous_joints_are_revolute_without_limits(tmp_path) -> None:  # type: ignore[no-untyped-def]
    revolute = load_arm(str(Z1LIKE)).model
    arm = load_arm(str(_continuous(tmp_path)))
    m = arm.model
    assert m.names == revolute.names
    assert np.isneginf(m.lower[[0, 5]]).all() and np.isposinf(m.upper[[0, 5]]).all()
    assert np.array_equal(m.lower[1:5], revolute.lower[1:5])
    assert m.velocity_limit[0] == np.inf and m.effort_limit[0] == np.inf  # none given
    assert m.velocity_limit[5] == 3.1415 and m.effort_limit[5] == 30.0
    for name in ("rotation", "translation", "axis", "inertial"):
        assert np.array_equal(getattr(m, name), getattr(revolute, name)), name
    # Pinocchio's model of it has one coordinate per joint, and the same dynamics
    pm, _ = m.pinocchio()
    assert (pm.nq, pm.nv) == (6, 6)
    q, qd, qdd = _states(20, 3)
    assert np.abs(pinocchio_regressor(m, q, qd, qdd)
                  - regressor(m, q, qd, qdd)[..., :60]).max() < 1e-10
    # and MuJoCo runs it
    traj = random_trajectory(np.zeros(6), 2, 1.0, np.full(6, 1.0), np.random.default_rng(1))
    run = simulate_arm(arm.mjcf, m, arm.dynamics, traj, 0.5)
    assert np.abs(run.q - traj.evaluate(run.t)[0]).max() < 1e-3


def test_a_revolute_joint_without_its_range_is_refused(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    """A revolute joint whose <limit> lacks lower/upper was read as [0, 0] (URDF's default),
    a joint that cannot move, and the design ranged it over nothing. Now it is refused in one
    line that names it; a continuous joint (no range by definition) is still taken."""
    from dampest_ros.cli.main import main

    text = Z1LIKE.read_text().replace(
        '<limit lower="0.0" upper="2.967" effort="60.0" velocity="3.1415"/>',
        '<limit upper="2.967" effort="60.0" velocity="3.1415"/>')
    path = tmp_path / "nolower.urdf"
    path.write_text(text)
    with pytest.raises(ArmDataError, match=r"joint joint2: its <limit> has no lower, which "
                                           r"URDF reads as 0 \(a range of \[0, 0\]"):
        load_arm(path)
    capsys.readouterr()
    assert main(["arm", "design", "--arm", str(path), "--out", str(tmp_path / "t.yaml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith("give its range in radians, or make it "
                                             "continuous if it has none"), err
    assert load_arm(_continuous(tmp_path)).model.n == 6
