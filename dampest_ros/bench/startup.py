"""The start-up rows (group ``startup``): ``dampest --help``, every ``dampest CMD --help``,
and how soon ``dampest record`` records."""

from __future__ import annotations

import argparse
import signal
import subprocess
import tempfile
import time
from pathlib import Path

from dampest_ros.bench.runner import child, dampest_script, ros_env


def _wall(argv: list[str], runs: int = 5) -> float:
    """Median wall-clock seconds of a command (its output discarded, exit status 0)."""
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        times.append(time.perf_counter() - t0)
    return sorted(times)[len(times) // 2]


def record_start(seconds: str = "4", runs: str = "5") -> dict[str, float]:
    """``dampest record -o BAG imu/data`` started ``runs`` times, one after the other, while
    this process publishes imu/data at 100 Hz: seconds from starting it to the receive stamp
    of its first message (median, min, max), messages recorded and exit status of the run
    of the median."""
    ros_env()
    import threading

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import Imu

    from dampest_ros.io.bag import bag_summary

    rclpy.init()
    node = rclpy.create_node("bench_imu")
    pub = node.create_publisher(Imu, "imu/data", 100)
    node.create_timer(0.01, lambda: pub.publish(Imu()))
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    spinner = threading.Thread(target=ex.spin, daemon=True)
    spinner.start()
    time.sleep(1.0)  # the publisher is up before the recorder starts
    found = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(int(runs)):
            out = Path(tmp) / f"bag{k}"
            t0 = time.time()
            rec = subprocess.Popen([dampest_script(), "record", "-o", str(out), "imu/data"],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            time.sleep(float(seconds))
            rec.send_signal(signal.SIGINT)
            rec.wait(60)
            summary = bag_summary(out)
            found.append((summary.start - t0, float(summary.message_count),
                          float(rec.returncode)))
    ex.shutdown()
    spinner.join(10)
    node.destroy_node()
    rclpy.try_shutdown()
    found.sort()
    first, messages, status = found[len(found) // 2]
    return {"first": first, "min": found[0][0], "max": found[-1][0], "messages": messages,
            "status": status, "runs": float(len(found))}


def startup_rows(args: argparse.Namespace, tmp: str) -> list[tuple[str, ...]]:
    """dampest --help, every dampest CMD --help, and how soon dampest record records."""
    from dampest_ros.cli.main import COMMANDS

    exe = dampest_script()
    rows: list[tuple[str, ...]] = [
        ("dampest --help", f"{_wall([exe, '--help']):.2f} s", "median of 5", "≤ 0.3 s", "")]
    for name in COMMANDS:
        rows.append((f"  dampest {name} --help", f"{_wall([exe, name, '--help']):.2f} s",
                     "median of 5", "≤ 0.5 s", ""))
    r = child("startup.record_start")
    rows.append(("dampest record: start to first message written", f"{r['first']:.2f} s",
                 f"median of {r['runs']:.0f} (min {r['min']:.2f} s, max {r['max']:.2f} s); "
                 f"imu/data at 100 Hz already published; {r['messages']:.0f} messages in "
                 f"4 s, exit status {r['status']:.0f}", "≤ 1 s", f"{r['peak_mb']:.0f}"))
    return rows
