"""Benchmarks (``make bench``): speed and memory of the simulator, the offline identification
and the online pipeline.

Each measurement runs in a fresh subprocess so that its peak resident memory is its own.
Prints a table; ``--hours`` sets the length of the long identification bags, ``--only`` picks
groups of rows. The online rows (ROS 2 nodes; the environment's ROS_DOMAIN_ID, localhost only):

- ``live``: sim_node → preprocess_node → estimator_node → controller_node (shadow mode) in
  one process on one SingleThreadedExecutor, as ``dampest live`` builds them, BlueROV2 Heavy,
  protocol B, flown flat out (the sim asks for 1000× real time and slows down to what the
  executor sustains, at most ``max_lag`` simulated seconds per tick); the figure is simulated
  over wall-clock time, with every message that did not arrive counted;
- ``estimator``: CPU per sample of estimator_node in its own process against a bare rclpy
  node (the same four dampest/* subscriptions, callbacks that do nothing) in another, both
  receiving the same samples from a third process at 10× real time;
- ``recorder``: recorder_node in its own process records the sim topic set while sim_node
  runs at 20× real time: messages lost and the recorder's CPU per message; then
  ``--kills`` recordings killed with SIGKILL at a random moment and recovered with reindex:
  the share of the messages the recorder had received before the kill that the bag keeps
  (the recorder's own loss; its node counts them in a shared memory page), and the share of
  those published before the kill (messages still in the middleware's queues included),
  min / median of each.

The start-up rows (``startup``): wall-clock time of ``dampest --help`` and of every
``dampest CMD --help`` (median of 5 runs of the console script), and how soon ``dampest
record`` records: a publisher sends imu/data at 100 Hz, ``dampest record -o BAG imu/data`` is
started, and the figure is the time from starting the process to the receive stamp of the
first message in the bag (the recorder stamps messages with the system clock on receipt), so
it holds the interpreter start, the imports, the node, discovery and the first subscription.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from dampest_ros.cli.common import table

VEHICLE = "bluerov2_heavy"
MUJOCO_VEHICLE = "torpedo_auv"  # the stiffer of the two MuJoCo presets (slender, finned)


def _simulate(out: str, duration: str, backend: str = "native", seed: str = "1"
              ) -> dict[str, float]:
    from dampest_ros.core.excitation import make_excitation
    from dampest_ros.core.sensors import measure
    from dampest_ros.core.simulate import run
    from dampest_ros.io.bag import write_bag
    from dampest_ros.io.yaml_io import load_vehicle

    vehicle = load_vehicle(VEHICLE if backend == "native" else MUJOCO_VEHICLE)
    t0 = time.perf_counter()
    traj = run(vehicle, make_excitation("B", vehicle, float(duration), seed=int(seed)),
               backend=backend)
    t1 = time.perf_counter()
    rec = measure(traj, vehicle.body.rho, vehicle.body.gravity, seed=int(seed))
    t2 = time.perf_counter()
    write_bag(out, rec)
    t3 = time.perf_counter()
    return {"seconds": t3 - t0, "integrate": t1 - t0, "sensors": t2 - t1, "write": t3 - t2,
            "messages": float(sum(len(s) for s in rec.values()))}


def _deserialise(bag: str) -> dict[str, float]:
    from rosbags.highlevel import AnyReader

    t0 = time.perf_counter()
    n = 0
    with AnyReader([Path(bag)]) as reader:
        for conn, _, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)
            n += 1
    return {"seconds": time.perf_counter() - t0, "messages": float(n)}


def _identify(bag: str, vehicle: str = VEHICLE, *options: str) -> dict[str, float]:
    return _quiet_identify([bag, "--vehicle", vehicle, *options])


def _quiet_identify(argv: list[str]) -> dict[str, float]:
    """``dampest identify ARGV`` with its output discarded: seconds and exit status."""
    from dampest_ros.cli.main import main

    t0 = time.perf_counter()
    with open(os.devnull, "w") as null:
        stdout, stderr, sys.stdout, sys.stderr = sys.stdout, sys.stderr, null, null
        try:
            status = main(["identify", *argv])
        finally:
            sys.stdout, sys.stderr = stdout, stderr
    return {"seconds": time.perf_counter() - t0, "status": float(status)}


def _pool(workers: str, *bags: str) -> dict[str, float]:
    """``dampest identify BAG ...`` end to end on a LocalCluster of ``workers`` processes
    (passed as --scheduler so that it outlives the command), then the workers' peak RSS."""
    import logging
    import resource

    from dask.distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=logging.CRITICAL)
    try:
        t = _quiet_identify([*bags, "--vehicle", VEHICLE, "--scheduler",
                             cluster.scheduler_address])
        with Client(cluster) as client:
            peak = client.run(lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
    finally:
        cluster.close()
    return {**t, "worker_peak_mb": max(peak.values()) / 1024}


def _ros_env() -> None:
    """Keep the benchmark's ROS traffic on this host (domain: the environment's, else 77)."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", "77")


def _live(duration: str) -> dict[str, float]:
    """The ``dampest live`` pipeline with its default options (shadow controller) flown flat
    out for ``duration`` simulated seconds."""
    _ros_env()
    import rclpy

    from dampest_ros.cli import live
    from dampest_ros.cli.live_options import add_options
    from dampest_ros.io.yaml_io import load_vehicle

    ap = argparse.ArgumentParser()
    add_options(ap, "")
    a = ap.parse_args([])  # dampest live's defaults, but for the length and the pace:
    a.duration = float(duration)
    a.rate_factor = 1000.0  # beyond reach: the sim flies max_lag per tick, flat out
    context = rclpy.Context()
    rclpy.init(context=context)
    with tempfile.TemporaryDirectory() as tmp:
        prior = live.write_prior(load_vehicle(a.vehicle), a.prior_factor,
                                 Path(tmp) / "prior.yaml")
        pipe = live.build_pipeline(a, prior, Path(tmp) / "model.yaml", context)
        sim, pre, est, ctrl, ex = pipe.sim, pipe.pre, pipe.est, pipe.ctrl, pipe.executor
        t0, c0 = time.monotonic(), time.process_time()
        while not sim.live.done:
            ex.spin_once(timeout_sec=0.05)
        wall, cpu = time.monotonic() - t0, time.process_time() - c0
        end = time.monotonic() + 1.0
        while time.monotonic() < end:  # what is still queued arrives late, not lost
            ex.spin_once(timeout_sec=0.05)
        c, e = pre.pre.counts, est.estimator.counts
        assert ctrl is not None  # dampest live's default: the controller in shadow mode
        out = {"sim_s": sim.live.t, "wall": wall, "cpu": cpu,
               "imu_lost": float(sim.counts["imu/data"] - c["imu"]),
               "thrusters_lost": float(sim.counts["thrusters/state"] - c["thrusters"]),
               "dvl_lost": float(sim.counts["dvl/twist"] - c["dvl"]),
               "samples": float(pre.published),
               "samples_lost": float(pre.published - e["attitude"]),
               "unmatched": float(e["unmatched"]), "used": float(e["used"]),
               "controller_lost": float(pre.published - ctrl.commands)}
        pipe.close()
    rclpy.try_shutdown(context=context)
    return out


def _publish_samples(seconds: str, speed: str, subscribers: str) -> dict[str, float]:
    """Publish the dampest/* samples of ``seconds`` of protocol B at ``speed``× real time
    once ``subscribers`` nodes subscribe to every topic."""
    _ros_env()
    import rclpy
    from geometry_msgs.msg import (
        AccelWithCovarianceStamped,
        QuaternionStamped,
        TwistWithCovarianceStamped,
        WrenchStamped,
    )

    from dampest_ros.core.excitation import make_excitation
    from dampest_ros.core.online.preprocessor import OnlinePreprocessor
    from dampest_ros.core.sensors import measure
    from dampest_ros.core.simulate import run
    from dampest_ros.io.yaml_io import load_vehicle
    from dampest_ros.ros.common import RELIABLE_QOS
    from dampest_ros.ros.preprocess_node import SampleMessages

    v = load_vehicle(VEHICLE)
    rec = measure(run(v, make_excitation("B", v, float(seconds), seed=1)), v.body.rho,
                  v.body.gravity, seed=1)
    samples = [s for s in OnlinePreprocessor(v.thrusters, v.body.gravity, v.body.rho).run(rec)
               if s.usable]
    rclpy.init()
    from rclpy.serialization import serialize_message
    writer = SampleMessages()  # serialised up front: publishing costs the publisher little
    msgs = [[serialize_message(m) for m in writer.fill(s, "base_link")] for s in samples]
    node = rclpy.create_node("bench_sample_publisher")
    pubs = [node.create_publisher(kind, f"dampest/{name}", RELIABLE_QOS) for name, kind in (
        ("velocity", TwistWithCovarianceStamped), ("acceleration", AccelWithCovarianceStamped),
        ("wrench", WrenchStamped), ("attitude", QuaternionStamped))]
    end = time.monotonic() + 60
    while time.monotonic() < end and min(p.get_subscription_count() for p in pubs) < \
            int(subscribers):
        time.sleep(0.05)
    time.sleep(1.0)
    rate = 50.0 * float(speed)
    t0 = time.monotonic()
    for k, group in enumerate(msgs):
        delay = t0 + k / rate - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        for p, m in zip(pubs, group, strict=True):
            p.publish(m)
    wall = time.monotonic() - t0
    time.sleep(2.0)  # reliable: let the subscribers take what is queued
    node.destroy_node()
    rclpy.shutdown()
    return {"samples": float(len(msgs)), "wall": wall}


def _receive(kind: str, samples: str) -> dict[str, float]:
    """Spin a subscriber (``estimator`` or ``bare``) until ``samples`` samples (4 messages
    each) arrived or none came for 5 s; its process CPU from the first message to the last."""
    _ros_env()
    import rclpy
    from rclpy.node import Node

    rclpy.init()
    node: Node
    count: Callable[[], int]
    if kind == "estimator":
        from dampest_ros.core.estimator import STREAMS
        from dampest_ros.ros.estimator_node import EstimatorNode
        est = EstimatorNode()
        node = est
        counts = est.estimator.counts

        def count() -> int:
            return sum(counts[s] for s in STREAMS)
    else:
        node = _bare_node()

        def count() -> int:
            return int(node.received)  # type: ignore[attr-defined]
    total = 4 * int(samples)
    n, c_first, c_last = 0, 0.0, 0.0
    idle = time.monotonic() + 60.0
    while n < total and time.monotonic() < idle:
        rclpy.spin_once(node, timeout_sec=0.1)
        k = count()
        if k != n:
            if n == 0:
                c_first = time.process_time()
            n, c_last, idle = k, time.process_time(), time.monotonic() + 5.0
    node.destroy_node()
    rclpy.shutdown()
    return {"received": float(n), "cpu": c_last - c_first}


def _bare_node() -> Any:
    """A node with the estimator's four subscriptions whose callbacks only count."""
    from geometry_msgs.msg import (
        AccelWithCovarianceStamped,
        QuaternionStamped,
        TwistWithCovarianceStamped,
        WrenchStamped,
    )
    from rclpy.node import Node

    from dampest_ros.ros.common import RELIABLE_QOS

    class Bare(Node):
        def __init__(self) -> None:
            super().__init__("bench_bare_subscriber")
            self.received = 0
            for name, kind in (("velocity", TwistWithCovarianceStamped),
                               ("acceleration", AccelWithCovarianceStamped),
                               ("wrench", WrenchStamped), ("attitude", QuaternionStamped)):
                self.create_subscription(kind, f"dampest/{name}", self._on, RELIABLE_QOS)

        def _on(self, _: Any) -> None:
            self.received += 1

    return Bare()


def _estimator_cost(seconds: float, speed: float) -> dict[str, float]:
    """The ``estimator`` rows: a publisher and two subscriber processes at once."""
    pub = _spawn("publish_samples", str(seconds), str(speed), "2")
    # the sample count is known only to the publisher: the subscribers stop when idle
    subs = {k: _spawn("receive", k, str(10**9)) for k in ("estimator", "bare")}
    sent = _result(pub, "publish_samples")
    out = {"samples": sent["samples"], "wall": sent["wall"]}
    for k, proc in subs.items():
        r = _result(proc, f"receive {k}")
        out[f"{k}_received"] = r["received"]
        out[f"{k}_cpu"] = r["cpu"]
    return out


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


def _recorder(rate_factor: str, seconds: str, kill_at: str = "") -> dict[str, float]:
    """recorder_node (own process) records the sim topics; sim_node here at ``rate_factor``.
    With ``kill_at`` (simulated seconds) the recorder is killed with SIGKILL then and the bag
    recovered with reindex; ``published`` counts the messages published before the kill,
    ``received`` those the recorder had handed to its bag recorder (:func:`counting_recorder`)."""
    _ros_env()
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
        rec = subprocess.Popen([sys.executable, "-c", "from dampest_ros import "
                                f"bench; bench.counting_recorder({str(counter)!r})",
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


def _dampest() -> str:
    """The dampest console script of this interpreter's environment (else the one on PATH)."""
    here = Path(sys.executable).parent / "dampest"
    return str(here) if here.exists() else (shutil.which("dampest") or "dampest")


def _wall(argv: list[str], runs: int = 5) -> float:
    """Median wall-clock seconds of a command (its output discarded, exit status 0)."""
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        times.append(time.perf_counter() - t0)
    return sorted(times)[len(times) // 2]


def _record_start(seconds: str = "4") -> dict[str, float]:
    """``dampest record -o BAG imu/data`` started while this process publishes imu/data at
    100 Hz: seconds from starting it to the receive stamp of its first message."""
    _ros_env()
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
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "bag"
        t0 = time.time()
        rec = subprocess.Popen([_dampest(), "record", "-o", str(out), "imu/data"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(float(seconds))
        rec.send_signal(signal.SIGINT)
        rec.wait(60)
        summary = bag_summary(out)
    ex.shutdown()
    spinner.join(10)
    node.destroy_node()
    rclpy.try_shutdown()
    return {"first": summary.start - t0, "messages": float(summary.message_count),
            "status": float(rec.returncode)}


def _arm_identify(hours: str) -> dict[str, float]:
    """``hours`` of 1 kHz UR5 joint data (an FFS trajectory, 5 harmonics at 0.1 Hz, the
    torque of the model's true parameters, 20-bit encoders, torque noise 0.4–0.1 N m; one
    period computed and repeated) identified as ``dampest arm identify`` does it (zero-phase
    filter, decimation, regressor in chunks, OLS, WLS, physically consistent fit), timed
    from the arrays on (the bag reading is not in it)."""
    import numpy as np

    from dampest_ros.core.arm.base import base_parameters
    from dampest_ros.core.arm.ffs import random_trajectory
    from dampest_ros.core.arm.identify import IdentifyConfig, filter_joints, identify_arm
    from dampest_ros.core.arm.regressor import full_parameters, regressor
    from dampest_ros.core.arm.simulate import REALISTIC
    from dampest_ros.io.arm import load_arm

    arm = load_arm("ur5")
    base = base_parameters(arm.model)
    traj = random_trajectory(np.zeros(6), 5, 0.1, np.full(6, 1.0), np.random.default_rng(3))
    q, qd, qdd = traj.evaluate(np.arange(10_000) / 1000.0)
    truth = full_parameters(arm.model, arm.dynamics, np.asarray(REALISTIC.torque_offset))
    reps = round(float(hours) * 360)
    step = 2.0 * np.pi / REALISTIC.encoder_counts
    position = np.round(np.tile(q, (reps, 1)) / step) * step
    effort = np.tile(regressor(arm.model, q, qd, qdd) @ truth, (reps, 1))
    effort += np.random.default_rng(1).normal(size=effort.shape) * REALISTIC.torque_sigma
    t = np.arange(len(effort)) / 1000.0
    cfg = IdentifyConfig()
    t0 = time.perf_counter()
    res = identify_arm(arm.model, base, filter_joints(t, position, effort, cfg),
                       full_parameters(arm.model, arm.dynamics), cfg)
    seconds = time.perf_counter() - t0
    z = np.abs(res.wls.theta - base.of(truth)) / res.wls.std
    return {"seconds": seconds, "samples": float(len(t)), "max_z": float(z.max())}


TASKS: dict[str, Callable[..., dict[str, float]]] = {
    "simulate": _simulate, "deserialise": _deserialise, "identify": _identify, "live": _live,
    "publish_samples": _publish_samples, "receive": _receive, "recorder": _recorder,
    "record_start": _record_start, "pool": _pool, "arm_identify": _arm_identify}


def _spawn(task: str, *args: str) -> subprocess.Popen[str]:
    """Start a task in a subprocess (it prints its result plus the peak RSS as JSON)."""
    code = ("import json, resource, sys; from dampest_ros import bench; "
            f"r = bench.TASKS[{task!r}](*{list(args)!r}); "
            "r['peak_mb'] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024; "
            "print(json.dumps(r))")
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)


def _result(proc: subprocess.Popen[str], task: str) -> dict[str, float]:
    out, err = proc.communicate()
    if proc.returncode:
        raise RuntimeError(f"benchmark {task} failed:\n{err}")
    result: dict[str, float] = json.loads(out.strip().splitlines()[-1])
    return result


def _child(task: str, *args: str) -> dict[str, float]:
    """Run a task in a subprocess; its result plus the peak RSS (MB)."""
    return _result(_spawn(task, *args), task)


GROUPS = ("startup", "simulate", "identify", "select", "pool", "live", "estimator", "recorder",
          "arm")


def _startup_rows() -> list[tuple[str, ...]]:
    """dampest --help, every dampest CMD --help, and how soon dampest record records."""
    from dampest_ros.cli.main import COMMANDS

    exe = _dampest()
    rows: list[tuple[str, ...]] = [
        ("dampest --help", f"{_wall([exe, '--help']):.2f} s", "median of 5", "≤ 0.3 s", "")]
    for name in COMMANDS:
        rows.append((f"  dampest {name} --help", f"{_wall([exe, name, '--help']):.2f} s",
                     "median of 5", "≤ 0.5 s", ""))
    r = _child("record_start")
    rows.append(("dampest record: start to first message written", f"{r['first']:.2f} s",
                 f"imu/data at 100 Hz already published; {r['messages']:.0f} messages in "
                 f"4 s, exit status {r['status']:.0f}", "≤ 1 s", f"{r['peak_mb']:.0f}"))
    return rows


def _online_rows(args: argparse.Namespace, only: set[str]) -> list[tuple[str, ...]]:
    rows: list[tuple[str, ...]] = []
    if "live" in only:
        r = _child("live", str(args.live_seconds))
        lost = {k: int(r[f"{k}_lost"]) for k in ("imu", "thrusters", "dvl", "samples",
                                                   "controller")}
        what = ", ".join(f"{k} {n}" for k, n in lost.items() if n) or "none"
        rows.append((f"dampest live pipeline {r['sim_s']:.0f} s, flat out (4 nodes, 1 "
                     "executor)", f"{r['wall']:.1f} s",
                     f"{r['sim_s'] / r['wall']:.2f}× real time; lost: {what}",
                     "≥ 5×, none lost", f"{r['peak_mb']:.0f}"))
        rows.append(("  its CPU (one process)", f"{r['cpu']:.1f} s",
                     f"{r['sim_s'] / r['cpu']:.2f} simulated s per CPU s; "
                     f"{r['samples']:.0f} samples, {r['used']:.0f} used by the RLS", "", ""))
    if "estimator" in only:
        r = _estimator_cost(args.estimator_seconds, 10.0)
        n = r["samples"]
        per = {k: r[f"{k}_cpu"] / max(r[f"{k}_received"] / 4, 1) for k in ("estimator", "bare")}
        lost = {k: int(4 * n - r[f"{k}_received"]) for k in ("estimator", "bare")}
        rows.append((f"estimator_node CPU per sample ({n:.0f} samples at 10× real time)",
                     f"{r['wall']:.1f} s", f"{per['estimator'] * 1e6:.0f} µs = "
                     f"{per['estimator'] / per['bare']:.2f}× the bare subscriber",
                     "≤ 1.2×", ""))
        rows.append(("  bare rclpy subscriber (the same 4 topics, same run)", "",
                     f"{per['bare'] * 1e6:.0f} µs per sample (4 executor rounds); messages "
                     f"lost: estimator {lost['estimator']}, bare {lost['bare']}", "", ""))
    if "recorder" in only:
        r = _child("recorder", "20", str(args.recorder_seconds))
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
        rows.append(("  the same kills, of the messages published before the kill", "",
                     f"min {100 * of_published[0]:.1f} %, median "
                     f"{100 * of_published[len(kills) // 2]:.1f} % (the rest: still in "
                     "the middleware's queues)", "", ""))
    return rows


def _pool_rows(tmp: str, seconds: float) -> list[tuple[str, ...]]:
    """Eight protocol-B bags (seeds 1–8) identified pooled on 1 and on 2 Dask workers, and
    the workers' peak memory for 4 and for 8 bags (2 workers)."""
    bags = [f"{tmp}/pool{k}" for k in range(1, 9)]
    for k, bag in enumerate(bags, 1):
        _child("simulate", bag, str(seconds), "native", str(k))
    one, two = _child("pool", "1", *bags), _child("pool", "2", *bags)
    four = _child("pool", "2", *bags[:4])
    name = f"identify 8 × {seconds:.0f} s bags pooled (Dask)"
    return [(f"{name}, 1 worker", f"{one['seconds']:.1f} s", "", "",
             f"{one['worker_peak_mb']:.0f} (worker)"),
            (f"{name}, 2 workers", f"{two['seconds']:.1f} s",
             f"{one['seconds'] / two['seconds']:.2f}× 1 worker", "≥ 1.6×",
             f"{two['worker_peak_mb']:.0f} (worker)"),
            ("  the same, 4 bags on 2 workers", f"{four['seconds']:.1f} s",
             f"worker peak {four['worker_peak_mb']:.0f} MB (4 bags) vs "
             f"{two['worker_peak_mb']:.0f} MB (8)", "flat", "")]


def _killed(seconds: float, seed: int) -> dict[str, float]:
    """A recording killed at a random moment (between 20 % and 90 % of ``seconds``,
    reproducible by ``seed``), recovered with reindex (:func:`_recorder`'s counts)."""
    kill_at = seconds * (0.2 + 0.7 * ((seed * 0.618034) % 1.0))
    return _child("recorder", "20", str(seconds), f"{kill_at:.3f}")


def main(argv: list[str] | None = None) -> int:
    """Run the benchmarks and print the table."""
    ap = argparse.ArgumentParser(prog="python -m dampest_ros.bench", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, nargs="*", default=[1.0],
                    help="lengths of the identification bags in hours (default: 1)")
    ap.add_argument("--sim-seconds", type=float, default=600.0,
                    help="simulated seconds for the simulator benchmark (default: 600)")
    ap.add_argument("--live-seconds", type=float, default=120.0,
                    help="simulated seconds of the live pipeline (default: 120)")
    ap.add_argument("--estimator-seconds", type=float, default=60.0,
                    help="seconds of samples for the estimator CPU rows (default: 60)")
    ap.add_argument("--recorder-seconds", type=float, default=120.0,
                    help="simulated seconds recorded by the recorder rows (default: 120)")
    ap.add_argument("--kills", type=int, default=10,
                    help="recordings killed with SIGKILL in the recorder rows (default: 10)")
    ap.add_argument("--pool-seconds", type=float, default=600.0,
                    help="length of each of the 8 bags of the pooled rows (default: 600)")
    ap.add_argument("--only", nargs="+", choices=GROUPS, default=list(GROUPS),
                    help="groups of rows to run (default: all)")
    args = ap.parse_args(argv)
    only = set(args.only)
    rows: list[tuple[str, ...]] = _startup_rows() if "startup" in only else []
    with tempfile.TemporaryDirectory() as tmp:
        if "simulate" in only:
            sim = _child("simulate", f"{tmp}/sim", str(args.sim_seconds))
            speed = args.sim_seconds / sim["seconds"]
            rows.append((f"simulate {args.sim_seconds:.0f} s → MCAP (200 Hz IMU)",
                         f"{sim['seconds']:.1f} s", f"{speed:.0f}× real time", "≥ 50×",
                         f"{sim['peak_mb']:.0f}"))
            sim = _child("simulate", f"{tmp}/mj", str(args.sim_seconds), "mujoco")
            speed = args.sim_seconds / sim["seconds"]
            rows.append((f"simulate --backend mujoco {args.sim_seconds:.0f} s ({MUJOCO_VEHICLE}) "
                         "→ MCAP", f"{sim['seconds']:.1f} s", f"{speed:.0f}× real time",
                         "≥ 20×", f"{sim['peak_mb']:.0f}"))
        for hours in args.hours if "identify" in only else []:
            bag = f"{tmp}/bag{hours}"
            _child("simulate", bag, str(hours * 3600))
            des = _child("deserialise", bag)
            ide = _child("identify", bag)
            rows.append((f"rosbags deserialise {hours:g} h ({des['messages']:.0f} msgs)",
                         f"{des['seconds']:.1f} s", f"{des['messages'] / des['seconds']:.0f} msg/s",
                         "", f"{des['peak_mb']:.0f}"))
            rows.append((f"dampest identify {hours:g} h, end to end",
                         f"{ide['seconds']:.1f} s",
                         f"{ide['seconds'] / des['seconds']:.2f}× deserialise time",
                         "≤ 1×, ≤ 400 MB", f"{ide['peak_mb']:.0f}"))
        if "select" in only:
            bag = f"{tmp}/select"
            _child("simulate", bag, str(args.sim_seconds), "mujoco")
            plain = _child("identify", bag, MUJOCO_VEHICLE)
            select = _child("identify", bag, MUJOCO_VEHICLE, "--select")
            rows.append((f"identify {args.sim_seconds:.0f} s {MUJOCO_VEHICLE} (MuJoCo)",
                         f"{plain['seconds']:.1f} s", "", "", f"{plain['peak_mb']:.0f}"))
            rows.append(("  the same with --select (882 library terms)",
                         f"{select['seconds']:.1f} s",
                         f"{select['seconds'] / plain['seconds']:.2f}× plain identify", "≤ 3×",
                         f"{select['peak_mb']:.0f}"))
        if "pool" in only:
            rows += _pool_rows(tmp, args.pool_seconds)
        for hours in args.hours if "arm" in only else []:
            arm = _child("arm_identify", str(hours))
            rows.append((f"arm identify {hours:g} h of 1 kHz UR5 joint data (arrays)",
                         f"{arm['seconds']:.1f} s", f"{arm['samples']:.0f} samples, WLS "
                         f"max |error|/sigma {arm['max_z']:.1f}", "≤ 10 s",
                         f"{arm['peak_mb']:.0f}"))
    rows += _online_rows(args, only)
    print(table(("benchmark", "time", "figure", "goal", "peak MB"), rows))
    load = os.getloadavg()
    print(f"\nmachine: {os.cpu_count()} cores, load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} "
          f"(1, 5, 15 min), Python {sys.version.split()[0]}")
    return 0

if __name__ == "__main__":
    sys.exit(main())
