"""Nodes fed what a user might send them: a non-finite value on a subscribed topic is
rejected, counted on /diagnostics and logged once; the node keeps its state and runs on.

In-process nodes on ROS_DOMAIN_ID 83 (localhost only)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from geometry_msgs.msg import Twist, TwistWithCovarianceStamped, WrenchStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from dampest_ros.ros.common import ParamNode  # noqa: E402
from dampest_ros.ros.controller_node import ControllerNode  # noqa: E402
from dampest_ros.ros.sim_node import SimNode  # noqa: E402

DOMAIN = "83"  # this module's ROS domain (the context fixture)


def diagnostics(node: ParamNode) -> dict[str, str]:
    """The key/values of the node's next /diagnostics message."""
    sent: list[Any] = []
    node.rejected.pub.publish = sent.append  # type: ignore[attr-defined]
    node.rejected.publish()  # type: ignore[attr-defined]
    return {kv.key: kv.value for kv in sent[-1].status[0].values}


def test_sim_node_rejects_a_non_finite_cmd_wrench(context: Any) -> None:
    """Was: one WrenchStamped with a NaN force turned the simulated state NaN for good."""
    sim = SimNode(context=context, parameter_overrides=[Parameter("duration", value=10.0)])
    try:
        bad = WrenchStamped()
        bad.wrench.force.x = math.nan
        sim._on_wrench(bad)
        sim.live.advance(sim.live.t + 0.2)
        assert np.all(np.isfinite(sim.live.sim.nu)) and sim.live.external_steps == 0
        assert diagnostics(sim)["count.rejected_nonfinite_cmd_wrench"] == "1"
    finally:
        sim.destroy_node()


def test_controller_rejects_a_non_finite_reference_and_velocity(context: Any) -> None:
    """Was: a NaN on cmd_vel became the reference and a NaN on dampest/velocity entered the
    PI's integrator: every wrench published after either was NaN."""
    ctl = ControllerNode(context=context, parameter_overrides=[
        Parameter("feedforward", value=False)])
    sent: list[Any] = []
    ctl.pub.publish = sent.append  # type: ignore[method-assign,assignment]
    try:
        cmd = Twist()
        cmd.linear.x = math.inf
        ctl._on_cmd_vel(cmd)
        bad = TwistWithCovarianceStamped()
        bad.twist.twist.angular.z = math.nan
        ctl._on_velocity(bad)
        good = TwistWithCovarianceStamped()
        good.header.stamp.sec = 1
        ctl._on_velocity(good)
        assert len(sent) == 1 and ctl.commands == 1
        force, torque = sent[0].wrench.force, sent[0].wrench.torque
        assert all(math.isfinite(v) for v in (force.x, force.y, force.z,
                                              torque.x, torque.y, torque.z))
        counts = diagnostics(ctl)
        assert counts["count.rejected_nonfinite_cmd_vel"] == "1"
        assert counts["count.rejected_nonfinite_velocity"] == "1"
    finally:
        ctl.destroy_node()
