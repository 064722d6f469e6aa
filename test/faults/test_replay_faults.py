"""dampest replay and its receivers: it waits for matched subscribers by default and says
how many messages were published while their topic had one; the estimator counts what it
lost on the way."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy")

from geometry_msgs.msg import (  # noqa: E402
    AccelWithCovarianceStamped,
    QuaternionStamped,
    TwistWithCovarianceStamped,
    WrenchStamped,
)
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

from dampest_ros.cli.main import main  # noqa: E402
from dampest_ros.io.bag import bag_summary  # noqa: E402
from dampest_ros.ros.common import RELIABLE_QOS, to_time  # noqa: E402
from dampest_ros.ros.estimator_node import EstimatorNode  # noqa: E402


@pytest.fixture
def domain(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "93")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


@pytest.fixture
def imu_listener(domain: None) -> Iterator[list[Any]]:
    """A node of its own context counting imu/data messages (reliable, a queue that holds the
    whole bag), spun in a thread."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("imu_listener", context=ctx)
    got: list[Any] = []
    node.create_subscription(Imu, "imu/data", got.append,
                             QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE))
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    thread = threading.Thread(target=ex.spin, daemon=True)
    thread.start()
    yield got
    ex.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)
    thread.join(timeout=5)


def test_replay_waits_for_a_subscriber_and_every_message_reaches_it(
        sim_bag: Path, imu_listener: list[Any], capfd: pytest.CaptureFixture[str]) -> None:
    """Was: playback began at once and a receiver that matched 0.05 to 3.4 s later missed
    what came before (0 to 92.6 % received) while the log said 100 %."""
    total = bag_summary(sim_bag).topics["/imu/data"].count
    assert main(["replay", str(sim_bag), "--topics", "imu/data", "--rate", "30",
                 "--reliability", "reliable"]) == 0
    err = capfd.readouterr().err
    # acknowledged is in the listener's reader queue; its thread may not have taken it yet
    deadline = time.monotonic() + 10.0
    while len(imu_listener) < total and time.monotonic() < deadline:
        time.sleep(0.05)
    assert len(imu_listener) == total == 6001
    assert (f"finished: published {total}/{total} messages (100.0 %), {total} (100.0 %) while "
            "their topic had a subscriber") in err


def test_replay_without_a_subscriber_warns_and_counts_what_reached_no_one(
        sim_bag: Path, domain: None, capfd: pytest.CaptureFixture[str]) -> None:
    """Was: '6000/6000 messages (100 %)' with no one listening."""
    assert main(["replay", str(sim_bag), "--topics", "pressure", "--rate", "50",
                 "--wait-for-subscribers-timeout", "0.3"]) == 0
    err = capfd.readouterr().err
    assert ("fewer than 1 subscriber(s) after 0.3 s on ['/pressure']; playing anyway: what "
            "they publish now reaches no one") in err
    assert "(100.0 %), 0 (0.0 %) while their topic had a subscriber" in err


def test_estimator_counts_the_samples_lost_before_it_took_them(
        domain: None, tmp_path: Path) -> None:
    """Was: at 10x replay the estimator's reader queues (200 deep) overflowed and 0.3 to
    1.4 % of the samples vanished from every counter. A burst of 1000 samples while the
    node does not spin: the queues keep the last 200 of each topic and 4 × 800 messages are
    counted lost. (Nothing is known of a topic before its first message is taken.)"""
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        est = EstimatorNode(context=ctx, parameter_overrides=[
            Parameter("save_path", value=str(tmp_path / "m.yaml")),
            Parameter("resume", value=False)])
        probe = rclpy.create_node("burst", context=ctx)
        kinds = {"velocity": TwistWithCovarianceStamped, "acceleration": AccelWithCovarianceStamped,
                 "wrench": WrenchStamped, "attitude": QuaternionStamped}
        pubs = {n: probe.create_publisher(k, f"dampest/{n}", RELIABLE_QOS)
                for n, k in kinds.items()}
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(est)
        deadline = time.monotonic() + 10.0
        while any(p.get_subscription_count() < 1 for p in pubs.values()) \
                and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)

        def publish(k: int) -> None:
            for n, kind in kinds.items():
                m = kind()
                m.header.stamp = to_time(10.0 + 0.02 * k)
                if n == "attitude":
                    m.quaternion.w = 1.0
                pubs[n].publish(m)

        def spin(seconds: float) -> None:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                ex.spin_once(timeout_sec=0.05)

        publish(0)  # taken: the node knows where each topic's numbers are
        spin(0.5)
        for k in range(1, 1001):  # while the node does not spin
            publish(k)
        spin(2.0)
        sent: list[Any] = []
        est.pub_diag.publish = sent.append  # type: ignore[method-assign,assignment]
        est._publish()
        values = {kv.key: kv.value for kv in sent[-1].status[0].values}
        assert values["count.lost_in_transport"] == "3200"
        assert values["count.matched"] == "201"
    finally:
        rclpy.try_shutdown(context=ctx)
