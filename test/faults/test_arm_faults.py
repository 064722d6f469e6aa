"""Arm faults: an implausible JointState sample, offline and online; backwards clocks in arm
logs; `dampest arm simulate` with a diverging run or a payload after the end."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dampest_ros.cli.main import main
from dampest_ros.core.arm.design import default_limits
from dampest_ros.core.arm.ffs import random_trajectory
from dampest_ros.core.arm.simulate import REALISTIC, ArmRun, simulate_arm
from dampest_ros.core.signals.measurements import JointSeries
from dampest_ros.io import cdr
from dampest_ros.io.arm import load_arm, load_arm_model, save_trajectory
from dampest_ros.io.bag import offered_qos, read_bag
from dampest_ros.io.recorder import BagRecorder

rclpy = pytest.importorskip("rclpy")

from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from dampest_ros.ros.arm_estimator_node import ArmEstimatorNode  # noqa: E402
from dampest_ros.ros.common import to_time  # noqa: E402


@pytest.fixture(scope="module")
def ur5_run() -> ArmRun:
    """20 s of the UR5 at 250 Hz, realistic sensors (seeded)."""
    arm = load_arm("ur5")
    traj = random_trajectory(np.zeros(6), 5, 0.1, np.full(6, 1.5), np.random.default_rng(3))
    return simulate_arm(arm.mjcf, arm.model, arm.dynamics, traj, 20.0, 250.0, REALISTIC,
                        seed=1)


def stream(node: ArmEstimatorNode, run: ArmRun, effort: np.ndarray) -> dict[str, str]:
    """Hand ``run`` (with ``effort``) to the node as JointState messages; its diagnostics."""
    for k, t in enumerate(run.t):
        m = JointState(name=list(node.names), position=list(run.position[k]),
                       effort=list(effort[k]), velocity=[])
        m.header.stamp = to_time(float(t))
        node._on_joint_state(m)
    sent: list[Any] = []
    node.pub_diag.publish = sent.append  # type: ignore[method-assign,assignment]
    node._publish()
    return {kv.key: kv.value for kv in sent[-1].status[0].values}


def test_a_huge_finite_effort_is_rejected_and_counted_by_the_arm_estimator(
        ur5_run: ArmRun, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Was: one 1e200 N m effort at 12 s took θ to ~3e197 with 58 NaN σ, served, and no
    counter moved. Now it is rejected before the filter and counted; like a lost message it
    is a gap (the filter restarts after it), and the estimate stays within 2 σ of the one
    from the clean stream."""
    monkeypatch.setenv("ROS_DOMAIN_ID", "93")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = rclpy.Context()
    rclpy.init(context=context)
    params = [Parameter("save_path", value=str(tmp_path / "arm.yaml")),
              Parameter("resume", value=False)]
    spiked = ur5_run.effort.copy()
    spiked[np.searchsorted(ur5_run.t, 12.0), 2] = 1e200
    try:
        clean = ArmEstimatorNode(context=context, parameter_overrides=params)
        stream(clean, ur5_run, ur5_run.effort)
        node = ArmEstimatorNode(context=context, parameter_overrides=params)
        values = stream(node, ur5_run, spiked)
        theta, std = node.estimator.theta, node.estimator.std
        assert np.all(np.isfinite(std))
        assert np.max(np.abs(theta - clean.estimator.theta) / std) < 2.0
        assert values["count.rejected_implausible"] == "1"
        assert values["count.rejected_nonfinite"] == "0"
        assert values["count.gaps"] == "1" and clean.estimator.gaps == 0
        assert clean.counts["used"] - int(values["count.used"]) == 150  # 3 s at 50 Hz
    finally:
        rclpy.try_shutdown(context=context)


