"""dampest replay and its receivers: it waits for matched subscribers by default and says
how many messages were published while their topic had one."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

from dampest_ros.cli.main import main  # noqa: E402
from dampest_ros.io.bag import bag_summary  # noqa: E402
from dampest_ros.ros.common import RELIABLE_QOS  # noqa: E402


@pytest.fixture
def domain(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "93")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


@pytest.fixture
def imu_listener(domain: None) -> Iterator[list[Any]]:
    """A node of its own context counting imu/data messages (reliable), spun in a thread."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("imu_listener", context=ctx)
    got: list[Any] = []
    node.create_subscription(Imu, "imu/data", got.append, RELIABLE_QOS)
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
