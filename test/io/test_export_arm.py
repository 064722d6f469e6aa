"""An identified arm exported to MJCF and URDF and read back: MuJoCo loads the MJCF, its
joint terms are the model file's to the last bit, the links are the consistent fit's, and
both files import to the base parameters that were exported. Through the command line too."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dampest_ros.cli.main import main
from dampest_ros.core.arm.base import base_parameters
from dampest_ros.core.arm.ffs import random_trajectory
from dampest_ros.core.arm.identify import IdentifyConfig, filter_joints, identify_arm
from dampest_ros.core.arm.model import arm_model_identity, joint_dynamics
from dampest_ros.core.arm.online import ArmEstimate
from dampest_ros.core.arm.regressor import full_parameters
from dampest_ros.core.arm.simulate import REALISTIC, simulate_arm
from dampest_ros.io.arm import (
    ArmDataError,
    arm_files,
    load_arm,
    load_arm_model,
    save_arm_model,
)
from dampest_ros.io.export.arm import (
    consistent_full,
    export_mjcf,
    export_urdf,
    exported_arm,
    import_arm,
    imported_estimate,
)


@pytest.fixture(scope="module")
def identified(tmp_path_factory):  # type: ignore[no-untyped-def]
    """A model file of 30 s of simulated UR5 data, as 'dampest arm identify --out' writes
    it (WLS θ and σ, the consistent fit's full parameters beside them)."""
    desc = load_arm("ur5")
    traj = random_trajectory(np.zeros(6), 5, 0.1, np.full(6, 1.5), np.random.default_rng(3))
    run = simulate_arm(desc.mjcf, desc.model, desc.dynamics, traj, 30.0, 1000.0, REALISTIC,
                       seed=1)
    base = base_parameters(desc.model)
    cfg = IdentifyConfig()
    res = identify_arm(desc.model, base, filter_joints(run.t, run.position, run.effort, cfg),
                       full_parameters(desc.model, desc.dynamics), cfg)
    kept = [base.names[k] for k in base.independent]
    est = ArmEstimate(desc.model.names, kept, res.wls.theta, res.wls.std,
                      np.ones(base.size, dtype=bool), base.mapping(),
                      identity=arm_model_identity("ur5", desc.model, kept))
    path = tmp_path_factory.mktemp("arm") / "arm_params.yaml"
    save_arm_model(path, est, "ur5", {"consistent_full": {
        "names": list(base.names), "values": [float(x) for x in res.consistent.full]}})
    return desc, base, path, res


def test_mjcf_export_loads_with_the_models_joint_terms(identified, tmp_path) -> None:  # type: ignore[no-untyped-def]
    import mujoco

    desc, base, path, res = identified
    est = load_arm_model(path)
    exp = exported_arm(desc, est, consistent_full(path, desc.model))
    text = export_mjcf(exp, "ur5", str(path))
    mj = mujoco.MjModel.from_xml_string(text)
    got = joint_dynamics(mj, desc.model.names)
    kept = est.parameter_names
    for j, name in enumerate(desc.model.names):
        # a term the data determine alone is the file's estimate, bit for bit
        for term, field in (("Fv", "damping"), ("Fc", "frictionloss")):
            assert getattr(got, field)[j] == est.theta[kept.index(f"{name}.{term}")]
        if j >= 2:
            assert got.armature[j] == est.theta[kept.index(f"{name}.Ia")]
    # the two armatures folded into the links' inertias are the consistent fit's split
    assert got.armature[:2].tolist() == res.consistent.full[60:68:4].tolist()
    assert "shoulder_pan_joint.Ia: determined only in a combination" in text
    assert "b6 spans the links of elbow_joint, shoulder_lift_joint, wrist_1_joint" in text
    assert "torque offsets (off): the sensor's" in text
    # and the file reads back: the links the consistent fit's, the joint terms as written
    (tmp_path / "arm.xml").write_text(text)
    arm, dyn = import_arm(tmp_path / "arm.xml", "mjcf", desc)
    assert np.abs(arm.inertial - res.consistent.full[:60].reshape(6, 10)).max() < 1e-12
    assert np.array_equal(dyn.damping, exp.dynamics.damping)
    imported = imported_estimate(arm, dyn, desc)
    exported = base.of(full_parameters(exp.arm, exp.dynamics))
    assert np.abs(imported.theta - exported).max() <= 1e-12 * np.abs(exported).max()
    assert not imported.identified.any() and not imported.theta_std.any()


def test_urdf_export_round_trips(identified, tmp_path) -> None:  # type: ignore[no-untyped-def]
    desc, _, path, _ = identified
    exp = exported_arm(desc, load_arm_model(path), consistent_full(path, desc.model))
    text = export_urdf(exp, arm_files("ur5")[0], str(path))
    assert "armature" in text and "(URDF has no element for it)" in text
    (tmp_path / "arm.urdf").write_text(text)
    arm, dyn = import_arm(tmp_path / "arm.urdf", "urdf", desc)
    assert np.array_equal(dyn.damping, exp.dynamics.damping)
    assert np.array_equal(dyn.frictionloss, exp.dynamics.frictionloss)
    assert np.abs(arm.inertial - exp.arm.inertial).max() < 1e-12
    # the UR5's wrist_3_link carries tool0 (no mass): its inertial is the identified one
    assert "inertial left as is" not in text


def test_an_online_model_file_exports_the_nominal_links_and_says_so(identified, tmp_path) -> None:  # type: ignore[no-untyped-def]
    desc, _, path, _ = identified
    est = load_arm_model(path)
    online = tmp_path / "online.yaml"
    save_arm_model(online, est, "ur5")  # as arm_estimator_node's ~/save: no consistent fit
    exp = exported_arm(desc, est, consistent_full(online, desc.model))
    assert np.array_equal(exp.arm.inertial, desc.model.inertial)
    assert np.array_equal(exp.dynamics.armature[:2], desc.dynamics.armature[:2])
    assert any(n.startswith("link inertias: the URDF's nominal ones") for n in exp.notes)


def test_the_command_line_exports_and_imports_an_arm(identified, tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    _, base, path, _ = identified
    xml, back = tmp_path / "arm.xml", tmp_path / "back.yaml"
    assert main(["export", str(path), "--format", "mjcf", "--out", str(xml)]) == 0
    assert main(["import", str(xml), "--format", "mjcf", "--arm", "ur5", "--out",
                 str(back)]) == 0
    est = load_arm_model(back)
    assert est.parameter_names == [base.names[k] for k in base.independent]
    capsys.readouterr()
    assert main(["export", str(path), "--format", "gz"]) == 2
    assert main(["import", str(xml), "--format", "mjcf", "--out", str(back)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"dampest export: error: {path} is an arm model file: --format mjcf or "
                   "urdf, not gz",
                   "dampest import: error: --format mjcf reads an arm: give the arm with "
                   "--arm"]


def test_a_negative_friction_estimate_is_not_exported_as_it_is(identified, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """An arm whose URDF states no friction identifies its Fc near 0, and WLS can put it
    below (the UR10 from example-robot-data: wrist_1_joint.Fc = -0.0065 N m). A simulator
    would apply it as a push: the consistent fit's value (kept > 0) is written instead and
    said so; a file without a consistent fit is refused in one line."""
    desc, _, path, res = identified
    est = load_arm_model(path)
    k = est.parameter_names.index("elbow_joint.Fc")
    theta = est.theta.copy()
    theta[k] = -0.0065
    negative = replace(est, theta=theta)
    exp = exported_arm(desc, negative, consistent_full(path, desc.model))
    assert exp.dynamics.frictionloss[2] == res.consistent.full[60 + 4 * 2 + 2] > 0
    assert "elbow_joint.Fc: the estimate -0.0065 < 0 is not dissipative; the consistent " \
           "fit's value" in exp.notes
    with pytest.raises(ArmDataError, match=r"^elbow_joint\.Fc = -0\.0065 < 0 is not "
                                           r"dissipative, and the model file has no"):
        exported_arm(desc, negative, None)


def test_a_gripper_arm_round_trips_through_its_urdf(outside_arm, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The Z1 of example-robot-data, its gripper joint locked: the exported URDF keeps the
    gripper (a revolute joint) and link06's own inertial (it carries gripperStator, fixed:
    the data determine their sum), and reads back with the gripper held fixed again."""
    path, lock = outside_arm("z1")
    desc = load_arm(path, lock=lock)
    exp = exported_arm(desc, imported_estimate(desc.model, desc.dynamics, desc), None)
    text = export_urdf(exp, arm_files(path)[0], "z1 nominal")
    assert "link link06: inertial left as is; the data determine its sum with " \
           "gripperStator (fixed to it)" in text
    assert '<joint name="jointGripper" type="revolute">' in text
    (tmp_path / "z1.urdf").write_text(text)
    arm, dyn = import_arm(tmp_path / "z1.urdf", "urdf", desc)
    assert arm.names == desc.model.names
    assert np.abs(arm.inertial - desc.model.inertial).max() < 1e-15
    assert np.array_equal(dyn.frictionloss, exp.dynamics.frictionloss)
    # the nominal friction through base parameters and back: to rounding
    assert np.allclose(dyn.frictionloss, desc.dynamics.frictionloss, rtol=1e-12, atol=0.0)