def refused(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """The one stderr line of a dampest command that exits 2."""
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return err


def test_arm_simulate_refuses_a_nan_trajectory(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """Was: a bag of NaN efforts written, exit 0."""
    traj = random_trajectory(np.zeros(6), 2, 0.2, np.full(6, 0.5), np.random.default_rng(1))
    traj.a[2, 1] = np.nan
    path = tmp_path / "traj.yaml"
    save_trajectory(path, traj, default_limits(load_arm("ur5").model), {"arm": "ur5"})
    err = refused(["arm", "simulate", "--trajectory", str(path), "--duration", "1", "--out",
                   str(tmp_path / "bag")], capsys)
    assert err == (f"dampest arm: error: trajectory file {path}: a must be numbers (finite; "
                   "base_frequency > 0); write the file again with 'dampest arm design'")
    assert not (tmp_path / "bag").exists()


def test_arm_simulate_refuses_a_run_that_diverges(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """Was: a 1e6 kg payload wrote a bag of joints 6000 rad and 1e13 N m away, exit 0."""
    err = refused(["arm", "simulate", "--random", "7", "--duration", "4", "--payload", "1e6",
                   "2", "--out", str(tmp_path / "bag")], capsys)
    assert err == ("dampest arm: error: the simulation diverged at t = 2.956 s: wrist_1_joint "
                   "is 4.33 rad off its trajectory (the controller cannot follow it: a lighter "
                   "payload or a slower trajectory)")
    assert not (tmp_path / "bag").exists()


def test_arm_simulate_refuses_a_payload_after_the_end(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """Was: accepted; the bag had no payload at all."""
    err = refused(["arm", "simulate", "--random", "7", "--duration", "2", "--payload", "1",
                   "50", "--out", str(tmp_path / "bag")], capsys)
    assert err == ("dampest arm: error: payload time 50 s is not within the 2 s run; attach "
                   "it between 0 and 2 s")
    assert not (tmp_path / "bag").exists()


def jumped_bag(src: Path, dst: Path, at: float, back: float) -> Path:
    """``src`` with the JointState header stamps from ``at`` s on ``back`` s earlier (the
    log times, the recorded order, unchanged)."""
    series = read_bag(src, ["joint_states"])["joint_states"]
    assert isinstance(series, JointSeries)
    log_ns = cdr.stamps_to_ns(series.stamp)
    stamp = np.where(series.stamp >= at, series.stamp - back, series.stamp)
    data = cdr.encode(replace(series, stamp=stamp))
    with BagRecorder(dst) as rec:
        conn = rec.add_connection("/joint_states", "sensor_msgs/msg/JointState",
                                  offered_qos("/joint_states"))
        for t, msg in zip(log_ns.tolist(), data, strict=True):
            rec.write(conn, t, msg)
    return dst


def test_a_clock_jump_back_in_an_arm_bag_is_named_and_split_there(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Was: the samples re-sorted by stamp silently, 5 s of two trajectories interleaved,
    the estimate 5 to 29 σ off. Now the jump is named (sample, stamp, how far back) and the
    record is split there: the estimate stays within 1 σ of the clean log's."""
    clean = tmp_path / "clean"
    assert main(["arm", "simulate", "--random", "7", "--duration", "30", "--rate", "250",
                 "--out", str(clean)]) == 0
    jumped = jumped_bag(clean, tmp_path / "jumped", 15.0, 5.0)
    capsys.readouterr()
    theta = {}
    for name, bag in (("clean", clean), ("jumped", jumped)):
        assert main(["arm", "identify", str(bag), "--out", str(tmp_path / f"{name}.yaml")]) == 0
        theta[name] = load_arm_model(tmp_path / f"{name}.yaml")
    out = capsys.readouterr().out
    assert (f"{jumped}: 1 gap: 2 gap-free stretches filtered, 0 too short (0 s) left out; the "
            "clock jumps back 4.996 s at sample 3750 (after t = 14.996 s): split there") in out
    z = (theta["jumped"].theta - theta["clean"].theta) / theta["clean"].theta_std
    assert np.max(np.abs(z)) < 1.0


def test_arm_estimator_counts_are_life_totals_across_a_rebuild_and_a_reset(
        ur5_run: ArmRun, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Was: count.gaps and count.rejected_implausible (kept by the estimator) went back to 0
    when a parameter change rebuilt the estimator, so a rejected message vanished from
    /diagnostics. The counts are the node's life totals, as the vehicle estimator_node's:
    a rebuild or ~/reset restarts the estimate, not the counts."""
    from std_srvs.srv import Trigger

    monkeypatch.setenv("ROS_DOMAIN_ID", "93")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = rclpy.Context()
    rclpy.init(context=context)
    spiked = ur5_run.effort.copy()
    spiked[np.searchsorted(ur5_run.t, 12.0), 2] = 1e200
    try:
        node = ArmEstimatorNode(context=context, parameter_overrides=[
            Parameter("save_path", value=str(tmp_path / "arm.yaml")),
            Parameter("resume", value=False)])
        first = stream(node, ur5_run, spiked)
        assert first["count.rejected_implausible"] == "1" and first["count.gaps"] == "1"
        assert node.set_parameters([Parameter("cutoff", value=4.0)])[0].successful
        assert node.estimator.gaps == 0          # a new estimator: its own counts start at 0
        node._srv_reset(Trigger.Request(), Trigger.Response())
        later = ur5_run.t + ur5_run.t[-1] + 1.0   # the stream goes on after the changes
        again = stream(node, replace(ur5_run, t=later), spiked)
        assert again["count.rejected_implausible"] == "2" and again["count.gaps"] == "2"
        assert int(again["count.received"]) == 2 * len(ur5_run.t)
        assert int(again["count.used"]) > int(first["count.used"])
    finally:
        rclpy.try_shutdown(context=context)
