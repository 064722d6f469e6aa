"""The work of dampest live and dampest demo (their options and --help:
cli/live_options.py): the pipeline, the tables, the report."""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.cli.common import check_outputs, table
from dampest_ros.core.identification.model import Model
from dampest_ros.core.online.estimator import EstimatorConfig, OnlineEstimator, parameter_scale
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.preprocess import DataError
from dampest_ros.core.simulation.control import DEFAULT_BANDWIDTH
from dampest_ros.core.simulation.effects import Effects, true_vehicle
from dampest_ros.io.yaml_io import save_model

FloatArray = NDArray[np.float64]

#: Tracking comparison: sine references in surge, heave and yaw (FRD), amplitudes (m/s,
#: rad/s) and angular frequencies (rad/s); the first TRACK_SKIP seconds are the transient.
TRACK_DOFS = (0, 2, 5)
TRACK_AMPLITUDE = (0.5, 0.2, 0.4)
TRACK_OMEGA = (0.3, 0.2, 0.25)
TRACK_DT = 0.02
TRACK_SKIP = 10.0


@dataclass
class History:
    """The estimate over time: times (s, simulation), θ and σ(θ) rows of shape (p,)."""

    t: list[float] = field(default_factory=list)
    theta: list[FloatArray] = field(default_factory=list)
    std: list[FloatArray] = field(default_factory=list)

    def add(self, t: float, theta: FloatArray, std: FloatArray) -> None:
        """One row (copies of θ and σ)."""
        self.t.append(float(t))
        self.theta.append(np.array(theta, dtype=float))
        self.std.append(np.array(std, dtype=float))

    def arrays(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """t (K,), θ (K, p), σ (K, p)."""
        return np.array(self.t), np.array(self.theta), np.array(self.std)


@dataclass
class Flight:
    """What an online run leaves: the estimator, the estimate over time, the saved model."""

    estimator: OnlineEstimator
    history: History
    t: float  #: simulated seconds
    wall: float  #: wall-clock seconds
    path: Path  #: the saved model file
    summary: str  #: pace and message counts, printed
    bandwidth: float  #: of the controller node (rad/s)


def _table(est: OnlineEstimator, truth: dict[str, float], t: float,
           batch: FloatArray | None = None, coverage: FloatArray | None = None) -> str:
    """The estimate against the truth (and the batch estimate, the ±2σ coverage) as a text
    table."""
    rows = []
    for j, (name, th, sd) in enumerate(zip(est.names, est.theta, est.theta_std, strict=True)):
        tr = truth.get(name, float("nan"))
        row: list[object] = [name, float(th), float(sd), tr, _error(th, tr)]
        if batch is not None:
            row += [float(batch[j]), _error(batch[j], tr)]
        if coverage is not None:
            row.append(float(100 * coverage[j]))
        rows.append(row)
    d = est.rls.diagnostics(condition=False)
    head = (f"t = {t:6.1f} s  samples {d.samples}  unexcited: "
            f"{','.join(d.unexcited) or 'none'}  change alarm: "
            f"{','.join(d.alarm_channels) or 'none'}")
    header = ["coefficient", "estimate", "std", "truth", "error %"]
    if batch is not None:
        header += ["batch", "batch error %"]
    if coverage is not None:
        header.append("±2σ cover %")
    return head + "\n" + table(header, rows)


def _error(value: float, truth: float) -> float:
    """Relative error in % (NaN for a zero or unknown truth)."""
    return float((value - truth) / truth * 100) if truth and np.isfinite(truth) else np.nan


def run(args: argparse.Namespace) -> int:
    """Fly the pipeline, print and save; then the batch column and the report."""
    from dampest_ros.io.yaml_io import load_vehicle, read_mapping
    from dampest_ros.report.convergence import band_coverage

    check_outputs(args, {}, ("out",))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    vehicle = load_vehicle(args.vehicle)
    prior = Path(args.prior) if args.prior else write_prior(vehicle, args.prior_factor,
                                                            out / "prior.yaml")
    effects = Effects.from_dict(read_mapping(args.effects)) if args.effects else Effects()
    truth_v = true_vehicle(vehicle, effects)
    truth = dict(zip(truth_v.damping.parameter_names, truth_v.theta, strict=True))
    if effects.damping_change_time >= 0:
        print(f"(the quadratic damping changes by x{effects.damping_change_factor} at "
              f"t = {effects.damping_change_time} s; the table's truth is before the change)")
    flight = _fly(args, vehicle.name, truth, prior, out / "model.yaml")
    e = flight.estimator
    batch = None
    if args.batch:
        from dampest_ros.core.identification.batch import FitOptions, fit
        from dampest_ros.core.online.sample import to_samples
        c = time.perf_counter()
        try:
            samples = to_samples(e.samples_log, e.cfg.rate)
            batch = fit(samples, e.model, e.body, FitOptions(cutoff=e.cfg.cutoff),
                        prior=e.prior_theta).theta
            print(f"\nbatch least squares on the same {len(samples)} samples: "
                  f"{time.perf_counter() - c:.1f} s")
        except (ConfigError, DataError) as exc:  # e.g. interrupted before enough samples
            print(f"\nno batch estimate: {exc}")
    ht, theta, std = flight.history.arrays()
    coverage = band_coverage(ht, theta, std, np.array([truth.get(n, np.nan) for n in e.names]))
    print("\n" + _table(e, truth, flight.t, batch, coverage))
    errors = [abs(_error(th, truth.get(n, np.nan))) for n, th in zip(e.names, e.theta,
                                                                      strict=True)]
    if np.any(np.isfinite(errors)):
        worst = int(np.nanargmax(errors))
        print(f"largest relative error of a nonzero coefficient: {errors[worst]:.2f} % "
              f"({e.names[worst]})")
    if np.any(np.isfinite(coverage)):
        low = int(np.nanargmin(coverage))
        print(f"±2σ coverage of the truth over the second half of the run: "
              f"{100 * np.nanmean(coverage):.0f} % on average, lowest {100 * coverage[low]:.0f} "
              f"% ({e.names[low]}) (about 95 % when σ is right)")
    print(flight.summary)
    if args.report:
        c = time.perf_counter()
        index = _report(args, out / "report", flight, truth, batch, vehicle, effects, prior)
        print(f"report: {index} ({time.perf_counter() - c:.1f} s)")
    print(f"model: {flight.path}\n(offline identification from a bag: dampest simulate "
          "... --out BAG, then dampest identify BAG)")
    return 0


def write_prior(vehicle: Vehicle, factor: float, path: Path) -> Path:
    """A deliberately wrong prior model file: ``factor`` × the vehicle's nominal coefficients,
    standard deviations as estimator_node gives a prior without them (ten times the scale of
    that mean): wide, so that the data decide.

    Parameters
    ----------
    vehicle : Vehicle
    factor : float
        > 0.
    path : Path
        Where the model YAML is written (atomically).

    Returns
    -------
    Path
    """
    if not factor > 0:
        raise ConfigError("prior_factor", f"must be > 0, got {factor}")
    theta = factor * vehicle.theta
    std = EstimatorConfig().prior_scale * parameter_scale(vehicle.damping, theta)
    return save_model(path, Model(
        vehicle.damping.parameter_names, theta, std, vehicle.body.M, damping=vehicle.damping,
        extra={"source": f"{factor:g} x the nominal damping of {vehicle.name}"},
        M_A=vehicle.body.added_mass, added_mass_terms=vehicle.body.added_mass_terms,
        identity=vehicle.identity))


@dataclass
class Pipeline:
    """The nodes of the online pipeline on one executor (see :func:`build_pipeline`)."""

    sim: Any
    pre: Any
    est: Any
    ctrl: Any | None
    executor: Any

    @property
    def nodes(self) -> list[Any]:
        """The nodes, the controller included when there is one."""
        return [n for n in (self.sim, self.pre, self.est, self.ctrl) if n is not None]

    def close(self) -> None:
        """Shut the executor down and destroy the nodes (the context stays)."""
        self.executor.shutdown()
        for n in self.nodes:
            n.destroy_node()


def build_pipeline(args: argparse.Namespace, prior: Path, path: Path, context: Any
                   ) -> Pipeline:
    """sim_node, preprocess_node, estimator_node (prior model file ``prior``, saving to
    ``path``) and controller_node as ``args`` (the options of :func:`add_options`) configure
    them, on one executor in ``context`` (an initialised rclpy context)."""
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from dampest_ros.ros.controller_node import ControllerNode
    from dampest_ros.ros.estimator_node import EstimatorNode
    from dampest_ros.ros.preprocess_node import PreprocessNode
    from dampest_ros.ros.sim_node import SimNode

    P = Parameter
    sim = SimNode(context=context, parameter_overrides=[
        P("vehicle", value=args.vehicle), P("protocol", value=args.protocol),
        P("duration", value=float(args.duration)), P("seed", value=int(args.seed)),
        P("rate_factor", value=float(args.rate_factor)), P("effects", value=args.effects)])
    pre = PreprocessNode(context=context, parameter_overrides=[P("vehicle", value=args.vehicle)])
    est = EstimatorNode(keep_samples=bool(args.batch), context=context, parameter_overrides=[
        P("vehicle", value=args.vehicle), P("use_sim_time", value=True),
        P("forgetting_factor", value=float(args.forgetting_factor)),
        P("prior", value=str(prior)), P("save_path", value=str(path)),
        P("resume", value=False)])  # every run from the prior, not from the last run's model
    ctrl = None
    if args.controller != "off":
        remap = [] if args.controller == "fly" else ["--ros-args", "-r",
                                                     "cmd_wrench:=controller/cmd_wrench"]
        reference = [float(x) for x in args.reference]
        ctrl = ControllerNode(context=context, cli_args=remap or None, parameter_overrides=[
            P("vehicle", value=args.vehicle), P("reference", value=reference)])
    ex = (MultiThreadedExecutor(num_threads=2, context=context) if args.executor == "multi"
          else SingleThreadedExecutor(context=context))
    pipe = Pipeline(sim, pre, est, ctrl, ex)
    for n in pipe.nodes:
        ex.add_node(n)
    return pipe


def _fly(args: argparse.Namespace, vehicle_name: str, truth: dict[str, float], prior: Path,
         path: Path) -> Flight:
    """Build the nodes (the estimator from the prior model file ``prior``), spin until the
    protocol ends (tables at 0 s and every ``args.every`` s, the estimate recorded every
    ``args.record_every`` s), save the model to ``path``."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if args.domain_id is not None:
        os.environ["ROS_DOMAIN_ID"] = str(args.domain_id)
    else:
        os.environ.setdefault("ROS_DOMAIN_ID", "77")
    import rclpy

    from dampest_ros.ros.common import signals_held

    context = rclpy.Context()
    rclpy.init(context=context)
    pipe = build_pipeline(args, prior, path, context)
    sim, pre, est, ctrl, ex = pipe.sim, pipe.pre, pipe.est, pipe.ctrl, pipe.executor
    cpu_est = _time_callbacks(est)
    print(f"dampest {getattr(args, 'command', 'live')}: {vehicle_name}, protocol "
          f"{args.protocol}, {args.duration:.0f} s at {args.rate_factor:g}x real time, "
          f"λ = {args.forgetting_factor}, {args.executor} executor, controller {args.controller}"
          f"\nprior: {prior}")
    e = est.estimator
    history = History()
    history.add(0.0, e.theta, e.theta_std)  # the prior
    print("\n" + _table(e, truth, 0.0), flush=True)
    t0, c0 = time.monotonic(), time.process_time()
    next_print, next_record = args.every, args.record_every
    try:
        while not sim.live.done:
            ex.spin_once(timeout_sec=0.05)
            if e.last_sample_t >= next_record:
                history.add(e.last_sample_t, e.theta, e.theta_std)
                next_record = e.last_sample_t + args.record_every
            if e.last_sample_t >= next_print:
                print("\n" + _table(e, truth, e.last_sample_t), flush=True)
                next_print += args.every
        end = time.monotonic() + 2.0
        while time.monotonic() < end:  # drain the queues
            ex.spin_once(timeout_sec=0.05)
    except KeyboardInterrupt:
        print("\ninterrupted: saving what was identified so far")
    with signals_held("dampest live"):  # a second Ctrl-C must not cut the save short
        wall, cpu = time.monotonic() - t0, time.process_time() - c0
        e.process(force=True)
        history.add(e.last_sample_t, e.theta, e.theta_std)
        est.version += 1
        saved = save_model(path, e.to_model(est.version))
        used = max(e.counts["used"], 1)
        lost = pre.pre.counts
        lines = [
            f"\n{sim.live.t:.0f} s simulated in {wall:.1f} s: {sim.live.t / wall:.2f}x real time "
            f"({cpu:.1f} s CPU); {sim.published} sensor messages, {pre.published} samples, "
            f"{e.counts['used']} used by the RLS",
            f"estimator callbacks: {cpu_est['cpu'] / used * 1e6:.0f} µs CPU per sample "
            f"(4 messages; rclpy's own wait and dispatch come on top: make bench compares the "
            f"node with a bare subscriber)",
            f"preprocessing: {lost['imu']} IMU, {lost['thrusters']} thruster messages; "
            f"{lost['imu_gaps']} IMU gaps, {lost['rejected_stale']} stale, "
            f"{lost['clock_resets']} clock resets"]
        if ctrl is not None:
            lines.append(f"controller: {ctrl.commands} commands, model version "
                         f"{ctrl.client.version}")
        flight = Flight(e, history, sim.live.t, wall, saved, "\n".join(lines),
                        ctrl.p("bandwidth") if ctrl is not None else DEFAULT_BANDWIDTH)
        pipe.close()
        rclpy.try_shutdown(context=context)
    return flight


def _report(args: argparse.Namespace, out: Path, flight: Flight,
            truth: dict[str, float], batch: FloatArray | None, vehicle: Vehicle,
            effects: Effects, prior: Path) -> Path:
    """Tracking runs without and with the saved model's feed-forward, then the report."""
    from dampest_ros.client import ModelClient
    from dampest_ros.core.simulation.control import VelocityPI
    from dampest_ros.core.simulation.simulate import Simulator, track
    from dampest_ros.report.convergence import Tracking, rms_by_unit, write_convergence_report
    from dampest_ros.report.figures import parameter_units

    e = flight.estimator
    client = ModelClient.from_yaml(flight.path)
    bandwidth = flight.bandwidth
    n = max(2, round(args.tracking_seconds / TRACK_DT))
    t = TRACK_DT * np.arange(n)
    ref = np.zeros((n, 6))
    ref[:, TRACK_DOFS] = np.asarray(TRACK_AMPLITUDE) * np.sin(np.outer(t, TRACK_OMEGA))
    skip = min(round(TRACK_SKIP / TRACK_DT), n // 2)
    runs, rms = {}, {}
    for label, ff in (("PI", None), ("PI + D(ν)ν + C(ν)ν", client.feedforward)):
        sim = Simulator(vehicle, effects, dt=TRACK_DT, record=False)
        runs[label] = track(sim, VelocityPI.for_vehicle(vehicle, bandwidth, ff), ref, TRACK_DT)
        rms[label] = rms_by_unit(ref, runs[label], TRACK_DOFS, skip)
    with_model = rms["PI + D(ν)ν + C(ν)ν"]
    print("velocity tracking on the simulator (sines in u, w, r; RMS after "
          f"{skip * TRACK_DT:.0f} s, PI → with the model): " + ", ".join(
              f"{rms['PI'][u]:.4f} → {with_model[u]:.4f} {u} ({rms['PI'][u] / with_model[u]:.1f}x"
              " lower)" for u in with_model))
    tr = Tracking(t, ref, runs, rms, TRACK_DOFS, skip, bandwidth)
    ht, theta, std = flight.history.arrays()
    groups = {term.kind: term.parameter_names for term in e.model.terms}
    summary = [("vehicle", vehicle.name), ("protocol", args.protocol),
               ("simulated", f"{flight.t:.0f} s in {flight.wall:.0f} s wall clock"),
               ("forgetting factor λ", f"{args.forgetting_factor:g}"),
               ("prior", str(prior) if args.prior else f"{args.prior_factor:g} × the "
                "nominal coefficients, std 10 × that"),
               ("samples used by the RLS", str(e.counts["used"])),
               ("effects", args.effects or "none"), ("model", str(flight.path))]
    return write_convergence_report(out, e.names, ht, theta, std, groups, truth, batch, tr,
                                    summary, title=f"Online identification: {vehicle.name}",
                                    units=parameter_units(e.model))


def _time_callbacks(node: Any) -> dict[str, float]:
    """Accumulate the thread CPU time spent in a node's subscription callbacks."""
    from dampest_ros.ros.common import same_arity

    acc = {"cpu": 0.0}

    def timed(cb: Any) -> Any:
        def run(*args: Any) -> None:
            c = time.thread_time()
            cb(*args)
            acc["cpu"] += time.thread_time() - c

        return same_arity(cb, run)

    for sub in node.subscriptions:
        sub.callback = timed(sub.callback)
    return acc
