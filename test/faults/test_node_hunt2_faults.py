"""preprocess_node, recorder_node and replay_node fed what a user might give them: a message
no sensor sends is rejected, counted on /diagnostics and logged once while the node runs on;
a setting that cannot work is refused at start in one line with exit status 2.

In-process nodes on ROS_DOMAIN_ID 33 (localhost only)."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy")

from geometry_msgs.msg import TwistWithCovarianceStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from sensor_msgs.msg import FluidPressure, Imu, JointState  # noqa: E402

from dampest_ros.io.bag import offered_qos  # noqa: E402
from dampest_ros.io.recorder import BagRecorder  # noqa: E402
from dampest_ros.io.yaml_io import load_vehicle  # noqa: E402
from dampest_ros.ros.preprocess_node import PreprocessNode  # noqa: E402
from dampest_ros.ros.recorder_node import RecorderNode  # noqa: E402
from dampest_ros.ros.replay_node import ReplayNode  # noqa: E402

THRUSTERS = load_vehicle("bluerov2_heavy").thrusters.names
DOMAIN = "33"  # this module's ROS domain (the context fixture)


def _stamped(m: Any, t: float, frame: str = "") -> Any:
    m.header.stamp.sec, m.header.stamp.nanosec = int(t), round((t % 1) * 1e9)
    m.header.frame_id = frame
    return m


def imu(t: float, accel: float = 9.81) -> bytes:
    """A level, still IMU at stamp ``t`` (s) with specific force ``accel`` up (m/s²)."""
    m = _stamped(Imu(), t, "imu_link")
    m.orientation.w = 1.0
    m.linear_acceleration.z = accel
    return serialize_message(m)


def dvl(t: float) -> bytes:
    """A DVL fix of 0.1 m/s forward (σ 1 cm/s)."""
    m = _stamped(TwistWithCovarianceStamped(), t, "dvl_link")
    m.twist.twist.linear.x = 0.1
    m.twist.covariance[0] = m.twist.covariance[7] = m.twist.covariance[14] = 1e-4
    return serialize_message(m)


def pressure(t: float) -> bytes:
    """1 m of water."""
    m = _stamped(FluidPressure(), t, "pressure_link")
    m.fluid_pressure = 101325.0 + 1e4
    return serialize_message(m)


def thrusters(t: float, names: list[str] | None = None,
              effort: list[float] | None = None) -> JointState:
    """1 N on each of the vehicle's thrusters (or the given names and efforts)."""
    m = _stamped(JointState(), t)
    m.name = list(THRUSTERS) if names is None else names
    m.effort = [1.0] * len(m.name) if effort is None else effort
    return m


def fly(node: PreprocessNode, t0: float, seconds: float, with_dvl: bool = True) -> float:
    """Feed ``seconds`` of a 200 Hz IMU, 10 Hz DVL, 20 Hz pressure and thrusters from stamp
    ``t0``; returns the last stamp."""
    k0 = round(t0 * 200)
    for k in range(k0 + 1, k0 + 1 + round(seconds * 200)):
        t = k / 200
        node._on_imu(imu(t))
        if k % 20 == 0 and with_dvl:
            node._on_dvl(dvl(t))
        if k % 10 == 0:
            node._on_thrusters(thrusters(t))
            node._on_pressure(pressure(t))
    return k0 / 200 + seconds


def status(node: PreprocessNode) -> Any:
    """The node's next diagnostics status (diagnostic_msgs/DiagnosticStatus)."""
    sent: list[Any] = []
    node.pub_diag.publish = sent.append  # type: ignore[method-assign]
    node._publish_diagnostics()
    return sent[-1].status[0]


def counts(node: PreprocessNode) -> dict[str, str]:
    """The key/values of the node's next diagnostics."""
    return {kv.key: kv.value for kv in status(node).values}


@pytest.fixture
def preprocess(context: Any) -> Iterator[PreprocessNode]:
    """A preprocess_node of the BlueROV2 Heavy that has flown 3 s (stamps 100 to 103 s)."""
    node = PreprocessNode(context=context)
    fly(node, 100.0, 3.0)
    yield node
    node.destroy_node()


def test_preprocess_rejects_thruster_names_that_are_not_the_vehicles(
        preprocess: PreprocessNode, caplog: pytest.LogCaptureFixture) -> None:
    """Was: a DataError raised in the subscription callback (a traceback; the node died)."""
    preprocess._on_thrusters(thrusters(103.001, names=[f"t{i}" for i in range(8)]))
    before = preprocess.published
    fly(preprocess, 103.0, 2.0)
    assert preprocess.published - before == 100  # 2 s at 50 Hz: it ran on
    assert counts(preprocess)["rejected_malformed"] == "1"


