"""sim_node: the 6-DOF vehicle simulator with its sensors, in real time or faster.

Publishes truth/odom, imu/data, dvl/twist, pressure, thrusters/state (sensor-data QoS except
the truth; with backend:=mujoco also truth/hydro_wrench, MuJoCo's fluid wrench, FLU) and
/clock (simulation time) when publish_clock is true. Flies the excitation protocol with its
velocity controller unless cmd_wrench (geometry_msgs/WrenchStamped, FLU) commands arrive;
each command holds for cmd_timeout seconds of simulation time. Changing vehicle, protocol,
duration, seed, effects, sensors, backend or dt restarts the simulation (its clock starts
again at 0).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from geometry_msgs.msg import TwistWithCovarianceStamped, WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.clock import Clock, ClockType
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import FluidPressure, Imu, JointState

from dampest_ros.core.physics import frames
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.simulation.effects import Effects
from dampest_ros.core.simulation.excitation import LIVE_PROTOCOLS
from dampest_ros.core.simulation.sensors import SensorConfig
from dampest_ros.core.simulation.simulate import BACKENDS
from dampest_ros.core.simulation.stream import LiveSimulation
from dampest_ros.io.yaml_io import load_vehicle, read_mapping
from dampest_ros.ros.common import (
    RELIABLE_QOS,
    SENSOR_QOS,
    NonFiniteCounter,
    Param,
    ParamNode,
    main_for,
    to_time,
    vehicle_check,
)
from dampest_ros.ros.convert import publications, wrench6


def _mapping_ok(kind: type[Effects] | type[SensorConfig]) -> Callable[[Any], str | None]:
    def check(value: Any) -> str | None:
        if not str(value).strip():
            return None
        try:
            kind.from_dict(read_mapping(str(value)))
        except (ConfigError, TypeError, ValueError) as exc:
            return f"{kind.__name__}: {exc}"
        return None
    return check


class SimNode(ParamNode):
    """Simulator node (see the module docstring)."""

    NODE_NAME = "sim_node"
    PARAMS = (
        Param("vehicle", "bluerov2_heavy", "vehicle preset name or YAML path",
              check=vehicle_check),
        Param("protocol", "B", "excitation protocol flown without cmd_wrench (optimal: "
              "Fourier-series references optimised for the damping regressor's condition "
              "number within the speed and thrust limits, designed at start in ~30 s)",
              choices=LIVE_PROTOCOLS),
        Param("duration", 300.0, "length of the protocol in s; the simulation stops after it",
              low=1.0, high=1e6),
        Param("seed", 1, "random seed of the protocol and the sensor noise", low=0,
              high=2**31 - 1),
        Param("rate_factor", 1.0, "simulated seconds per wall-clock second (1: real time)",
              low=0.01, high=1000.0),
        Param("effects", "", "YAML mapping of hidden effects (dampest_ros.core.simulation.effects."
              "Effects), e.g. '{damping_change_time: 200, damping_change_factor: 1.3}'",
              check=_mapping_ok(Effects)),
        Param("sensors", "", "YAML mapping of sensor settings (dampest_ros.core.simulation.sensors."
              "SensorConfig), e.g. '{dvl_rate: 5}'", check=_mapping_ok(SensorConfig)),
        Param("dt", 0.02, "integration step in s", low=0.001, high=0.1),
        Param("backend", "native", "the plant: native (our equations) or mujoco (MuJoCo's "
              "ellipsoid fluid model; the vehicle needs a geometry: block)",
              choices=BACKENDS),
        Param("publish_clock", True, "publish /clock with the simulation time"),
        Param("cmd_timeout", 0.5, "s of simulation time a cmd_wrench stays in force",
              low=0.0, high=10.0),
        Param("tick", 0.02, "wall-clock period of the simulation loop in s", low=0.001,
              high=1.0),
        Param("max_lag", 0.5, "largest simulated time in s flown in one tick (when the "
              "computer cannot keep up, the simulation slows down instead)", low=0.01,
              high=10.0),
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.NODE_NAME, self.PARAMS, **kwargs)
        self.pub = {
            "imu/data": self.create_publisher(Imu, "imu/data", SENSOR_QOS),
            "dvl/twist": self.create_publisher(TwistWithCovarianceStamped, "dvl/twist",
                                               SENSOR_QOS),
            "pressure": self.create_publisher(FluidPressure, "pressure", SENSOR_QOS),
            "thrusters/state": self.create_publisher(JointState, "thrusters/state",
                                                     SENSOR_QOS),
            "truth/odom": self.create_publisher(Odometry, "truth/odom", RELIABLE_QOS),
            # the plant's own fluid wrench (mujoco backend only), for evaluation
            "truth/hydro_wrench": self.create_publisher(WrenchStamped, "truth/hydro_wrench",
                                                        RELIABLE_QOS),
        }
        self.clock_pub = self.create_publisher(ClockMsg, "/clock", 10)
        self.create_subscription(WrenchStamped, "cmd_wrench", self._on_wrench, RELIABLE_QOS)
        self.rejected = NonFiniteCounter(self, "simulation", ["rejected_nonfinite_cmd_wrench"])
        self.published = 0
        #: messages published per topic (since the node started)
        self.counts = dict.fromkeys(self.pub, 0)
        self._start()
        # the loop runs on the wall clock even when this node uses sim time
        self._timer = self.create_timer(self.p("tick"), self._tick,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _start(self) -> None:
        effects = Effects.from_dict(read_mapping(self.p("effects"))) \
            if str(self.p("effects")).strip() else Effects()
        sensors = SensorConfig.from_dict(read_mapping(self.p("sensors"))) \
            if str(self.p("sensors")).strip() else SensorConfig()
        if self.p("protocol") == "optimal":  # the node publishes nothing meanwhile: say so
            self.get_logger().info(f"designing protocol optimal for {self.p('vehicle')} "
                                   "(about 30 s; protocol B starts at once)")
        self.live = LiveSimulation(load_vehicle(self.p("vehicle")), self.p("protocol"),
                                   self.p("duration"), self.p("seed"), effects, sensors,
                                   self.p("dt"), self.p("backend"))
        self._wall0 = time.monotonic()
        self._sim0 = self.live.t
        self._rate = float(self.p("rate_factor"))
        self._finished_logged = False
        design = self.live.excitation.design
        if design is not None:
            self.get_logger().info(
                f"designed protocol {self.p('protocol')}: damping regressor condition number "
                f"{design.cond:.3g} (random Fourier series within the same limits: median "
                f"{design.cond_random:.3g}, {design.cond_random / design.cond:.1f}x higher)")
        self.get_logger().info(
            f"simulating {self.live.vehicle.name}, protocol {self.p('protocol')} for "
            f"{self.p('duration'):.0f} s at {self._rate:g}x real time"
            + (f", effects {effects.as_dict()}" if effects.as_dict() else ""))

    def on_parameters(self, names: list[str]) -> None:
        if "rate_factor" in names:
            # keep the simulated time continuous, change the pace from now on
            self._sim0, self._wall0 = self.live.t, time.monotonic()
            self._rate = float(self.p("rate_factor"))
        if "tick" in names:
            self._timer.cancel()
            self._timer = self.create_timer(self.p("tick"), self._tick,
                                            clock=Clock(clock_type=ClockType.STEADY_TIME))
        if set(names) & {"vehicle", "protocol", "duration", "seed", "effects", "sensors",
                         "backend", "dt"}:
            self._start()

    def _on_wrench(self, msg: WrenchStamped) -> None:
        wrench = wrench6(msg)
        if not self.rejected.finite("rejected_nonfinite_cmd_wrench", wrench, "cmd_wrench"):
            return
        # FLU → FRD through the core's frame conversion
        self.live.command(frames.body_twist(wrench), float(self.p("cmd_timeout")))

    def _tick(self) -> None:
        live = self.live
        if live.done:
            if not self._finished_logged:
                self.get_logger().info(f"protocol finished at t = {live.t:.1f} s")
                self._finished_logged = True
            return
        target = self._sim0 + (time.monotonic() - self._wall0) * self._rate
        if target - live.t > self.p("max_lag"):
            # cannot keep up: fly at most max_lag now and slow the pace down
            target = live.t + self.p("max_lag")
            self._sim0, self._wall0 = target, time.monotonic()
        n = 0
        for name, m in publications(live.advance(target)):
            self.pub[name].publish(m)
            self.counts[name] += 1
            n += 1
        self.published += n
        if self.p("publish_clock") and n:
            self.clock_pub.publish(ClockMsg(clock=to_time(live.t)))


main = main_for(SimNode, __doc__ or "")

if __name__ == "__main__":
    main()
