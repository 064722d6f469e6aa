"""Benchmark (not collected by pytest): recorder_node as a separate process records the sim
topic set while sim_node runs in this process at RATE_FACTOR × real time; prints the sim's
message count, the recorder's counts, messages lost and its CPU per message.

    python test/ros/bench_recorder.py [RATE_FACTOR [SIM_SECONDS [OUTPUT_DIR]]]

Uses ROS_DOMAIN_ID 89, localhost only.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.update(ROS_DOMAIN_ID="89", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                  OPENBLAS_NUM_THREADS="1")
REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from dampest_ros.io.bag import bag_summary  # noqa: E402
from dampest_ros.ros.sim_node import SimNode  # noqa: E402

SIM_TOPICS = ("/imu/data", "/dvl/twist", "/pressure", "/thrusters/state", "/truth/odom")


def main() -> None:
    factor = float(sys.argv[1]) if len(sys.argv) > 1 else 20.0
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 120.0
    root = Path(sys.argv[3]) if len(sys.argv) > 3 else Path(tempfile.mkdtemp())
    out = root / "bench_bag"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    log = (root / "recorder.log").open("w")
    rec = subprocess.Popen([sys.executable, "-m", "dampest_ros.ros.recorder_node",
                            "--ros-args", "-p", f"output:={out}", "-p", "status_period:=0.0",
                            "-r", "__node:=bench_recorder"],
                           env=env, stdout=log, stderr=subprocess.STDOUT)
    rclpy.init()
    sim = SimNode(parameter_overrides=[Parameter("rate_factor", value=factor),
                                       Parameter("duration", value=seconds),
                                       Parameter("publish_clock", value=False)])
    end = time.monotonic() + 60
    while time.monotonic() < end and not all(
            any(i.node_name == "bench_recorder" for i in sim.get_subscriptions_info_by_topic(t))
            for t in SIM_TOPICS):
        time.sleep(0.1)
    time.sleep(0.5)
    executor = SingleThreadedExecutor()
    executor.add_node(sim)
    sim.set_parameters([Parameter("seed", value=2)])  # restart now that the recorder listens
    sim.published = 0
    wall0 = time.monotonic()
    while not sim.live.done:
        executor.spin_once(timeout_sec=0.05)
    wall = time.monotonic() - wall0
    print(f"sim: {sim.published} messages, {seconds:g} s simulated in {wall:.1f} s "
          f"({seconds / wall:.1f}x real time)")
    time.sleep(1.5)
    rec.send_signal(signal.SIGINT)
    rec.wait(60)
    log.close()
    print((root / "recorder.log").read_text().strip().splitlines()[-1])
    summary = bag_summary(out)
    print(f"bag: {summary.message_count} messages, "
          f"{summary.message_count - sim.published} against the sim's count")
    sim.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
