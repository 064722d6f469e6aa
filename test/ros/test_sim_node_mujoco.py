"""sim_node with backend:=mujoco: the same sensor topics, and MuJoCo's own fluid wrench on
truth/hydro_wrench equal to the offline simulation of the same protocol and seed."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("mujoco")

from geometry_msgs.msg import WrenchStamped  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

from dampest_ros.core.physics.frames import body_twist  # noqa: E402
from dampest_ros.core.simulation.excitation import make_excitation  # noqa: E402
from dampest_ros.core.simulation.simulate import run  # noqa: E402
from dampest_ros.io.yaml_io import load_vehicle  # noqa: E402
from dampest_ros.ros.common import RELIABLE_QOS, SENSOR_QOS  # noqa: E402
from dampest_ros.ros.sim_node import SimNode  # noqa: E402

SECONDS = 6.0


def test_mujoco_backend_publishes_sensors_and_the_true_fluid_wrench() -> None:
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", "77")
    context = rclpy.Context()
    rclpy.init(context=context)
    sim = SimNode(context=context, parameter_overrides=[
        Parameter("backend", value="mujoco"), Parameter("vehicle", value="torpedo_auv"),
        Parameter("rate_factor", value=10.0), Parameter("duration", value=SECONDS),
        Parameter("seed", value=3)])
    probe = rclpy.create_node("probe_mj", context=context)
    hydro: list[tuple[float, np.ndarray]] = []
    imu: list[Imu] = []

    def on_hydro(m: WrenchStamped) -> None:
        f, t = m.wrench.force, m.wrench.torque
        hydro.append((m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
                      np.array([f.x, f.y, f.z, t.x, t.y, t.z])))

    probe.create_subscription(WrenchStamped, "truth/hydro_wrench", on_hydro, RELIABLE_QOS)
    probe.create_subscription(Imu, "imu/data", imu.append, SENSOR_QOS)
    ex = SingleThreadedExecutor(context=context)
    for n in (sim, probe):
        ex.add_node(n)
    try:
        while not sim.live.done:
            ex.spin_once(timeout_sec=0.05)
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
    finally:
        ex.shutdown()
        for n in (sim, probe):
            n.destroy_node()
        rclpy.try_shutdown(context=context)
    # 50 Hz truth and 200 Hz IMU over the protocol, none lost (reliable, one process)
    assert len(hydro) >= 50 * (SECONDS - 0.5)
    assert len(imu) >= 200 * (SECONDS - 0.5) * 0.9
    # the offline run of the same protocol and seed: MuJoCo's fluid wrench, FRD → FLU
    v = load_vehicle("torpedo_auv")
    traj = run(v, make_excitation("B", v, SECONDS, seed=3), backend="mujoco")
    assert traj.hydro is not None
    stamps = np.array([s for s, _ in hydro])
    live = np.array([w for _, w in hydro])
    offline = body_twist(np.column_stack([np.interp(stamps, traj.t, c) for c in traj.hydro.T]))
    assert np.abs(offline).max() > 0.1
    assert np.allclose(live, offline, atol=1e-9 * np.abs(offline).max())
