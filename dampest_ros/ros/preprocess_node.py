"""preprocess_node: causal fusion of IMU, DVL, pressure and thruster states into samples.

Subscribes imu/data, dvl/twist, pressure, thrusters/state (sensor-data QoS) or, with the
parameter wrench_topic (read at start), a body wrench (geometry_msgs/WrenchStamped, FLU) on
that topic instead of thrusters/state (the vehicle then needs no thrusters); publishes
dampest/velocity (TwistWithCovarianceStamped), dampest/acceleration
(AccelWithCovarianceStamped), dampest/wrench (WrenchStamped) and dampest/attitude
(QuaternionStamped, base_link FLU → odom ENU, for the restoring forces) with identical header
stamps at a fixed rate, body frame FLU (base_link), only for usable samples (not during DVL
dropouts); diagnostics with the message counts, rejections and resets once per second (wall
clock), WARN with what is wrong when a rejection or reset was counted or when one sensor has
sent nothing for 5 s while the others arrive (a wrong topic name, a sensor down). The counts
are the node's life totals: a parameter change that rebuilds the preprocessing keeps them,
and first passes on what the stamp order holds.
The DVL may send geometry_msgs/TwistStamped instead (parameter dvl_type, read at start).
Sensor mounting (lever arms, rotations) and the expected frame_ids come from the vehicle
file's sensors: section; messages with another header.frame_id are counted
(frame_id_mismatch in the diagnostics) and warned about once per topic. Messages refused
(non-finite or implausible values, malformed thruster states, header.stamp 0) are counted
in the diagnostics (rejected_*) and the first of each kind is logged; the node runs on.
The work is done by dampest_ros.core.online.preprocessor.OnlinePreprocessor (the same class
replays bags).
The sensor messages reach it in stamp order whatever the order of their arrival
(dampest_ros.core.signals.reorder.StampOrder, up to reorder_latency of stamp time; what is held is
released when no message has come for half a second of wall-clock time, also when use_sim_time
and /clock has stopped at the end of a replayed bag), so that live data, a replayed bag and
'dampest identify --method rls' give the same samples.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import (
    AccelWithCovarianceStamped,
    QuaternionStamped,
    TwistStamped,
    TwistWithCovarianceStamped,
    WrenchStamped,
)
from rclpy.clock import Clock, ClockType
from sensor_msgs.msg import FluidPressure, Imu, JointState

from dampest_ros.core.online.estimator import attitude_quaternion
from dampest_ros.core.online.preprocessor import OnlinePreprocessor
from dampest_ros.core.online.sample import OnlineConfig, OnlineSample, topic_roles
from dampest_ros.core.physics import frames
from dampest_ros.core.signals.reorder import StampOrder
from dampest_ros.io.yaml_io import load_vehicle
from dampest_ros.ros.common import (
    DIAGNOSTICS_TOPIC,
    RELIABLE_QOS,
    SENSOR_QOS,
    LifeCounts,
    Param,
    ParamNode,
    QuietFlush,
    diagnostic_array,
    main_for,
    seconds,
    stamp_ns,
    to_time,
    vehicle_check,
)
from dampest_ros.ros.convert import header_frame_id, stamped_floats

#: The diagnostics counts that raise the status to WARN.
PROBLEMS = ("rejected_nonfinite", "rejected_implausible", "rejected_malformed",
            "rejected_unstamped", "rejected_stale", "clock_resets")

#: Seconds (diagnostics periods) a sensor may stay silent while the others arrive before the
#: status says so (WARN): without it no sample is usable, which the counts alone do not say.
SILENT_AFTER = 5


class SampleMessages:
    """The four dampest/* messages of a sample: velocity, acceleration and wrench (FLU, in
    the given frame) and the attitude (base_link FLU → odom ENU), all with the sample's stamp.

    One object per message, filled sample after sample (building new messages costs several
    times more): the messages of a sample are valid until the next :meth:`fill`; publish them
    at once (rclpy serialises on publish).
    """

    def __init__(self) -> None:
        self.v = TwistWithCovarianceStamped()
        self.a = AccelWithCovarianceStamped()
        self.w = WrenchStamped()
        self.q = QuaternionStamped()
        self.q.header.frame_id = "odom"
        self._vectors = (self.v.twist.twist.linear, self.v.twist.twist.angular,
                         self.a.accel.accel.linear, self.a.accel.accel.angular,
                         self.w.wrench.force, self.w.wrench.torque)

    def fill(self, s: OnlineSample, frame_id: str) -> tuple[
            TwistWithCovarianceStamped, AccelWithCovarianceStamped, WrenchStamped,
            QuaternionStamped]:
        """The messages of sample ``s`` (FRD, SI); ``frame_id`` of the first three."""
        # FRD → FLU through the core's frame conversion
        values = frames.body_twist(np.stack([s.nu, s.nu_dot, s.tau])).reshape(6, 3).tolist()
        for vec, (x, y, z) in zip(self._vectors, values, strict=True):
            vec.x, vec.y, vec.z = x, y, z
        # attitude FRD → NED (Euler) to the ROS quaternion FLU → ENU
        o = self.q.quaternion
        o.x, o.y, o.z, o.w = attitude_quaternion(s.euler).tolist()
        stamp = to_time(s.t)
        for m in (self.v, self.a, self.w):
            m.header.stamp = stamp
            m.header.frame_id = frame_id
        self.q.header.stamp = stamp
        return self.v, self.a, self.w, self.q


class PreprocessNode(ParamNode):
    """Preprocessing node (see the module docstring)."""

    NODE_NAME = "preprocess_node"
    PARAMS = (
        Param("vehicle", "bluerov2_heavy", "vehicle preset (thruster allocation, g, ρ)",
              check=vehicle_check),
        Param("rate", 50.0, "output sample rate in Hz", low=1.0, high=500.0),
        Param("max_dvl_gap", 1.0, "samples more than this (s) after the last DVL fix are "
              "not published", low=0.05, high=60.0),
        Param("settle", 1.0, "s after a (re)start or a DVL recovery before samples are "
              "published", low=0.0, high=60.0),
        Param("stale_after", 1.0, "messages older than this (s) behind the newest are "
              "rejected", low=0.01, high=60.0),
        Param("clock_jump", 1.0, "a stamp this far (s) behind its topic's last one is a "
              "clock jump: reset", low=0.01, high=3600.0),
        Param("reorder_latency", 5.0, "s of stamp time a sensor message may arrive after a "
              "newer one of another topic and still be put in stamp order (later: counted as "
              "late); a topic gone quiet holds the others up this long", low=0.0, high=60.0),
        Param("frame_id", "base_link", "frame_id of the published samples"),
        Param("dvl_type", "TwistWithCovarianceStamped", "message type on dvl/twist "
              "(geometry_msgs); read at start", choices=("TwistWithCovarianceStamped",
                                                         "TwistStamped"), read_only=True),
        Param("wrench_topic", "", "topic of a body wrench τ (geometry_msgs/WrenchStamped, "
              "FLU) read instead of thrusters/state ('': τ from thrusters/state through the "
              "vehicle's allocation); read at start", read_only=True),
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.NODE_NAME, self.PARAMS, **kwargs)
        self.pub_v = self.create_publisher(TwistWithCovarianceStamped, "dampest/velocity",
                                           RELIABLE_QOS)
        self.pub_a = self.create_publisher(AccelWithCovarianceStamped, "dampest/acceleration",
                                           RELIABLE_QOS)
        self.pub_w = self.create_publisher(WrenchStamped, "dampest/wrench", RELIABLE_QOS)
        self.pub_q = self.create_publisher(QuaternionStamped, "dampest/attitude", RELIABLE_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC,
                                             RELIABLE_QOS)
        self.messages = SampleMessages()
        self.life_counts = LifeCounts(self._counts)  # kept across rebuilds
        self._build()
        # raw: stamps and values read from the CDR bytes (the joint names need rclpy's)
        self.create_subscription(Imu, "imu/data", self._on_imu, SENSOR_QOS, raw=True)
        if self.p("dvl_type") == "TwistStamped":
            self.create_subscription(TwistStamped, "dvl/twist", self._on_dvl_twist,
                                     SENSOR_QOS, raw=True)
        else:
            self.create_subscription(TwistWithCovarianceStamped, "dvl/twist", self._on_dvl,
                                     SENSOR_QOS, raw=True)
        self.create_subscription(FluidPressure, "pressure", self._on_pressure, SENSOR_QOS,
                                 raw=True)
        wrench = str(self.p("wrench_topic")).strip()
        if wrench:
            self.create_subscription(WrenchStamped, wrench, self._on_wrench, SENSOR_QOS,
                                     raw=True)
        else:
            self.create_subscription(JointState, "thrusters/state", self._on_thrusters,
                                     SENSOR_QOS)
        # wall clock: with use_sim_time the node clock stops with /clock (a replay's end)
        self.create_timer(1.0, self._publish_diagnostics,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.quiet = QuietFlush(self, self._flush)
        self.published = 0
        self.unstamped = 0  # messages with header.stamp 0, rejected
        self._arrived: dict[str, int] = {}  # per role, messages arrived
        self._heard: dict[str, int] = {}  # per role, the arrivals at the last diagnostics
        self._silent: dict[str, int] = {}  # per role, periods without a message

    def _build(self) -> None:
        v = load_vehicle(self.p("vehicle"))
        cfg = OnlineConfig(rate=self.p("rate"), max_dvl_gap=self.p("max_dvl_gap"),
                           settle=self.p("settle"), stale_after=self.p("stale_after"),
                           clock_jump=self.p("clock_jump"))
        wrench = bool(str(self.p("wrench_topic")).strip())
        if not wrench:
            v.need_thrusters("preprocess_node (τ from thrusters/state)",
                             "set the parameter wrench_topic (a body wrench)")
        self.pre = OnlinePreprocessor(v.thrusters, v.body.gravity, v.body.rho, cfg,
                                      mounting=v.mounting)
        self.order = StampOrder(topic_roles(wrench), self.p("reorder_latency"),
                                self.p("clock_jump"))

    def _counts(self) -> dict[str, int]:
        """The counters the preprocessor and the stamp order keep (a rebuild zeroes them)."""
        return {**self.pre.counts, "late": self.order.counts["late"]}

    def on_parameters(self, names: list[str]) -> None:
        if set(names) - {"frame_id"}:
            self._flush()  # what the stamp order holds goes through the settings it came under
            self.life_counts.restart(self._build)
            self.get_logger().info(f"preprocessing restarted ({', '.join(names)} changed)")

    # --- subscriptions: convert, call core, publish -------------------------------------------

    def _on_imu(self, data: bytes) -> None:
        # orientation, its covariance, angular velocity, its covariance, linear acceleration
        ns, v = stamped_floats(data, 28)
        self._feed("imu", ns, (v[0:4], v[13:16], v[25:28], header_frame_id(data)))

    def _on_dvl(self, data: bytes) -> None:
        ns, v = stamped_floats(data, 42)  # twist (linear, angular), covariance (36)
        self._feed("dvl", ns, (v[0:3], v[6:42], header_frame_id(data)))

    def _on_dvl_twist(self, data: bytes) -> None:
        ns, v = stamped_floats(data, 6)  # TwistStamped: linear, angular; no covariance
        self._feed("dvl", ns, (v[0:3], None, header_frame_id(data)))

    def _on_pressure(self, data: bytes) -> None:
        ns, v = stamped_floats(data, 1)
        self._feed("pressure", ns, (float(v[0]), header_frame_id(data)))

    def _on_thrusters(self, m: JointState) -> None:
        self._feed("thrusters", stamp_ns(m.header.stamp), (tuple(m.name),
                                                           np.asarray(m.effort, dtype=float)))

    def _on_wrench(self, data: bytes) -> None:
        ns, v = stamped_floats(data, 6)  # force, torque
        self._feed("wrench", ns, (v[0:3], v[3:6]))

    def _feed(self, role: str, stamp: int, args: tuple[Any, ...]) -> None:
        """Through the stamp-order stage to the preprocessor method of the role. A message
        stamped 0 once stamps past clock_jump have come (a header never set; a simulator
        starts at 0) is rejected before it, as it would be a clock jump that resets the
        state (a restarted clock's next message still is one)."""
        self.quiet.arrived()
        self._arrived[role] = self._arrived.get(role, 0) + 1
        if stamp == 0 and self.order.newest > self.p("clock_jump"):
            self.unstamped += 1
            if self.unstamped == 1:
                self.get_logger().error(
                    f"{role}: a message with header.stamp 0 rejected (counted as "
                    "rejected_unstamped, reported once); its publisher must stamp it")
            return
        self._process(self.order.push(role, seconds(stamp), args))

    def _process(self, released: list[tuple[str, float, Any]]) -> None:
        samples: list[OnlineSample] = []
        for role, t, args in released:
            samples += getattr(self.pre, role)(t, *args)
        self._publish(samples)

    def _flush(self) -> None:
        """Process what the stamp order holds (the input has gone quiet, or a rebuild is
        due)."""
        if len(self.order):
            self._process(self.order.flush())

    def _publish(self, samples: list[OnlineSample]) -> None:
        frame = self.p("frame_id") if samples else ""
        for s in samples:
            if not s.usable:
                continue
            mv, ma, mw, mq = self.messages.fill(s, frame)
            self.pub_v.publish(mv)
            self.pub_a.publish(ma)
            self.pub_w.publish(mw)
            self.pub_q.publish(mq)
            self.published += 1
        while self.pre.events:
            self.get_logger().warning(self.pre.events.popleft())

    def _publish_diagnostics(self) -> None:
        c: dict[str, float] = dict(self.life_counts(self._counts()))  # life totals
        c["published"] = self.published
        c["rejected_unstamped"] = self.unstamped
        c["max_lag_s"] = self.order.max_lag
        c["derivative_lag_s"] = self.pre.derivative_lag
        problems = sum(int(c[k]) for k in PROBLEMS)
        said = [f"{problems} rejected or reset"] if problems else []
        said += [f"no {role} message for {n} s while the others arrive"
                 for role, n in self._silences().items() if n >= SILENT_AFTER]
        self.pub_diag.publish(diagnostic_array(
            self, "preprocessing", c, level=1 if said else 0,
            message="; ".join(said) if said else "ok"))

    def _silences(self) -> dict[str, int]:
        """Per sensor role, for how many diagnostics periods no message of it has arrived
        while others have (0 when one arrived or nothing arrived at all)."""
        roles = topic_roles(bool(str(self.p("wrench_topic")).strip()))  # the expected ones
        now = {r: self._arrived.get(r, 0) for r in roles}
        before, self._heard = self._heard, now
        grew = {r: n > before.get(r, 0) for r, n in now.items()}
        self._silent = {r: 0 if grew[r] or not any(grew.values()) else
                        self._silent.get(r, 0) + 1 for r in now}
        return self._silent


main = main_for(PreprocessNode, __doc__ or "")

if __name__ == "__main__":
    main()
