"""Conversions between rclpy and bag metadata for the recorder and replay nodes: QoS profiles
(rclpy ``QoSProfile`` ↔ rosbags ``Qos``, whose enums share the rmw values) and message classes
imported from type names."""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from typing import Any

from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)

from dampest_ros.io.bag_metadata import qos_time


def to_bag_qos(profile: QoSProfile) -> Qos:
    """The QoS a publisher offers (from ``get_publishers_info_by_topic``) as bag metadata."""

    def t(d: Duration) -> QosTime:
        return qos_time(d.nanoseconds)

    return Qos(QosHistory(int(profile.history)), int(profile.depth),
               QosReliability(int(profile.reliability)), QosDurability(int(profile.durability)),
               t(profile.deadline), t(profile.lifespan), QosLiveliness(int(profile.liveliness)),
               t(profile.liveliness_lease_duration),
               bool(profile.avoid_ros_namespace_conventions))


def compatible_qos(offered: Sequence[Any], depth: int, reliability: str = "auto") -> QoSProfile:
    """A QoS that receives from every one of the offered profiles (as rosbag2 adapts it).

    Reliable only when every publisher is reliable, transient local only when every one is;
    keep last ``depth``. ``offered`` holds rclpy ``QoSProfile`` or rosbags ``Qos`` items.
    ``reliability`` forces 'reliable' or 'best_effort' instead of 'auto'.
    """
    rel = [int(q.reliability.value if isinstance(q, Qos) else q.reliability) for q in offered]
    dur = [int(q.durability.value if isinstance(q, Qos) else q.durability) for q in offered]
    reliable = bool(rel) and all(r == ReliabilityPolicy.RELIABLE.value for r in rel)
    if reliability != "auto":
        reliable = reliability == "reliable"
    latched = bool(dur) and all(d == DurabilityPolicy.TRANSIENT_LOCAL.value for d in dur)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        liveliness=LivelinessPolicy.AUTOMATIC)


def import_message_type(msgtype: str) -> type[Any]:
    """The Python class of a ROS 2 message type such as ``sensor_msgs/msg/Imu``.

    Raises
    ------
    ImportError
        If the package or the type is not installed (or the name is malformed).
    """
    pkg, kind, name = [*msgtype.split("/"), "", "", ""][:3]
    if kind != "msg" or not pkg or not name:
        raise ImportError(f"not a message type name: {msgtype!r}")
    try:
        module = importlib.import_module(f"{pkg}.msg")
        cls = getattr(module, name)
    except (ImportError, AttributeError) as exc:
        raise ImportError(f"message type {msgtype} is not installed: {exc}") from None
    if not isinstance(cls, type):
        raise ImportError(f"{msgtype} is not a message class")
    return cls
