"""arm_feedforward_node: an example arm controller part that uses the identified arm model.

Subscribes joint_reference (sensor_msgs/JointState: the desired position and velocity of each
of the arm's joints, in any order, matched by name; effort is not used; the stamps must
increase). trajectory_msgs is not among the pinned message packages, so the desired
acceleration is the backward difference of the desired velocities of two consecutive messages
over their stamps; the first message (and one after a refusal) only starts the difference.
Publishes effort_feedforward (std_msgs/Float64MultiArray, what ros2_control's effort forward
controller takes on <controller>/commands): the joint torques τ = Y_b(q, q̇, q̈) θ in N m, in
the model's joint order (model.joint_names), with the model read through
dampest_ros.client.ArmModelClient from model_node (model_server_node serving an arm model
file, or arm_estimator_node), refreshed on /parameter_events. Until a model has come, or
while its server is lost, it publishes nothing and logs why once. Refused messages are counted
on /diagnostics (count.rejected_joints_joint_reference: a joint of the arm missing or a joint
it does not have, one line naming them; rejected_fields_joint_reference: position or velocity
not one per name; rejected_stamp_joint_reference: a stamp not after the previous one;
rejected_nonfinite_joint_reference).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from dampest_ros.client import ArmModelClient
from dampest_ros.io.arm import joint_list, load_arm
from dampest_ros.ros.common import (
    RELIABLE_QOS,
    NonFiniteCounter,
    Param,
    ParamNode,
    arm_problem,
    main_for,
    seconds,
)
from dampest_ros.ros.convert import joint_columns

TOPIC = "joint_reference"


class ArmFeedforwardNode(ParamNode):
    """Arm feed-forward node (see the module docstring)."""

    NODE_NAME = "arm_feedforward_node"
    PARAMS = (
        Param("arm", "ur5", "arm preset or URDF path the model was identified for (as "
              "arm_estimator_node's arm): joint names and kinematics; read at start",
              read_only=True),
        Param("lock", "", "joints held fixed at 0, comma separated, as arm_estimator_node's "
              "lock ('': none); read at start", read_only=True),
        Param("model_node", "model_server_node", "node that holds the arm's model.* "
              "(model_server_node or arm_estimator_node); read at start", read_only=True),
        Param("timeout", 5.0, "seconds model_node may be missing from the graph before the "
              "model counts as lost (nothing is published then); read at start",
              low=0.1, high=60.0, read_only=True),
        Param("offsets", False, "add the model's torque offsets (<joint>.off: the measured "
              "effort's bias, which a motor need not produce)"),
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.NODE_NAME, self.PARAMS, **kwargs)
        reason = arm_problem(self.p("arm"), self.p("lock"))
        if reason is not None:
            raise ValueError(f"parameter {reason}")
        arm = load_arm(self.p("arm"), lock=joint_list(self.p("lock")))
        self.names = tuple(arm.model.names)
        self.client = ArmModelClient(self, self.p("model_node"), on_update=self._on_model,
                                     timeout=self.p("timeout"), arm=arm)
        self.pub = self.create_publisher(Float64MultiArray, "effort_feedforward",
                                         RELIABLE_QOS)
        self.create_subscription(JointState, TOPIC, self._on_reference, RELIABLE_QOS)
        self.rejected = NonFiniteCounter(self, "arm feed-forward", [
            f"rejected_{what}_{TOPIC}" for what in ("joints", "fields", "stamp", "nonfinite")])
        self._order: dict[tuple[str, ...], np.ndarray | str] = {}  # or why refused
        self._previous: tuple[float, np.ndarray] | None = None  # stamp and q̇ of the last
        self._told = False  # why nothing is published has been logged since the last command
        self.commands = 0

    def _on_model(self, m: Any) -> None:
        log = self.get_logger()
        (log.info if self.client.refreshes == 1 else log.debug)(f"arm model version {m.version}")

    def _columns(self, names: tuple[str, ...]) -> np.ndarray | None:
        """Where the model's joints are in a message naming ``names`` (None: a joint missing,
        unknown or named twice; counted, and the first such message is logged)."""
        if names not in self._order:
            columns, missing = joint_columns(self.names, names)
            unknown = sorted({n for n in names if n not in self.names})
            if columns is None or unknown or len(set(names)) < len(names):
                self._order[names] = (
                    f"{TOPIC}: a message naming joints {list(names)} rejected (missing "
                    f"{missing}, unknown {unknown}); name each joint of the arm "
                    f"{list(self.names)} once")
            else:
                self._order[names] = columns
        order = self._order[names]
        if isinstance(order, str):
            self.rejected.reject(f"rejected_joints_{TOPIC}", order)
            return None
        return order

    def _state(self, m: JointState) -> tuple[float, np.ndarray, np.ndarray] | None:
        """Stamp, q and q̇ of a message in the model's joint order (None: refused)."""
        order = self._columns(tuple(m.name))
        if order is None:
            return None
        n = len(m.name)
        if len(m.position) != n or len(m.velocity) != n:
            self.rejected.reject(f"rejected_fields_{TOPIC}", (
                f"{TOPIC}: a message with {len(m.position)} positions and {len(m.velocity)} "
                f"velocities for {n} joints rejected; give both for every joint"))
            return None
        q, qd = np.asarray(m.position)[order], np.asarray(m.velocity)[order]
        if not self.rejected.finite(f"rejected_nonfinite_{TOPIC}", [*q, *qd], TOPIC):
            return None
        return seconds(m.header.stamp), q, qd

    def _acceleration(self, t: float, qd: np.ndarray) -> np.ndarray | None:
        """q̈ as the backward difference of q̇ to the previous message (None: none yet, or a
        stamp not after it, which is counted)."""
        previous, self._previous = self._previous, (t, qd)
        if previous is None:
            return None
        dt = t - previous[0]
        if not dt > 0.0:
            self.rejected.reject(f"rejected_stamp_{TOPIC}", (
                f"{TOPIC}: a message stamped {t:.9f} s, not after the previous one "
                f"({previous[0]:.9f} s), rejected; stamp each reference with its time"))
            self._previous = None
            return None
        return (qd - previous[1]) / dt

    def _on_reference(self, m: JointState) -> None:
        state = self._state(m)
        if state is None:
            self._previous = None
            return
        t, q, qd = state
        qdd = self._acceleration(t, qd)
        if qdd is None:
            return
        if not self.client.available:
            if not self._told:
                self._told = True
                why = (f"model server {self.client.server} lost: not in the graph for "
                       f"{self.client.timeout:g} s; publishing resumes when it is back"
                       if self.client.lost else self.client.why(probe=False))
                self.get_logger().warning(f"no arm model, publishing nothing: {why}")
            return
        tau = self.client.feedforward(q, qd, qdd, offsets=self.p("offsets"))
        self.pub.publish(Float64MultiArray(data=tau.tolist()))
        self.commands += 1
        self._told = False  # a model lost later is told again


main = main_for(ArmFeedforwardNode, __doc__ or "")

if __name__ == "__main__":
    main()
