"""``dampest live``: the online pipeline in one process, faster than real time.

sim_node → preprocess_node → estimator_node → controller_node on one rclpy executor: the
BlueROV2 Heavy flies protocol B (300 s of simulation time by default) while the estimator
identifies its damping with recursive least squares. Every few simulated seconds a table
shows the estimate converging against the simulator's truth; at the end the model is saved
(an atomic write, as the estimator's ~/save does) to OUT/model.yaml.

The controller runs in shadow mode by default: it reads the model through
dampest_ros.client and computes its commands (controller/cmd_wrench) while the protocol flies
the vehicle; with --controller fly it flies the vehicle itself (cmd_wrench) at the reference
--reference, using the model identified so far as feed-forward.

Executors: rclpy's SingleThreadedExecutor by default. With the GIL the MultiThreadedExecutor
runs the same callbacks with no parallelism and about twice the dispatch cost; on a 2-core
machine it fell behind at 2–3x real time and dropped most of the best-effort IMU messages
(--executor multi to see it).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

from dampest_ros.cli.common import table


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the sub-command."""
    p = sub.add_parser("live", help="online pipeline (sim, preprocess, RLS, controller) in "
                                    "one process", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog="example: dampest live --duration 300 --rate-factor 2.5")
    p.add_argument("--out", default="runs/live", help="output folder (default: runs/live)")
    p.add_argument("--duration", type=float, default=300.0,
                   help="simulated seconds (default: 300)")
    p.add_argument("--rate-factor", type=float, default=2.5,
                   help="simulated seconds per wall-clock second (default: 2.5)")
    p.add_argument("--vehicle", default="bluerov2_heavy", help="preset (default: "
                                                               "bluerov2_heavy)")
    p.add_argument("--protocol", default="B", help="excitation protocol (default: B)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--forgetting-factor", type=float, default=0.999,
                   help="RLS forgetting factor λ (default: 0.999)")
    p.add_argument("--effects", default="", help="hidden effects as YAML, e.g. "
                   "'{damping_change_time: 200, damping_change_factor: 1.3}'")
    p.add_argument("--every", type=float, default=20.0,
                   help="print the table every this many simulated seconds (default: 20)")
    p.add_argument("--executor", choices=("single", "multi"), default="single",
                   help="rclpy executor (default: single; see above)")
    p.add_argument("--controller", choices=("shadow", "fly", "off"), default="shadow",
                   help="controller mode (default: shadow)")
    p.add_argument("--reference", type=float, nargs=6, default=[0.3, 0.0, 0.0, 0.0, 0.0, 0.2],
                   metavar="V", help="velocity reference of the controller, FLU "
                   "(default: 0.3 0 0 0 0 0.2)")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS_DOMAIN_ID (default: the environment's, else 77)")
    p.set_defaults(run=run)


def _table(est: Any, truth: dict[str, float], t: float) -> str:
    rows = []
    for name, th, sd in zip(est.names, est.theta, est.theta_std, strict=True):
        tr = truth.get(name, float("nan"))
        err = (th - tr) / tr * 100 if tr else float("nan")
        rows.append((name, float(th), float(sd), tr, err))
    d = est.rls.diagnostics(condition=False)
    head = (f"t = {t:6.1f} s  samples {d.samples}  unexcited: "
            f"{','.join(d.unexcited) or 'none'}  change alarm: "
            f"{','.join(d.alarm_channels) or 'none'}")
    return head + "\n" + table(("coefficient", "estimate", "std", "truth", "error %"), rows)


def run(args: argparse.Namespace) -> int:
    """Build the nodes, spin until the protocol ends, print and save."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if args.domain_id is not None:
        os.environ["ROS_DOMAIN_ID"] = str(args.domain_id)
    else:
        os.environ.setdefault("ROS_DOMAIN_ID", "77")
    import rclpy
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from dampest_ros.core.simulate import Effects, true_vehicle
    from dampest_ros.io.yaml_io import load_vehicle, read_mapping
    from dampest_ros.ros.controller_node import ControllerNode
    from dampest_ros.ros.estimator_node import EstimatorNode
    from dampest_ros.ros.preprocess_node import PreprocessNode
    from dampest_ros.ros.sim_node import SimNode

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    vehicle = load_vehicle(args.vehicle)
    effects = Effects.from_dict(read_mapping(args.effects)) if args.effects else Effects()
    truth_v = true_vehicle(vehicle, effects)
    truth = dict(zip(truth_v.damping.parameter_names, truth_v.theta, strict=True))
    if effects.damping_change_time >= 0:
        print(f"(the quadratic damping changes by x{effects.damping_change_factor} at "
              f"t = {effects.damping_change_time} s; the table's truth is before the change)")

    context = rclpy.Context()
    rclpy.init(context=context)
    P = Parameter
    sim = SimNode(context=context, parameter_overrides=[
        P("vehicle", value=args.vehicle), P("protocol", value=args.protocol),
        P("duration", value=float(args.duration)), P("seed", value=int(args.seed)),
        P("rate_factor", value=float(args.rate_factor)), P("effects", value=args.effects)])
    pre = PreprocessNode(context=context, parameter_overrides=[P("vehicle", value=args.vehicle)])
    est = EstimatorNode(context=context, parameter_overrides=[
        P("vehicle", value=args.vehicle), P("use_sim_time", value=True),
        P("forgetting_factor", value=float(args.forgetting_factor)),
        P("save_path", value=str(out / "model.yaml"))])
    nodes: list[Any] = [sim, pre, est]
    ctrl = None
    if args.controller != "off":
        remap = [] if args.controller == "fly" else ["--ros-args", "-r",
                                                     "cmd_wrench:=controller/cmd_wrench"]
        reference = [float(x) for x in args.reference]
        ctrl = ControllerNode(context=context, cli_args=remap or None, parameter_overrides=[
            P("vehicle", value=args.vehicle), P("reference", value=reference)])
        nodes.append(ctrl)
    ex = (MultiThreadedExecutor(num_threads=2, context=context) if args.executor == "multi"
          else SingleThreadedExecutor(context=context))
    for n in nodes:
        ex.add_node(n)
    cpu_est = _time_callbacks(est)
    print(f"dampest live: {vehicle.name}, protocol {args.protocol}, {args.duration:.0f} s at "
          f"{args.rate_factor:g}x real time, λ = {args.forgetting_factor}, "
          f"{args.executor} executor, controller {args.controller}")
    t0, c0 = time.monotonic(), time.process_time()
    next_print = args.every
    try:
        while not sim.live.done:
            ex.spin_once(timeout_sec=0.05)
            if est.estimator.last_sample_t >= next_print:
                print("\n" + _table(est.estimator, truth, est.estimator.last_sample_t),
                      flush=True)
                next_print += args.every
        end = time.monotonic() + 2.0
        while time.monotonic() < end:  # drain the queues
            ex.spin_once(timeout_sec=0.05)
    except KeyboardInterrupt:
        print("\ninterrupted: saving what was identified so far")
    wall, cpu = time.monotonic() - t0, time.process_time() - c0
    e = est.estimator
    e.process(force=True)
    est.version += 1
    path = e.save(out / "model.yaml", est.version)
    print("\n" + _table(e, truth, sim.live.t))
    used = max(e.counts["used"], 1)
    print(f"\n{sim.live.t:.0f} s simulated in {wall:.1f} s: {sim.live.t / wall:.2f}x real time "
          f"({cpu:.1f} s CPU); {sim.published} sensor messages, {pre.published} samples, "
          f"{e.counts['used']} used by the RLS")
    print(f"estimator callbacks: {cpu_est['cpu'] / used * 1e6:.0f} µs CPU per sample "
          f"(4 messages; rclpy's own receive cost, ~200 µs per message, comes on top)")
    lost = pre.pre.counts
    print(f"preprocessing: {lost['imu']} IMU, {lost['thrusters']} thruster messages; "
          f"{lost['imu_gaps']} IMU gaps, {lost['rejected_stale']} stale, "
          f"{lost['clock_resets']} clock resets")
    if ctrl is not None:
        print(f"controller: {ctrl.commands} commands, model version {ctrl.client.version}")
    print(f"wrote {path}")
    ex.shutdown()
    for n in nodes:
        n.destroy_node()
    rclpy.try_shutdown(context=context)
    return 0


def _time_callbacks(node: Any) -> dict[str, float]:
    """Accumulate the thread CPU time spent in a node's subscription callbacks."""
    acc = {"cpu": 0.0}
    for sub in node.subscriptions:
        cb = sub.callback

        def timed(msg: Any, cb: Any = cb) -> None:
            c = time.thread_time()
            cb(msg)
            acc["cpu"] += time.thread_time() - c
        sub.callback = timed
    return acc
