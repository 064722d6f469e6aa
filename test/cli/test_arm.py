"""dampest arm: simulate -> identify on bags, and one line + exit 2 for unusable input."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from dampest_ros.cli.main import main
from dampest_ros.core.signals.measurements import WrenchSeries
from dampest_ros.io.arm import JointData, load_arm_model
from dampest_ros.io.bag import write_bag


@pytest.mark.slow
def test_simulate_identify_validate(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                    ) -> None:
    train, val = tmp_path / "train", tmp_path / "val"
    assert main(["arm", "simulate", "--random", "3", "--duration", "30", "--seed", "1",
                 "--out", str(train)]) == 0
    assert main(["arm", "simulate", "--random", "8", "--duration", "12", "--seed", "2",
                 "--rate", "500", "--out", str(val)]) == 0
    capsys.readouterr()
    assert main(["arm", "identify", str(train), "--validate", str(val), "--mapping",
                 "--out", str(tmp_path / "p.yaml"), "--report", str(tmp_path / "rep")]) == 0
    out = capsys.readouterr().out
    assert "58 base parameters" in out and "b1 = " in out and "noise floor from truth" in out
    rows = [line.split() for line in out.splitlines() if line.strip().startswith("WLS")]
    ratios = np.array([float(r[-1]) for r in rows])
    assert len(ratios) == 6 and np.all(ratios <= 1.05)
    page = (tmp_path / "rep" / "index.html").read_text()
    assert "RMSE / noise floor" in page and (tmp_path / "rep" / "torque.png").stat().st_size
    model = load_arm_model(tmp_path / "p.yaml")  # the file arm_estimator_node takes as prior
    assert model.theta[model.parameter_names.index("elbow_joint.Fc")] == pytest.approx(
        2.0, rel=0.02)


def test_bad_input_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                          ) -> None:
    t = np.arange(5) * 0.1
    write_bag(tmp_path / "w", {"wrench": WrenchSeries(t, "", np.ones((5, 3)), np.ones((5, 3)))})
    assert main(["arm", "identify", str(tmp_path / "w")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no sensor_msgs/JointState topic" in err
    # a trajectory beyond the limits it was designed within
    traj = {"base_frequency": 0.1, "q0": [0.0] * 6, "a": [[3.0, 0.0]] * 6,
            "b": [[0.0, 0.0]] * 6,
            "limits": {"lower": [-1.0] * 6, "upper": [1.0] * 6, "velocity": [1.0] * 6,
                       "acceleration": [4.0] * 6, "effort": [150, 150, 150, 28, 28, 28]}}
    (tmp_path / "t.yaml").write_text(yaml.safe_dump(traj))
    assert main(["arm", "simulate", "--trajectory", str(tmp_path / "t.yaml"), "--out",
                 str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "shoulder_pan_joint |velocity| 3 exceeds 1 rad/s" in err
    assert "position" in err and not (tmp_path / "x").exists()
    # joints that do not match the model: a three-joint bag
    from dampest_ros.io.arm import joint_series, write_joint_bag

    write_joint_bag(tmp_path / "j3", joint_series(t, ("a", "b", "c"), *(np.ones((5, 3)),) * 3))
    assert main(["arm", "identify", str(tmp_path / "j3")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "'shoulder_pan_joint'" in err and "not in the " \
        "messages" in err


def test_coulomb_width_is_an_option_and_recorded(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """The smooth dry friction Fc tanh(q̇/w) of the core, on the command line. On MuJoCo's
    friction loss (its Coulomb value within 0.05 rad/s of a reversal) and the rows above
    --min-speed, where tanh(q̇/0.02) ≈ sign, Fc is what sign gives: within 0.48 % of the
    truth. The model file records the width; a negative one is refused in one line."""
    bag = tmp_path / "train"
    assert main(["arm", "simulate", "--random", "3", "--duration", "20", "--seed", "1",
                 "--out", str(bag)]) == 0
    assert main(["arm", "identify", str(bag), "--coulomb-width", "0.02", "--out",
                 str(tmp_path / "p.yaml")]) == 0
    model = load_arm_model(tmp_path / "p.yaml")
    truth = {"shoulder_pan_joint": 3.0, "shoulder_lift_joint": 3.0, "elbow_joint": 2.0,
             "wrist_1_joint": 0.8, "wrist_2_joint": 0.8, "wrist_3_joint": 0.5}
    for joint, fc in truth.items():
        assert model.theta[model.parameter_names.index(f"{joint}.Fc")] == pytest.approx(
            fc, rel=0.01)  # measured: at most 0.48 %
    doc = yaml.safe_load((tmp_path / "p.yaml").read_text())
    assert doc["/**"]["ros__parameters"]["model"]["coulomb_width"] == 0.02
    capsys.readouterr()
    assert main(["arm", "identify", str(bag), "--coulomb-width", "-1"]) == 2
    assert capsys.readouterr().err.strip() == (
        "dampest arm: error: --coulomb-width -1: give a width >= 0 rad/s (0: Fc sign(qd))")


def test_an_outside_urdf_simulates_with_sensors_scaled_to_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], outside_arm) -> None:  # type: ignore[no-untyped-def]
    """The xArm7 (7 joints, a URDF alone): --noise realistic, the UR5's six sensors, ended
    in "operands could not be broadcast"; now it is refused in one line that names the
    choice, and --noise scaled simulates it with noise 0.27 % of each effort limit."""
    path, _ = outside_arm("xarm7")
    capsys.readouterr()
    assert main(["arm", "simulate", "--arm", path, "--random", "3", "--duration", "2",
                 "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "has 7: use --noise scaled" in err[0], err
    assert main(["arm", "simulate", "--arm", path, "--random", "3", "--duration", "2",
                 "--noise", "scaled", "--out", str(tmp_path / "b")]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()
            if line.startswith("joint")]
    # joint, |q - q0|, |qd|, |tau|, noise, offset: the xArm7's limits 50/50/30/30/30/20/20 N m
    assert [float(r[4]) for r in rows] == pytest.approx(
        [0.135, 0.135, 0.081, 0.081, 0.081, 0.054, 0.054])


def test_a_gripper_arm_from_the_command_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                             outside_arm) -> None:  # type: ignore[no-untyped-def]
    """The Z1 of example-robot-data with its gripper joint locked (--lock): simulated,
    identified (the model file records the lock), exported to MJCF and imported back, all
    from the command line, with the six arm joints."""
    import mujoco
    import yaml as yaml_

    path, lock = outside_arm("z1")
    bag, model, xml = tmp_path / "z1", tmp_path / "z1.yaml", tmp_path / "z1.xml"
    arm = ["--arm", path, "--lock", ",".join(lock)]
    assert main(["arm", "simulate", *arm, "--random", "3", "--duration", "20", "--noise",
                 "scaled", "--out", str(bag)]) == 0
    assert main(["arm", "identify", str(bag), *arm, "--out", str(model)]) == 0
    doc = yaml_.safe_load(model.read_text())["/**"]["ros__parameters"]["model"]
    assert doc["lock"] == ["jointGripper"] and len(doc["joint_names"]) == 6
    assert main(["export", str(model), "--format", "mjcf", "--out", str(xml)]) == 0
    assert mujoco.MjModel.from_xml_string(xml.read_text()).nv == 6
    assert main(["import", str(xml), "--format", "mjcf", *arm, "--out",
                 str(tmp_path / "back.yaml")]) == 0
    assert load_arm_model(tmp_path / "back.yaml").joint_names == tuple(doc["joint_names"])
    capsys.readouterr()


def write_ros1_joints(path: Path, data: JointData, names: tuple[str, ...]) -> Path:
    """``data`` as sensor_msgs/JointState on /joint_states of a ROS 1 bag written by rosbags'
    rosbag1 Writer (header seq counting up, log time = stamp), the joints in reverse order."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    noetic = get_typestore(Stores.ROS1_NOETIC)
    T = noetic.types
    msgtype = "sensor_msgs/msg/JointState"
    ns = np.round(data.t * 1e9).astype(np.int64)
    rev = slice(None, None, -1)
    with Writer(path) as writer:
        conn = writer.add_connection("/joint_states", msgtype, typestore=noetic)
        for i, stamp in enumerate(ns):
            header = T["std_msgs/msg/Header"](
                seq=i, stamp=T["builtin_interfaces/msg/Time"](
                    sec=int(stamp // 10**9), nanosec=int(stamp % 10**9)), frame_id="")
            msg = T[msgtype](header=header, name=list(names[rev]),
                             position=data.position[i, rev].copy(),
                             velocity=data.velocity[i, rev].copy(),
                             effort=data.effort[i, rev].copy())
            writer.write(conn, int(stamp), bytes(noetic.serialize_ros1(msg, msgtype)))
    return path


def test_ros1_bag_and_csv_logs_identify_as_the_rosbag2_bag(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """20 s of a simulated UR5 at 500 Hz, as the rosbag2 bag of 'arm simulate', as a ROS 1
    bag (joints in another order) and as a CSV log without velocity columns, its joints
    under other names through a column map: the three give the same θ (to 1e-9) and the
    same samples."""
    from dampest_ros.io.arm import load_arm, read_joint_bag
    from dampest_ros.io.arm_csv import read_joint_csv
    from dampest_ros.io.csv import load_column_map, write_table

    names = load_arm("ur5").model.names
    bag2 = tmp_path / "ros2"
    assert main(["arm", "simulate", "--random", "3", "--duration", "20", "--rate", "500",
                 "--seed", "1", "--out", str(bag2)]) == 0
    data, _ = read_joint_bag(bag2, names)
    ros1 = write_ros1_joints(tmp_path / "log.bag", data, names)
    cols = {"stamp": data.t}
    for j in range(len(names)):
        cols[f"pos{j}"] = data.position[:, j]
        cols[f"torque{j}"] = data.effort[:, j]
    csv = write_table(tmp_path / "log.csv", cols)
    cmap = tmp_path / "columns.yaml"
    cmap.write_text("columns:\n  stamp: time\n" + "".join(
        f"  pos{j}: {n}.q\n  torque{j}: {n}.tau\n" for j, n in enumerate(names)))
    for log in (ros1, csv):
        back = (read_joint_bag(log, names)[0] if log == ros1 else
                read_joint_csv(log, names, load_column_map(cmap)))
        np.testing.assert_array_equal(back.t, data.t)
        np.testing.assert_array_equal(back.position, data.position)
        np.testing.assert_array_equal(back.effort, data.effort)
    theta = {}
    for label, log, extra in (("ros2", bag2, []), ("ros1", ros1, []),
                              ("csv", csv, ["--columns", str(cmap)])):
        out = tmp_path / f"{label}.yaml"
        assert main(["arm", "identify", str(log), *extra, "--out", str(out)]) == 0
        theta[label] = load_arm_model(out).theta
    capsys.readouterr()
    for label in ("ros1", "csv"):
        np.testing.assert_allclose(theta[label], theta["ros2"], rtol=1e-9, atol=1e-9)


def test_a_misspelt_csv_column_is_one_line_with_the_closest_name(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A CSV joint log whose column names a joint wrongly, one whose column map does, and a
    column map naming a column the file lacks: each one line, exit 2, naming the file, the
    column and the closest valid name."""
    from dampest_ros.io.arm import load_arm
    from dampest_ros.io.csv import write_table

    names = load_arm("ur5").model.names
    t = np.arange(50) * 0.002
    cols = {"time": t, **{f"{n}.q": np.sin(t) for n in names},
            **{f"{n}.tau": np.cos(t) for n in names}}
    cols["elbow_jiont.q"] = cols.pop("elbow_joint.q")
    log = write_table(tmp_path / "log.csv", cols)
    assert main(["arm", "identify", str(log)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"dampest arm: error: {log}: column 'elbow_jiont.q' is no column of this "
                   "arm; the closest valid name is 'elbow_joint.q' (joint elbow_joint's "
                   "position in rad): rename the column to 'elbow_joint.q' or map it in the "
                   "column map (--columns)"]
    cmap = tmp_path / "c.yaml"
    cmap.write_text("elbow_jiont.q: elbow_joitn.q\n")
    assert main(["arm", "identify", str(log), "--columns", str(cmap)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "column 'elbow_jiont.q' (mapped to 'elbow_joitn.q' by the " \
        "column map) is no column of this arm; the closest valid name is 'elbow_joint.q'" \
        in err[0] and str(log) in err[0]
    cmap.write_text("elbow_joint_.q: elbow_joint.q\n")
    assert main(["arm", "identify", str(log), "--columns", str(cmap)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the column map maps 'elbow_joint_.q' to 'elbow_joint.q' " \
        "(joint elbow_joint's position in rad), but the file has no column 'elbow_joint_.q'; " \
        "closest column: 'elbow_jiont.q'" in err[0] and str(log) in err[0]


def test_report_draws_trajectory_fit_and_parameters_with_units(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], saved_figures: list[Any],
        axis_unit_problems: Callable[[list[Any]], list[str]]) -> None:
    """--report draws the trajectory, the measured torque against the model's with its
    residual, and the base parameters with σ against the nominal, every axis with its
    unit; what they show is the fit: the residual is measured − model, the parameter panels
    hold the model file's θ (elbow friction within 2 % of the simulated 2 N·m)."""
    bag = tmp_path / "train"
    assert main(["arm", "simulate", "--random", "3", "--duration", "20", "--seed", "1",
                 "--rate", "500", "--out", str(bag)]) == 0
    saved_figures.clear()
    assert main(["arm", "identify", str(bag), "--out", str(tmp_path / "p.yaml"),
                 "--report", str(tmp_path / "rep")]) == 0
    capsys.readouterr()
    model = load_arm_model(tmp_path / "p.yaml")
    titles = [f.texts[0].get_text() for f in saved_figures]
    assert titles == ["Joint trajectory (filtered positions q)",
                      "Joint torque: measured (filtered) vs the WLS model",
                      "Base parameters: WLS estimate with 95 % interval vs nominal"]
    assert axis_unit_problems(saved_figures) == []
    page = (tmp_path / "rep" / "index.html").read_text()
    for png in ("trajectory.png", "fit_torque.png", "parameters.png"):
        assert f"src='{png}'" in page and (tmp_path / "rep" / png).stat().st_size > 10_000
    torque = saved_figures[1].axes
    measured, fitted = (line.get_ydata() for line in torque[0].lines[:2])
    np.testing.assert_allclose(torque[1].lines[0].get_ydata(), measured - fitted, atol=1e-12)
    assert torque[0].get_ylabel() == "shoulder_pan_joint (N·m)"
    panels = {ax.get_title(): ax for ax in saved_figures[2].axes if ax.get_visible()}
    assert list(panels) == model.parameter_names
    fc = panels["elbow_joint.Fc"]
    estimate = fc.lines[0].get_ydata()[0] if fc.lines[0].get_xdata()[0] == 0 else None
    assert estimate == model.theta[model.parameter_names.index("elbow_joint.Fc")]
    assert estimate == pytest.approx(2.0, rel=0.02)
    assert fc.get_ylabel() == "(N·m)"


def test_design_objective_dopt_writes_its_log_det(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "dopt.yaml"
    assert main(["arm", "design", "--objective", "dopt", "--harmonics", "2", "--iterations",
                 "2", "--out", str(out)]) == 0
    doc = yaml.safe_load(out.read_text())
    assert doc["objective"] == "dopt" and doc["logdet"] > doc["logdet_random_median"]
    assert "log det of the column-normalised information matrix" in capsys.readouterr().out
    # a misspelt objective is argparse's one line and exit 2, no file
    with pytest.raises(SystemExit) as exc:
        main(["arm", "design", "--objective", "dopd", "--out", str(tmp_path / "x.yaml")])
    assert exc.value.code == 2 and not (tmp_path / "x.yaml").exists()
    assert "invalid choice: 'dopd'" in capsys.readouterr().err
