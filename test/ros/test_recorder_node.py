"""recorder_node in-process: its take thread writes bursts while the executor is idle, it
subscribes to publishers that appear after its start within its early looks at the graph,
it stamps messages with the reception time (the simulation time under use_sim_time), and a
write refused in the take thread ends the node with status 1.

Runs on its own ROS_DOMAIN_ID, localhost only (docs/architecture.md §6)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy")

from mcap.reader import make_reader  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosgraph_msgs.msg import Clock as ClockMsg  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

from dampest_ros.core.signals.measurements import ImuSeries  # noqa: E402
from dampest_ros.io import bag  # noqa: E402
from dampest_ros.io.recorder import StorageError  # noqa: E402
from dampest_ros.ros.common import RELIABLE_QOS, SENSOR_QOS  # noqa: E402
from dampest_ros.ros.recorder_node import RecorderNode  # noqa: E402

DOMAIN = 91


@pytest.fixture
def ctx() -> Iterator[Any]:
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=DOMAIN)
    yield context
    rclpy.try_shutdown(context=context)


def wait_until(done: Callable[[], bool], timeout: float) -> bool:
    """Wait without spinning any executor."""
    end = time.monotonic() + timeout
    while not done():
        if time.monotonic() > end:
            return False
        time.sleep(0.01)
    return True


def recorder(ctx: Any, out: Path, **params: Any) -> RecorderNode:
    overrides = [Parameter("output", value=str(out)), Parameter("status_period", value=0.0),
                 *(Parameter(k, value=v) for k, v in params.items())]
    return RecorderNode(context=ctx, parameter_overrides=overrides)


def log_times(path: Path) -> dict[str, list[tuple[int, int, int]]]:
    """Per topic: (sequence, log time, publish time) of every message, in file order."""
    out: dict[str, list[tuple[int, int, int]]] = {}
    for f in sorted(path.glob("*.mcap")):
        with f.open("rb") as stream:
            for _, channel, m in make_reader(stream).iter_messages(log_time_order=False):
                out.setdefault(channel.topic, []).append((m.sequence, m.log_time,
                                                          m.publish_time))
    return out


def test_burst_written_by_the_take_thread_with_the_executor_idle(
        ctx: Any, tmp_path: Path, spin_until: Callable[..., bool]) -> None:
    """Publishers created after the start are found by the early looks (discovery_period
    60 s); then 600 messages published at once all reach the bag while no executor spins,
    each stamped between its publication and the moment the bag had it."""
    rec = recorder(ctx, tmp_path / "bag", topics=["imu/data", "truth/odom"],
                   discovery_period=60.0)
    src = rclpy.create_node("recorder_test_source", context=ctx)
    imu = src.create_publisher(Imu, "imu/data", SENSOR_QOS)
    odom = src.create_publisher(Odometry, "truth/odom", RELIABLE_QOS)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(rec)
    try:
        assert spin_until(ex, lambda: len(rec.subs) == 2 and imu.get_subscription_count() == 1
                          and odom.get_subscription_count() == 1, 10.0), rec.subs
        t0 = time.time_ns()
        for k in range(500):
            m = Imu()
            m.angular_velocity.x = float(k)
            imu.publish(m)
            if k % 5 == 0:
                odom.publish(Odometry())
        assert wait_until(lambda: rec.recorder.message_count == 600, 10.0), \
            rec.recorder.message_count
        t1 = time.time_ns()
        assert rec.stats()["messages"] == {"/imu/data": 500, "/truth/odom": 100}
    finally:
        ex.shutdown()
        rec.destroy_node()  # closes the bag
        src.destroy_node()
    assert bag.bag_summary(tmp_path / "bag").message_count == 600
    data = bag.read_bag(tmp_path / "bag")["imu/data"]
    assert isinstance(data, ImuSeries)
    assert list(data.angular_velocity[:, 0]) == [float(k) for k in range(500)]
    for topic, msgs in log_times(tmp_path / "bag").items():
        assert [s for s, _, _ in msgs] == list(range(1, len(msgs) + 1)), topic
        assert all(t0 <= sent <= logged <= t1 for _, logged, sent in msgs), topic


def test_log_time_is_the_simulation_time_under_use_sim_time(
        ctx: Any, tmp_path: Path, spin_until: Callable[..., bool]) -> None:
    rec = recorder(ctx, tmp_path / "bag", topics=["imu/data"], use_sim_time=True)
    src = rclpy.create_node("recorder_test_clock", context=ctx)
    clock = src.create_publisher(ClockMsg, "/clock", 10)
    imu = src.create_publisher(Imu, "imu/data", SENSOR_QOS)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(rec)
    sim_ns = 123_456_000_000
    try:
        def clock_set() -> bool:
            clock.publish(ClockMsg(clock=rclpy.time.Time(nanoseconds=sim_ns).to_msg()))
            return rec.get_clock().now().nanoseconds == sim_ns and len(rec.subs) == 1
        assert spin_until(ex, clock_set, 10.0)
        imu.publish(Imu())
        assert wait_until(lambda: rec.recorder.message_count == 1, 10.0)
    finally:
        ex.shutdown()
        rec.destroy_node()
        src.destroy_node()
    ((_, logged, sent),) = log_times(tmp_path / "bag")["/imu/data"]
    assert logged == sim_ns and sent > 1e18  # the publisher's stamp is the system clock's


def test_write_refused_in_the_take_thread_ends_the_node_with_status_1(
        ctx: Any, tmp_path: Path, spin_until: Callable[..., bool]) -> None:
    rec = recorder(ctx, tmp_path / "bag", topics=["imu/data"])
    src = rclpy.create_node("recorder_test_full", context=ctx)
    imu = src.create_publisher(Imu, "imu/data", SENSOR_QOS)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(rec)

    def refuse(*_: Any, **__: Any) -> None:
        raise StorageError("No space left on device while recording: recording stopped")

    try:
        assert spin_until(ex, lambda: imu.get_subscription_count() == 1, 10.0)
        rec.recorder.write = refuse  # type: ignore[method-assign]
        imu.publish(Imu())
        with pytest.raises(SystemExit) as stopped:
            spin_until(ex, lambda: False, 10.0)
        assert stopped.value.code == 1
        assert not rec._taker.is_alive()
    finally:
        ex.shutdown()
        rec.destroy_node()
        src.destroy_node()


class Warnings:
    """A logger stand-in that keeps the warnings."""

    def __init__(self) -> None:
        self.lines: list[str] = []

    def warning(self, text: str) -> None:
        self.lines.append(text)

    def info(self, text: str) -> None:
        """Info lines are not kept."""


def test_silence_after_the_start_is_warned_with_the_domain(
        ctx: Any, tmp_path: Path, spin_until: Callable[..., bool],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Nothing published: after silence_warning seconds one warning names the topics and the
    ROS_DOMAIN_ID the recorder listens on; it does not repeat."""
    rec = recorder(ctx, tmp_path / "bag", topics=["imu/data", "dvl/twist"],
                   silence_warning=0.3)
    log = Warnings()
    monkeypatch.setattr(rec, "get_logger", lambda: log)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(rec)
    try:
        spin_until(ex, lambda: False, 1.0)
    finally:
        ex.shutdown()
        rec.destroy_node()
    assert log.lines == ["no message on any of the 2 topics after 0.3 s (0 with a publisher): "
                         f"is the pipeline running, on this ROS_DOMAIN_ID ({DOMAIN})?"]


