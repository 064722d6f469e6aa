"""Reading stamps and values from serialized dampest/* messages (dampest_ros.ros.convert)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rclpy")

from builtin_interfaces.msg import Time
from geometry_msgs.msg import (
    AccelWithCovarianceStamped,
    QuaternionStamped,
    TwistWithCovarianceStamped,
    WrenchStamped,
)
from rclpy.serialization import serialize_message

from dampest_ros.ros.convert import stamped_floats


@pytest.mark.parametrize("frame_id", ["", "a", "base_link", "odom_1234", "x" * 17])
def test_stamped_floats_reads_what_rclpy_serialised(frame_id: str) -> None:
    """Every frame_id length (alignment of the doubles after the string) and each type."""
    rng = np.random.default_rng(len(frame_id))
    v = rng.normal(size=6)
    stamp = Time(sec=1_700_000_123, nanosec=987_654_321)
    tw = TwistWithCovarianceStamped()
    tw.twist.twist.linear.x, tw.twist.twist.linear.y, tw.twist.twist.linear.z = v[:3]
    tw.twist.twist.angular.x, tw.twist.twist.angular.y, tw.twist.twist.angular.z = v[3:]
    tw.twist.covariance = rng.normal(size=36)
    ac = AccelWithCovarianceStamped()
    ac.accel.accel.linear.x, ac.accel.accel.linear.y, ac.accel.accel.linear.z = v[:3]
    ac.accel.accel.angular.x, ac.accel.accel.angular.y, ac.accel.accel.angular.z = v[3:]
    wr = WrenchStamped()
    wr.wrench.force.x, wr.wrench.force.y, wr.wrench.force.z = v[:3]
    wr.wrench.torque.x, wr.wrench.torque.y, wr.wrench.torque.z = v[3:]
    q = QuaternionStamped()
    q.quaternion.x, q.quaternion.y, q.quaternion.z, q.quaternion.w = v[:4]
    for m, want in ((tw, v), (ac, v), (wr, v), (q, v[:4])):
        m.header.stamp, m.header.frame_id = stamp, frame_id
        ns, values = stamped_floats(serialize_message(m), len(want))
        assert ns == 1_700_000_123_987_654_321
        np.testing.assert_array_equal(values, want)


def test_stamped_floats_rejects_what_it_cannot_read() -> None:
    data = serialize_message(QuaternionStamped())
    with pytest.raises(ValueError, match="too short"):
        stamped_floats(data, 5)
    with pytest.raises(ValueError, match="not plain CDR"):
        stamped_floats(b"\x00\x07" + data[2:], 4)
