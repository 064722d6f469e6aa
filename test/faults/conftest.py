"""Shared inputs of the fault suite: a short simulated bag and bags made wrong from it."""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import pytest
from rosbags.rosbag2 import Reader

from dampest_ros.cli.main import main
from dampest_ros.io.bag import offered_qos
from dampest_ros.io.recorder import BagRecorder


@pytest.fixture(scope="session")
def sim_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """30 s of BlueROV2 Heavy, protocol B (IMU, DVL, pressure, thrusters, truth)."""
    out = tmp_path_factory.mktemp("faults") / "sim"
    assert main(["simulate", "--vehicle", "bluerov2_heavy", "--protocol", "B",
                 "--duration", "30", "--seed", "1", "--out", str(out)]) == 0
    return out


def std_string(text: str) -> bytes:
    """A std_msgs/msg/String message, CDR little endian with its encapsulation header."""
    data = text.encode() + b"\0"
    return b"\0\1\0\0" + struct.pack("<I", len(data)) + data


def copy_bag(src: Path, dst: Path, rename: Mapping[str, str] | None = None,
          strings: tuple[str, ...] = ()) -> Path:
    """Copy the messages of bag ``src`` to ``dst``, topic ``a`` recorded as ``rename[a]``
    (its type kept); each topic of ``strings`` is replaced by std_msgs/msg/String messages at
    the same log times."""
    with Reader(src) as reader, BagRecorder(dst) as rec:
        conns: dict[int, int] = {}
        for c in reader.connections:
            topic = (rename or {}).get(c.topic, c.topic)
            msgtype = "std_msgs/msg/String" if c.topic in strings else c.msgtype
            conns[c.id] = rec.add_connection(topic, msgtype, offered_qos(topic))
        for c, t, data in reader.messages():
            rec.write(conns[c.id], t, std_string(f"msg {t}") if c.topic in strings else data)
    return dst


@pytest.fixture
def rebag() -> Callable[..., Path]:
    """:func:`copy_bag` (test modules import no helpers under --import-mode=importlib)."""
    return copy_bag


@pytest.fixture
def string_cdr() -> Callable[[str], bytes]:
    """:func:`std_string`."""
    return std_string


@pytest.fixture
def context(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> Iterator[Any]:
    """An rclpy context of its own on the test module's ``DOMAIN`` (localhost only), so
    that suites of in-process nodes never hear each other."""
    rclpy = pytest.importorskip("rclpy")
    monkeypatch.setenv("ROS_DOMAIN_ID", request.module.DOMAIN)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)