def test_exclude_regex_keeps_topics_out_and_a_recording_is_not_warned(
        ctx: Any, tmp_path: Path, spin_until: Callable[..., bool],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """-x '^/truth/' with every topic: truth/odom is published but not recorded, imu/data
    is; messages within silence_warning: no warning."""
    rec = recorder(ctx, tmp_path / "bag", topics=["all"], exclude_regex="^/truth/",
                   silence_warning=3.0)
    log = Warnings()
    monkeypatch.setattr(rec, "get_logger", lambda: log)
    src = rclpy.create_node("recorder_test_exclude", context=ctx)
    imu = src.create_publisher(Imu, "imu/data", SENSOR_QOS)
    odom = src.create_publisher(Odometry, "truth/odom", RELIABLE_QOS)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(rec)
    try:
        assert spin_until(ex, lambda: imu.get_subscription_count() == 1, 2.5)
        imu.publish(Imu())
        odom.publish(Odometry())
        assert wait_until(lambda: rec.recorder.message_count == 1, 5.0)
        spin_until(ex, lambda: False, 3.5)
        assert odom.get_subscription_count() == 0 and "/truth/odom" not in rec.subs
    finally:
        ex.shutdown()
        rec.destroy_node()
        src.destroy_node()
    assert {t: s.count for t, s in bag.bag_summary(tmp_path / "bag").topics.items()} \
        == {"/imu/data": 1}
    assert log.lines == []


def test_regex_records_the_topics_it_matches_and_only_those(
        ctx: Any, tmp_path: Path, spin_until: Callable[..., bool]) -> None:
    """regex '^/imu/' without topics (dampest record -e '^/imu/'): imu/data, published, is
    recorded as soon as it appears; truth/odom, published too, is not."""
    rec = recorder(ctx, tmp_path / "bag", topics=[""], regex="^/imu/")
    src = rclpy.create_node("recorder_test_regex", context=ctx)
    odom = src.create_publisher(Odometry, "truth/odom", RELIABLE_QOS)
    imu = src.create_publisher(Imu, "imu/data", SENSOR_QOS)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(rec)
    try:
        assert spin_until(ex, lambda: imu.get_subscription_count() == 1, 2.5)
        for _ in range(3):
            imu.publish(Imu())
            odom.publish(Odometry())
        assert wait_until(lambda: rec.recorder.message_count == 3, 5.0)
        assert odom.get_subscription_count() == 0 and list(rec.subs) == ["/imu/data"]
    finally:
        ex.shutdown()
        rec.destroy_node()
        src.destroy_node()
    assert {t: s.count for t, s in bag.bag_summary(tmp_path / "bag").topics.items()} \
        == {"/imu/data": 3}


def test_no_topic_and_no_regex_is_refused_at_start(ctx: Any, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"topics must name at least one topic, or be "
                                         r"\['all'\], or regex select them"):
        recorder(ctx, tmp_path / "bag", topics=[""])