def test_preprocess_counts_efforts_not_one_per_name_as_malformed(
        preprocess: PreprocessNode) -> None:
    """Was: a JointState with 1 effort for 8 names (or none) counted as rejected_nonfinite."""
    preprocess._on_thrusters(thrusters(103.001, effort=[1.0]))
    preprocess._on_thrusters(thrusters(103.002, effort=[]))
    fly(preprocess, 103.0, 6.0)
    c = counts(preprocess)
    assert (c["rejected_malformed"], c["rejected_nonfinite"]) == ("2", "0")


def test_preprocess_rejects_an_implausible_specific_force(
        preprocess: PreprocessNode) -> None:
    """Was: one IMU message of 1e150 m/s² (finite) threw the velocity filter off: of the
    next 7 s, 69 DVL fixes gated as outliers and 54 samples published instead of 350."""
    preprocess._on_imu(imu(103.001, accel=1e150))
    before = preprocess.published
    fly(preprocess, 103.0, 7.0)
    c = counts(preprocess)
    assert preprocess.published - before == 350
    assert (c["rejected_implausible"], c["dvl_outliers"]) == ("1", "0")


def test_preprocess_rejects_a_message_stamped_0_without_a_reset(
        preprocess: PreprocessNode) -> None:
    """Was: one IMU message whose header was never stamped reset the whole state (a clock
    jump back of 103 s, then an IMU gap): 293 samples in the next 7 s instead of 350."""
    preprocess._on_imu(imu(0.0))
    before = preprocess.published
    fly(preprocess, 103.0, 7.0)
    c = counts(preprocess)
    assert preprocess.published - before == 350
    assert (c["rejected_unstamped"], c["clock_resets"]) == ("1", "0")


@pytest.fixture
def imu_bag(tmp_path: Path) -> Path:
    """A bag of 11 IMU messages over 1 s (log times 1 to 2 s) and a topic without messages."""
    path = tmp_path / "imu"
    with BagRecorder(path) as rec:
        conn = rec.add_connection("/imu/data", "sensor_msgs/msg/Imu", offered_qos("/imu/data"))
        rec.add_connection("/pressure", "sensor_msgs/msg/FluidPressure",
                           offered_qos("/pressure"))
        for k in range(11):
            t = 1.0 + k / 10
            rec.write(conn, round(t * 1e9), imu(t))
    return path


def replay_refusal(context: Any, bag: Path, **params: Any) -> str:
    """The one line with which replay_node refuses to start with ``params``."""
    overrides = [Parameter("bag", value=str(bag)), *(Parameter(k, value=v)
                                                     for k, v in params.items())]
    with pytest.raises(ValueError) as refused:
        ReplayNode(context=context, parameter_overrides=overrides)
    assert "\n" not in str(refused.value)
    return str(refused.value)


@pytest.mark.parametrize(("option", "value"), [
    ("topics", ["imu/dta"]), ("exclude_topics", ["imu/dta"]), ("remap", ["imu/dta:=x"])])
def test_replay_refuses_a_topic_the_bag_does_not_have(context: Any, imu_bag: Path,
                                                      option: str, value: list[str]) -> None:
    """Was: topics: a warning, 0 messages played, status 0; exclude_topics and remap: the
    misspelt name silently ignored (everything played, nothing renamed)."""
    text = replay_refusal(context, imu_bag, **{option: value})
    assert f"{option}: /imu/dta not in the bag; did you mean /imu/data?" in text


def test_replay_refuses_a_start_offset_past_the_end(context: Any, imu_bag: Path) -> None:
    """Was: 'finished: published 0/11 messages', status 0 (with loop: a core spun for good)."""
    text = replay_refusal(context, imu_bag, start_offset=5.0)
    assert "start_offset 5 s is past the end of the bag (1.000 s" in text


def test_replay_refuses_a_remap_to_an_invalid_name(context: Any, imu_bag: Path) -> None:
    """Was: rclpy's InvalidTopicNameException, a traceback and status 1."""
    text = replay_refusal(context, imu_bag, remap=["imu/data:=imu data"])
    assert text.startswith("remap: 'imu data' is not a valid topic name")


