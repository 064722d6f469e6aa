"""controller_node: an example velocity controller that uses the identified damping model.

Per-DOF PI on the body velocity (dampest/velocity, FLU) plus the model feed-forward
D(ν)ν + C(ν)ν evaluated at the reference, with the model read through dampest_ros.client
(model.* of model_node with get_parameters, refreshed on /parameter_events). Publishes
cmd_wrench (geometry_msgs/WrenchStamped, FLU) at every velocity sample. The reference is the
reference parameter (6 numbers, FLU: u, v, w, p, q, r) or the latest cmd_vel
(geometry_msgs/Twist, FLU).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from geometry_msgs.msg import Twist, TwistWithCovarianceStamped, WrenchStamped

from dampest_ros.client import ModelClient
from dampest_ros.core.physics import frames
from dampest_ros.core.simulation.control import DEFAULT_BANDWIDTH, VelocityPI
from dampest_ros.io.yaml_io import load_vehicle
from dampest_ros.ros.common import (
    RELIABLE_QOS,
    NonFiniteCounter,
    Param,
    ParamNode,
    main_for,
    seconds,
    vehicle_check,
)
from dampest_ros.ros.convert import twist6, wrench_msg, xyz


def _six(value: Any) -> str | None:
    v = list(value)
    if len(v) != 6 or not all(np.isfinite(v)):
        return f"reference needs 6 finite numbers (u, v, w, p, q, r), got {v}"
    return None


class ControllerNode(ParamNode):
    """Controller node (see the module docstring)."""

    NODE_NAME = "controller_node"
    PARAMS = (
        Param("vehicle", "bluerov2_heavy", "vehicle preset: M (gain scaling) and thrust "
              "limits", check=vehicle_check),
        Param("model_node", "estimator_node", "node that holds model.* (estimator_node or "
              "model_server_node)"),
        Param("feedforward", True, "add the model feed-forward D(ν)ν + C(ν)ν"),
        Param("bandwidth", DEFAULT_BANDWIDTH, "closed-loop bandwidth of the PI in rad/s", low=0.01,
              high=50.0),
        Param("reference", [0.0] * 6, "velocity reference, body FLU (m/s, rad/s), used until "
              "cmd_vel arrives", check=_six),
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.NODE_NAME, self.PARAMS, **kwargs)
        self.vehicle = load_vehicle(self.p("vehicle"))
        self.client = ModelClient(self, self.p("model_node"), on_update=self._on_model,
                                  vehicle=self.vehicle.identity)
        self._build()
        self.ref = frames.body_twist(np.array(self.p("reference"), dtype=float))
        self.pub = self.create_publisher(WrenchStamped, "cmd_wrench", RELIABLE_QOS)
        self.create_subscription(TwistWithCovarianceStamped, "dampest/velocity",
                                 self._on_velocity, RELIABLE_QOS)
        self.create_subscription(Twist, "cmd_vel", self._on_cmd_vel, RELIABLE_QOS)
        self.rejected = NonFiniteCounter(self, "velocity control", [
            "rejected_nonfinite_cmd_vel", "rejected_nonfinite_velocity"])
        self._t_prev: float | None = None
        self.commands = 0

    def _on_model(self, m: Any) -> None:
        # the estimator publishes about once a second: only the first model is news
        log = self.get_logger()
        (log.info if self.client.refreshes == 1 else log.debug)(f"model version {m.version}")

    def _build(self) -> None:
        self.pi = VelocityPI.for_vehicle(self.vehicle, self.p("bandwidth"), self._feedforward)

    def _feedforward(self, nu_ref: np.ndarray) -> np.ndarray:
        if not self.p("feedforward") or not self.client.available:
            return np.zeros(6)
        return self.client.feedforward(nu_ref)

    def on_parameters(self, names: list[str]) -> None:
        if "reference" in names:
            self.ref = frames.body_twist(np.array(self.p("reference"), dtype=float))
        if "vehicle" in names:
            self.vehicle = load_vehicle(self.p("vehicle"))
            self.client.vehicle = self.vehicle.identity
        if {"vehicle", "bandwidth"} & set(names):
            self._build()

    def _on_cmd_vel(self, m: Twist) -> None:
        ref = np.concatenate([xyz(m.linear), xyz(m.angular)])
        if self.rejected.finite("rejected_nonfinite_cmd_vel", ref, "cmd_vel"):
            self.ref = frames.body_twist(ref)

    def _on_velocity(self, m: TwistWithCovarianceStamped) -> None:
        flu = twist6(m)
        if not self.rejected.finite("rejected_nonfinite_velocity", flu, "dampest/velocity"):
            return
        t = seconds(m.header.stamp)
        dt = 0.02 if self._t_prev is None else min(max(t - self._t_prev, 1e-3), 0.2)
        self._t_prev = t
        nu = frames.body_twist(flu)  # FLU → FRD
        tau = self.pi(self.ref, nu, dt)
        out = wrench_msg(frames.body_twist(tau))  # FRD → FLU
        out.header.stamp = m.header.stamp
        out.header.frame_id = m.header.frame_id
        self.pub.publish(out)
        self.commands += 1


main = main_for(ControllerNode, __doc__ or "")

if __name__ == "__main__":
    main()
