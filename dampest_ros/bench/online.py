"""The online rows: the ``dampest live`` pipeline flown flat out (group ``live``) and
estimator_node's CPU per sample against a bare rclpy subscriber (group ``estimator``)."""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from dampest_ros.bench.runner import VEHICLE, child, result, ros_env, spawn


def live(duration: str) -> dict[str, float]:
    """The ``dampest live`` pipeline with its default options (shadow controller) flown flat
    out for ``duration`` simulated seconds."""
    ros_env()
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


def publish_samples(seconds: str, speed: str, subscribers: str) -> dict[str, float]:
    """Publish the dampest/* samples of ``seconds`` of protocol B at ``speed``× real time
    once ``subscribers`` nodes subscribe to every topic."""
    ros_env()
    import rclpy
    from geometry_msgs.msg import (
        AccelWithCovarianceStamped,
        QuaternionStamped,
        TwistWithCovarianceStamped,
        WrenchStamped,
    )

    from dampest_ros.core.online.preprocessor import OnlinePreprocessor
    from dampest_ros.core.simulation.excitation import make_excitation
    from dampest_ros.core.simulation.sensors import measure
    from dampest_ros.core.simulation.simulate import run
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


def receive(kind: str, samples: str) -> dict[str, float]:
    """Spin a subscriber (``estimator`` or ``bare``) until ``samples`` samples (4 messages
    each) arrived or none came for 5 s; its process CPU from the first message to the last."""
    ros_env()
    import rclpy
    from rclpy.node import Node

    rclpy.init()
    node: Node
    count: Callable[[], int]
    if kind == "estimator":
        from dampest_ros.core.online.estimator import STREAMS
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
    pub = spawn("online.publish_samples", str(seconds), str(speed), "2")
    # the sample count is known only to the publisher: the subscribers stop when idle
    subs = {k: spawn("online.receive", k, str(10**9)) for k in ("estimator", "bare")}
    sent = result(pub, "publish_samples")
    out = {"samples": sent["samples"], "wall": sent["wall"]}
    for k, proc in subs.items():
        r = result(proc, f"receive {k}")
        out[f"{k}_received"] = r["received"]
        out[f"{k}_cpu"] = r["cpu"]
    return out


def live_rows(args: argparse.Namespace, tmp: str) -> list[tuple[str, ...]]:
    """The ``dampest live`` pipeline flown flat out, and its CPU."""
    rows: list[tuple[str, ...]] = []
    r = child("online.live", str(args.live_seconds))
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
    return rows


def estimator_rows(args: argparse.Namespace, tmp: str) -> list[tuple[str, ...]]:
    """estimator_node CPU per sample against a bare subscriber."""
    rows: list[tuple[str, ...]] = []
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
    return rows
