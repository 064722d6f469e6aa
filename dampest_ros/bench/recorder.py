"""The recorder rows (group ``recorder``): recorder_node recording the sim topics at 20× real
time, and recordings killed with SIGKILL and recovered with reindex."""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from dampest_ros.bench.runner import child, ros_env

SIM_TOPICS = ("/imu/data", "/dvl/twist", "/pressure", "/thrusters/state", "/truth/odom")


def _proc_cpu(pid: int) -> float:
    """User + system CPU seconds of a running process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def counting_recorder(count_file: str) -> None:
    """recorder_node's main() (arguments from sys.argv) whose every message handed to the
    bag recorder is counted in the first 8 bytes of ``count_file`` (shared memory: the count
    survives a SIGKILL)."""
    import mmap

    from dampest_ros.ros import recorder_node

    with open(count_file, "r+b") as f:
        page = mmap.mmap(f.fileno(), 8)
    count = memoryview(page).cast("Q")
    write = recorder_node.RecorderNode._write

    def counted(self: Any, conn: int, data: bytes, info: dict[str, Any]) -> None:
        write(self, conn, data, info)
        count[0] += 1

    recorder_node.RecorderNode._write = counted  # type: ignore[method-assign]
    recorder_node.main()


def recorder(rate_factor: str, seconds: str, kill_at: str = "") -> dict[str, float]:
    """recorder_node (own process) records the sim topics; sim_node here at ``rate_factor``.
    With ``kill_at`` (simulated seconds) the recorder is killed with SIGKILL then and the bag
    recovered with reindex; ``published`` counts the messages published before the kill,
    ``received`` those the recorder had handed to its bag recorder (:func:`counting_recorder`)."""
    ros_env()
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from dampest_ros.io.bag import bag_summary
    from dampest_ros.io.reindex import reindex
    from dampest_ros.ros.sim_node import SimNode

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "bag"
        counter = Path(tmp) / "received"
        counter.write_bytes(bytes(8))
        rec = subprocess.Popen([sys.executable, "-c", "from dampest_ros.bench "
                                f"import recorder; recorder.counting_recorder({str(counter)!r})",
                                "--ros-args", "-p", f"output:={out}", "-p", "status_period:=0.0",
                                "-r", "__node:=bench_recorder"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        rclpy.init()
        sim = SimNode(parameter_overrides=[Parameter("rate_factor", value=float(rate_factor)),
                                           Parameter("duration", value=float(seconds)),
                                           Parameter("publish_clock", value=False)])
        end = time.monotonic() + 60
        while time.monotonic() < end and not all(
                any(i.node_name == "bench_recorder"
                    for i in sim.get_subscriptions_info_by_topic(t)) for t in SIM_TOPICS):
            time.sleep(0.1)
        time.sleep(0.5)
        ex = SingleThreadedExecutor()
        ex.add_node(sim)
        sim.set_parameters([Parameter("seed", value=2)])  # restart now that the recorder listens
        sim.published = 0
        cpu0, wall0 = _proc_cpu(rec.pid), time.monotonic()
        stop = float(kill_at) if kill_at else float("inf")
        while not sim.live.done and sim.live.t < stop:
            ex.spin_once(timeout_sec=0.05)
        wall = time.monotonic() - wall0
        published = sim.published
        if kill_at:
            rec.kill()
            rec.wait(60)
            cpu = 0.0
            recorded = reindex(out).messages
        else:
            time.sleep(1.5)
            cpu = _proc_cpu(rec.pid) - cpu0
            rec.send_signal(signal.SIGINT)
            rec.wait(60)
            recorded = bag_summary(out).message_count
        received = int.from_bytes(counter.read_bytes()[:8], "little")
        sim_s = sim.live.t
        ex.shutdown()
        sim.destroy_node()
        rclpy.shutdown()
    return {"published": float(published), "received": float(received),
            "recorded": float(recorded), "cpu": cpu, "wall": wall, "sim_s": sim_s}


def _killed(seconds: float, seed: int) -> dict[str, float]:
    """A recording killed at a random moment (between 20 % and 90 % of ``seconds``,
    reproducible by ``seed``), recovered with reindex (:func:`_recorder`'s counts)."""
    kill_at = seconds * (0.2 + 0.7 * ((seed * 0.618034) % 1.0))
    return child("recorder.recorder", "20", str(seconds), f"{kill_at:.3f}")


def recorder_rows(args: argparse.Namespace, tmp: str) -> list[tuple[str, ...]]:
    """Recording at 20× real time, and SIGKILL recovery."""
    rows: list[tuple[str, ...]] = []
    r = child("recorder.recorder", "20", str(args.recorder_seconds))
    n = r["recorded"]
    rows.append((f"recorder_node, sim topics at 20× ({r['published']:.0f} msgs, "
                 f"{r['sim_s'] / r['wall']:.1f}× reached)", f"{r['wall']:.1f} s",
                 f"lost {r['published'] - n:.0f}; {r['cpu'] / max(n, 1) * 1e6:.0f} µs CPU "
                 f"per message ({100 * r['cpu'] / r['wall']:.0f} % of a core)",
                 "none lost", ""))
    kills = [_killed(args.recorder_seconds, k) for k in range(args.kills)]
    of_received = sorted(r["recorded"] / max(r["received"], 1.0) for r in kills)
    of_published = sorted(r["recorded"] / max(r["published"], 1.0) for r in kills)
    pace = sorted(r["sim_s"] / r["wall"] for r in kills)
    rows.append((f"  SIGKILL at a random moment, reindex ({args.kills} kills at 20×, "
                 f"{pace[len(pace) // 2]:.1f}× reached)", "",
                 f"kept of the messages received before the kill: min "
                 f"{100 * of_received[0]:.2f} %, median "
                 f"{100 * of_received[len(kills) // 2]:.2f} %", "≥ 99 %", ""))
    behind = sorted(r["published"] - r["received"] for r in kills)
    rows.append(("  the same kills, of the messages published before the kill", "",
                 f"min {100 * of_published[0]:.1f} %, median "
                 f"{100 * of_published[len(kills) // 2]:.1f} % (the rest had not reached "
                 f"the recorder when it was killed: median {behind[len(kills) // 2]:.0f}, "
                 f"max {behind[-1]:.0f} messages)", "", ""))
    return rows