def test_replay_loop_over_no_message_ends(context: Any, imu_bag: Path) -> None:
    """Was: loop over a topic without messages re-read the bag forever at 100 % of a core."""
    node = ReplayNode(context=context, parameter_overrides=[
        Parameter("bag", value=str(imu_bag)), Parameter("topics", value=["pressure"]),
        Parameter("loop", value=True), Parameter("wait_for_subscribers", value=0)])
    try:
        playing = threading.Thread(target=node._play, daemon=True)
        playing.start()
        playing.join(timeout=5.0)
        assert not playing.is_alive() and node.published == 0
    finally:
        node.destroy_node()


def test_recorder_names_a_wanted_topic_nobody_publishes_and_the_closest(
        context: Any, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """Was: topics [imu/dta] while imu/data ran recorded nothing, and no warning came (the
    silence warning only when no topic at all delivered)."""
    node = RecorderNode(context=context, parameter_overrides=[
        Parameter("output", value=str(tmp_path / "bag")),
        Parameter("topics", value=["imu/dta", "pressure"])])
    try:
        node.create_publisher(Imu, "imu/data", 10)
        node.create_publisher(FluidPressure, "pressure", 10)
        node._discover()
        assert node.silence_timer is not None
        node._warn_if_silent()
        err = capfd.readouterr().err
        assert "no publisher of /imu/dta after 5 s (nothing recorded from it); did you mean " \
               "/imu/data?" in err
        assert "/pressure after" not in err
    finally:
        node.destroy_node()


def test_recorder_closes_its_bag_through_a_train_of_signals(tmp_path: Path) -> None:
    """Ctrl-C pressed again and again (or a launch system's repeated SIGTERM) from the moment
    the recorder creates its bag until it has exited: the close finishes (metadata.yaml
    written) or, stopped inside the bag's open, nothing is left; at most one warning, no
    traceback, status 0. Before, a second SIGINT raised
    KeyboardInterrupt inside the close (3 runs of 3), and one during the node's start left
    the bag open without metadata.yaml."""
    import os
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "bag"
    env = dict(os.environ, ROS_DOMAIN_ID="34", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    proc = subprocess.Popen(  # the console script's entry, as ros2 run starts it
        [sys.executable, "-c", "from dampest_ros.ros.entry import recorder_node; recorder_node()",
         "--ros-args", "-p", f"output:={out}"], env=env, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True, start_new_session=True)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")))
    reader.start()
    try:
        deadline = time.monotonic() + 30.0
        while not out.exists() and time.monotonic() < deadline:  # the bag is open: the
            time.sleep(0.001)  # node may still be starting (a Ctrl-C there closes it too)
        while proc.poll() is None and time.monotonic() < deadline:
            proc.send_signal(signal.SIGINT)
            time.sleep(0.01)  # ten times as fast as a hand on Ctrl-C
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        reader.join()
    text = "".join(lines)
    assert proc.returncode == 0, text
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text
    # a bag complete with its metadata, or (stopped inside its open) no bag at all
    assert (out / "metadata.yaml").exists() or not out.exists(), sorted(out.iterdir())
    assert text.count("while closing: finishing the close first") <= 1, text


def test_preprocess_rebuild_keeps_its_counts_and_the_messages_it_held(
        preprocess: PreprocessNode) -> None:
    """Was: a parameter change rebuilt the preprocessor and the stamp order with their counts
    at 0 (a rejection vanished from /diagnostics) and dropped the messages the stamp order
    still held (up to reorder_latency of every sensor)."""
    preprocess._on_thrusters(thrusters(103.001, effort=[1.0]))  # held by the stamp order
    preprocess.set_parameters([Parameter("settle", value=2.0)])
    c = counts(preprocess)
    assert c["rejected_malformed"] == "1"
    assert (c["imu"], c["dvl"], c["pressure"], c["thrusters"]) == ("600", "30", "60", "61")
    fly(preprocess, 103.0, 1.0)
    assert counts(preprocess)["imu"] == "800"


def test_preprocess_says_when_one_sensor_has_gone_silent(preprocess: PreprocessNode) -> None:
    """Was: with the DVL silent the status stayed 'ok' (no sample usable, nothing said)."""
    assert status(preprocess).message == "ok"
    t = 103.0
    messages = []
    for _ in range(6):  # 6 diagnostics periods (1 s each) without the DVL
        t = fly(preprocess, t, 1.0, with_dvl=False)
        s = status(preprocess)
        messages.append((int.from_bytes(s.level, "little"), s.message))
    assert messages[3] == (0, "ok")
    assert messages[4:] == [(1, "no dvl message for 5 s while the others arrive"),
                            (1, "no dvl message for 6 s while the others arrive")]
    fly(preprocess, t, 1.0)  # back
    assert status(preprocess).message == "ok"
