"""dampest arm: dynamic parameters and joint friction of an arm (revolute joints).

design: finite-Fourier-series excitation optimised for the condition number of the base
regressor (friction columns included) or its D-optimality (log det of the column-normalised
information matrix) within position, velocity, acceleration and torque limits. simulate:
MuJoCo tracks a trajectory with computed-torque control; writes a rosbag2 (MCAP) bag of
sensor_msgs/JointState with quantised encoders and a noisy torque sensor, and the truth.
identify: base parameters (OLS, WLS, physically consistent) with joint damping and friction
from a bag, validated on another bag.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from dampest_ros.cli.common import Elapsed, check_outputs, describe, table

if TYPE_CHECKING:
    import numpy as np

EXAMPLES = {
    "design": "  dampest arm design --arm ur5 --harmonics 5 --base-frequency 0.1 "
              "--out excite.yaml\n  dampest arm design --arm ur5 --objective dopt "
              "--out excite_dopt.yaml",
    "simulate": "  dampest arm simulate --trajectory excite.yaml --duration 60 --seed 1 "
                "--out bags/arm_train\n  dampest arm simulate --random 7 --duration 20 "
                "--seed 2 --out bags/arm_val",
    "identify": "  dampest arm identify bags/arm_train --validate bags/arm_val "
                "--out arm_params.yaml",
}

HELP = {
    "design": "optimise an FFS excitation trajectory for the base regressor's conditioning "
              "(--objective cond) or D-optimality (--objective dopt)",
    "simulate": "run a trajectory on the MuJoCo arm and write a JointState bag",
    "identify": "identify base parameters and joint friction from a JointState bag or a CSV "
                "log",
}


def _arm_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--lock", default="", metavar="JOINT[,JOINT]",
                   help="joints held fixed at 0 (a gripper's), for a URDF without an MJCF "
                        "beside it; identify --out records them")
    p.add_argument("--arm", default="ur5", metavar="NAME|URDF",
                   help="arm preset (ur5, shipped) or a URDF path (revolute and continuous "
                        "joints); an MJCF beside it (same stem, .xml) is the simulated arm, "
                        "without one it is written from the URDF (its <dynamics damping "
                        "friction>, no armature) (default: ur5)")


def _limit_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--span", type=float, default=1.0, metavar="RAD",
                   help="position range: +-SPAN around the middle of each joint's own "
                        "limits, within them; a continuous joint: around 0 (default: 1.0)")
    p.add_argument("--velocity", type=float, default=1.0, metavar="RAD/S",
                   help="|joint velocity| limit (default: 1.0; never above the URDF's)")
    p.add_argument("--acceleration", type=float, default=4.0, metavar="RAD/S2",
                   help="|joint acceleration| limit (default: 4.0)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of dampest arm and its sub-commands."""
    describe(p, __doc__, "example:\n" + "\n".join(EXAMPLES.values()))
    sub = p.add_subparsers(dest="arm_command", metavar="ARM_COMMAND", required=True,
                           help="design, simulate or identify (each has its --help)")
    d = sub.add_parser("design", help=HELP["design"], description=HELP["design"],
                       epilog="example:\n" + EXAMPLES["design"],
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    _arm_option(d)
    d.add_argument("--harmonics", type=int, default=5, help="N harmonics (default: 5)")
    d.add_argument("--base-frequency", type=float, default=0.1, metavar="HZ",
                   help="base frequency; the period is its inverse (default: 0.1)")
    _limit_options(d)
    d.add_argument("--iterations", type=int, default=40,
                   help="optimiser iterations (default: 40; about 2 s each)")
    d.add_argument("--objective", choices=("cond", "dopt"), default="cond",
                   help="cond: minimise the base regressor's condition number (balance of "
                        "its directions); dopt: maximise the log det of its column-normalised "
                        "information matrix (D-optimal: the smallest confidence volume, every "
                        "direction's information counted) (default: cond)")
    d.add_argument("--seed", type=int, default=0, help="seed of the random start (default: 0)")
    d.add_argument("--out", required=True, metavar="YAML", help="trajectory file to write")

    s = sub.add_parser("simulate", help=HELP["simulate"], description=HELP["simulate"],
                       epilog="example:\n" + EXAMPLES["simulate"],
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    _arm_option(s)
    which = s.add_mutually_exclusive_group(required=True)
    which.add_argument("--trajectory", metavar="YAML",
                       help="trajectory file of 'dampest arm design' (checked against the "
                            "limits it holds)")
    which.add_argument("--random", type=int, metavar="SEED",
                       help="random FFS coefficients (4 harmonics, 0.125 Hz) within the "
                            "design limits instead (a validation trajectory)")
    _limit_options(s)
    s.add_argument("--duration", type=float, default=60.0, metavar="S",
                   help="simulated seconds (default: 60)")
    s.add_argument("--rate", type=float, default=1000.0, metavar="HZ",
                   help="JointState rate, 1000 divided by an integer (default: 1000)")
    s.add_argument("--noise", choices=("realistic", "scaled", "none"), default="realistic",
                   help="sensors: 20-bit encoders and torque noise 0.4/0.4/0.3/0.1/0.1/0.1 "
                        "N m with offsets (realistic, default: a UR5's six joints), the same "
                        "relative to each joint's effort limit (scaled: 0.27 %%, offsets "
                        "0.2 %%; any arm) or exact (none)")
    s.add_argument("--payload", type=float, nargs=2, metavar=("KG", "AT_S"),
                   help="attach a point mass of KG at the last link's origin at AT_S seconds")
    s.add_argument("--seed", type=int, default=1, help="seed of the sensor noise (default: 1)")
    s.add_argument("--out", required=True, metavar="BAG",
                   help="bag directory to create (must not exist)")

    i = sub.add_parser("identify", help=HELP["identify"], description=HELP["identify"] + (
        ".\n\nJittered stamps are resampled onto a uniform grid; a step over 1.75 sample\n"
        "periods is a gap, and each gap-free stretch is filtered on its own (the count\n"
        "is printed). A stamp over 1.75 periods before the one recorded before it is a\n"
        "clock jump: named (sample, stamp, seconds back), the record split there."),
                       epilog="example:\n" + EXAMPLES["identify"],
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    i.add_argument("bag", metavar="LOG", help="sensor_msgs/JointState in a rosbag2 bag or a "
                   "ROS 1 .bag file, or a CSV log: time, <joint>.q (rad), <joint>.qd "
                   "(rad/s, optional), <joint>.tau (N m), joints by name")
    i.add_argument("--columns", metavar="YAML",
                   help="column map of a CSV log ('their name: our name', at the top level "
                        "or under 'columns:'; ours: time, <joint>.q, <joint>.qd, <joint>.tau)")
    _arm_option(i)
    i.add_argument("--topic", metavar="TOPIC",
                   help="JointState topic (default: joint_states, or the only one)")
    i.add_argument("--validate", metavar="LOG",
                   help="a log (bag or CSV) of another trajectory: torque RMSE per joint of "
                        "the identified and the nominal parameters against the noise floor")
    i.add_argument("--cutoff", type=float, default=10.0, metavar="HZ",
                   help="zero-phase low-pass of q and torque (default: 10)")
    i.add_argument("--rate-out", type=float, default=50.0, metavar="HZ",
                   help="rate the filtered data are decimated to (default: 50)")
    i.add_argument("--min-speed", type=float, default=0.1, metavar="RAD/S",
                   help="rows of a joint slower than this are not used: dry friction is "
                        "undefined at rest (default: 0.1)")
    i.add_argument("--coulomb-width", type=float, default=0.0, metavar="RAD/S",
                   help="dry friction as Fc tanh(qd / W), smooth through a reversal, instead "
                        "of Fc sign(qd) (default: 0, the sign); the model file records it")
    i.add_argument("--mapping", action="store_true",
                   help="print how each base parameter combines the full parameters")
    i.add_argument("--out", metavar="YAML",
                   help="write the arm model file (WLS base parameters with sigma, the OLS "
                        "and consistent fits beside them; arm_estimator_node's prior)")
    i.add_argument("--report", metavar="DIR",
                   help="write an HTML report to DIR: index.html with the trajectory, "
                        "measured vs model torque with the residual, the base parameters "
                        "with sigma vs nominal (and the validation torque with --validate)")


def run(args: argparse.Namespace) -> int:
    """Dispatch to the chosen arm command (after checking that Pinocchio and MuJoCo load)."""
    import importlib

    for module, pip in (("pinocchio", "pin==4.1.0"), ("mujoco", "mujoco==4.0.0")):
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise ValueError(f"dampest arm needs {module} ({exc}); install it with "
                             f"'pip install {pip}' (pinned in requirements/lock.txt)") from None
    return {"design": _design, "simulate": _simulate, "identify": _identify}[
        args.arm_command](args)


def _limits(args: argparse.Namespace, arm: Any) -> Any:
    from dampest_ros.core.arm.design import default_limits

    for name in ("span", "velocity", "acceleration"):
        if not getattr(args, name) > 0:
            raise ValueError(f"--{name} must be > 0, got {getattr(args, name)}")
    return default_limits(arm, span=args.span, velocity=args.velocity,
                          acceleration=args.acceleration)


def _design(args: argparse.Namespace) -> int:
    import math
    import time
    from pathlib import Path

    from dampest_ros.core.arm.base import base_parameters
    from dampest_ros.core.arm.design import design_excitation
    from dampest_ros.core.arm.regressor import full_parameters
    from dampest_ros.io.arm import joint_list, load_arm, save_trajectory

    if args.harmonics < 1 or not args.base_frequency > 0 or args.iterations < 0:
        raise ValueError("--harmonics must be >= 1, --base-frequency > 0, --iterations >= 0")
    check_outputs(args, {"out": "trajectory.yaml"})
    if Path(args.out).exists():
        raise FileExistsError(f"{args.out} exists; choose a new --out")
    arm = load_arm(args.arm, lock=joint_list(args.lock))
    limits = _limits(args, arm.model)
    base = base_parameters(arm.model)
    t0 = time.perf_counter()
    with Elapsed(f"designing the excitation of {args.arm} ({args.iterations} iterations "
                 "at most)"):
        d = design_excitation(arm.model, base, full_parameters(arm.model, arm.dynamics),
                              limits, harmonics=args.harmonics,
                              base_frequency=args.base_frequency, seed=args.seed,
                              iterations=args.iterations, objective=args.objective)
    save_trajectory(args.out, d.trajectory, limits, {
        "arm": str(args.arm), "objective": d.objective, "cond": d.cond,
        "cond_start": d.cond_start, "cond_random_median": d.cond_random, "logdet": d.logdet,
        "logdet_start": d.logdet_start, "logdet_random_median": d.logdet_random})
    print(f"wrote {args.out} in {time.perf_counter() - t0:.1f} s ({d.iterations} iterations)"
          f": {base.size} base parameters, period {d.trajectory.period:g} s")
    print(table(("base regressor condition number", "value"),
                [("random FFS within the limits (median)", d.cond_random),
                 ("start (random)", d.cond_start), ("designed", d.cond),
                 ("improvement over random", d.cond_random / d.cond)]))
    print(table(("log det of the column-normalised information matrix", "value"),
                [("random FFS within the limits (median)", d.logdet_random),
                 ("start (random)", d.logdet_start), ("designed", d.logdet),
                 ("gain over random per parameter (x, geometric mean of eigenvalues)",
                  math.exp((d.logdet - d.logdet_random) / base.size))]))
    return 0


def _simulate(args: argparse.Namespace) -> int:
    import time
    from pathlib import Path

    import numpy as np

    from dampest_ros.core.arm.base import base_parameters
    from dampest_ros.core.arm.design import regressor_cond, within_limits
    from dampest_ros.core.arm.ffs import random_trajectory
    from dampest_ros.core.arm.regressor import full_parameters, regressor
    from dampest_ros.core.arm.simulate import (
        REALISTIC,
        ArmSensors,
        scaled_sensors,
        simulate_arm,
    )
    from dampest_ros.io.arm import (
        joint_list,
        joint_series,
        load_arm,
        load_trajectory,
        write_joint_bag,
    )

    out = Path(args.out)
    if out.exists():
        raise FileExistsError(f"{out} exists; choose a new --out")
    check_outputs(args, {}, ("out",))
    if not args.duration > 0:
        raise ValueError(f"--duration must be > 0, got {args.duration}")
    if not 0 < args.rate <= 1000:
        raise ValueError(f"--rate must be 1000 Hz divided by a whole number (1000, 500, "
                         f"250, ...), got {args.rate:g}")
    arm = load_arm(args.arm, lock=joint_list(args.lock))
    limits = _limits(args, arm.model)
    if args.trajectory:
        traj, held = load_trajectory(args.trajectory, arm.model.n)
        limits = held or limits
    else:
        rng = np.random.default_rng(args.random)
        traj = within_limits(arm.model, random_trajectory(
            0.5 * (limits.lower + limits.upper), 4, 0.125, limits.velocity, rng), limits,
            full_parameters(arm.model, arm.dynamics))
    t = np.linspace(0.0, traj.period, 20 * 40 * traj.harmonics, endpoint=False)
    q, qd, qdd = traj.evaluate(t)
    nominal = full_parameters(arm.model, arm.dynamics)
    bad = limits.violations(q, qd, qdd, regressor(arm.model, q, qd, qdd) @ nominal,
                            arm.model.names)
    if bad:
        raise ValueError(f"trajectory {args.trajectory or 'random'} violates its limits: "
                         + "; ".join(bad))
    if args.noise == "realistic" and arm.model.n != np.size(REALISTIC.torque_sigma):
        raise ValueError(f"--noise realistic is a UR5's sensors (6 joints); {args.arm} has "
                         f"{arm.model.n}: use --noise scaled (the same relative to each "
                         "joint's effort limit) or none")
    sensors = {"realistic": REALISTIC, "scaled": scaled_sensors(arm.model),
               "none": ArmSensors()}[args.noise]
    payload = None if args.payload is None else (float(args.payload[0]),
                                                 float(args.payload[1]))
    t0 = time.perf_counter()
    run = simulate_arm(arm.mjcf, arm.model, arm.dynamics, traj, args.duration, args.rate,
                       sensors, seed=args.seed, payload=payload)
    names = arm.model.names
    write_joint_bag(out, joint_series(run.t, names, run.position, run.velocity, run.effort),
                    joint_series(run.t, names, run.q, run.qd, run.tau))
    print(f"wrote {out} in {time.perf_counter() - t0:.1f} s: {args.duration:g} s of "
          f"{args.arm} at {args.rate:g} Hz ({len(run.t)} JointState messages on joint_states, "
          "truth on truth/joint_states); base regressor condition number of the trajectory "
          f"{regressor_cond(arm.model, base_parameters(arm.model), traj):.4g}")
    print(table(("joint", "|q - q0| max rad", "|qd| max rad/s", "|tau| max N m",
                 "noise N m", "offset N m"),
                [(n, float(np.abs(run.q[:, j] - traj.q0[j]).max()),
                  float(np.abs(run.qd[:, j]).max()), float(np.abs(run.tau[:, j]).max()),
                  float(np.broadcast_to(sensors.torque_sigma, (len(names),))[j]),
                  float(np.broadcast_to(sensors.torque_offset, (len(names),))[j]))
                 for j, n in enumerate(names)]))
    return 0


def _identify(args: argparse.Namespace) -> int:
    import time

    import numpy as np

    from dampest_ros.core.arm.base import base_parameters
    from dampest_ros.core.arm.fit import pseudo_inertia_eigenvalues
    from dampest_ros.core.arm.identify import (
        IdentifyConfig,
        filter_stretches,
        identify_arm,
        predict,
        torque_rmse,
    )
    from dampest_ros.core.arm.regressor import full_parameters
    from dampest_ros.core.signals.resample import increasing_runs, interpolate
    from dampest_ros.io.arm import joint_list, load_arm

    check_outputs(args, {"out": "arm_model.yaml"}, ("report",))
    if not (np.isfinite(args.coulomb_width) and args.coulomb_width >= 0):
        raise ValueError(f"--coulomb-width {args.coulomb_width:g}: give a width >= 0 rad/s "
                         "(0: Fc sign(qd))")
    cfg = IdentifyConfig(cutoff=args.cutoff, rate_out=args.rate_out, min_speed=args.min_speed,
                         coulomb_width=args.coulomb_width)
    arm = load_arm(args.arm, lock=joint_list(args.lock))
    names = arm.model.names
    t0 = time.perf_counter()
    data, _ = _read_joints(args.bag, names, args)
    val = _read_joints(args.validate, names, args) if args.validate else None
    t1 = time.perf_counter()
    base = base_parameters(arm.model)
    nominal = full_parameters(arm.model, arm.dynamics)
    filtered, stretches = filter_stretches(data.t, data.position, data.effort, cfg)
    res = identify_arm(arm.model, base, filtered, nominal, cfg)
    t2 = time.perf_counter()
    print(f"{args.bag}: {len(data.t)} samples of {len(names)} joints on {data.topic} "
          f"(read {t1 - t0:.1f} s, identified {t2 - t1:.1f} s); {base.size} base parameters, "
          f"rows used per joint {res.rows.tolist()}")
    if stretches.describe():
        print(f"{args.bag}: {stretches.describe()}")
    ind = [base.names[k] for k in base.independent]
    print(table(("base parameter", "OLS", "WLS", "sigma", "consistent", "nominal"),
                [(f"b{k + 1} {ind[k]}", res.ols.theta[k], res.wls.theta[k], res.wls.std[k],
                  res.consistent.theta[k], base.of(nominal)[k])
                 for k in range(base.size)]))
    eig = pseudo_inertia_eigenvalues(res.consistent.full[:10 * len(names)])
    masses = np.round(res.consistent.full[0:10 * len(names):10], 3).tolist()
    print(f"\nphysically consistent: every link's pseudo-inertia positive definite (smallest "
          f"eigenvalue {eig.min():.3g}), masses {masses} kg; weighted cost above WLS "
          f"{res.consistent.cost_increase:.3g} residual variances; {res.consistent.status}")
    if args.mapping:
        print("\nbase parameters in the full ones (b = kept + beta x folded):")
        print("\n".join(base.mapping()))
        print("not identifiable (in no base parameter): " + ", ".join(base.unidentifiable()))
    if val is not None:
        vdata, truth = val
        vcfg = IdentifyConfig(cutoff=cfg.cutoff, rate_out=1.0 / float(np.median(
            np.diff(vdata.t))), min_speed=cfg.min_speed, coulomb_width=cfg.coulomb_width)
        fv, vstretches = filter_stretches(vdata.t, vdata.position, vdata.effort, vcfg)
        if vstretches.describe():
            print(f"{args.validate}: {vstretches.describe()}")
        measured = vdata.effort[fv.index]
        if truth is not None:
            floor = np.std(vdata.effort - truth.effort, axis=0)
            floor_from = "truth: std of effort - true torque"
        else:
            floor = fv.noise
            floor_from = "estimated from the torque above the cutoff (an upper bound)"
        rows: list[tuple[object, ...]] = []
        shown: dict[str, np.ndarray] = {}
        for label, theta in (("WLS", res.wls.theta), ("consistent", res.consistent.theta),
                             ("OLS", res.ols.theta), ("nominal", base.of(nominal))):
            # on the filtered grid, then at the measured samples' own (jittered) times, each
            # run of the clock on its own
            tau = predict(arm.model, base, theta, fv.q, fv.qd, fv.qdd, vcfg)
            for run in increasing_runs(fv.t):
                tau[run] = interpolate(vdata.t[fv.index[run]], fv.t[run], tau[run])
            shown[label] = tau
            rmse, moving = torque_rmse(measured, tau, fv.qd, cfg.min_speed)
            rows.extend((label, n, rmse[j], moving[j], rmse[j] / floor[j])
                        for j, n in enumerate(names))
        print(f"\nvalidation on {args.validate} ({len(fv.t)} samples); noise floor from "
              f"{floor_from}: " + ", ".join(f"{f:.3g}" for f in floor) + " N m")
        print(table(("parameters", "joint", "RMSE N m", f"RMSE |qd|>={cfg.min_speed:g}",
                     "RMSE / noise floor"), rows))
        validation = (fv.t, measured, shown, rows, floor_from)
    if args.report:
        fit = (filtered, predict(arm.model, base, res.wls.theta, filtered.q, filtered.qd,
                                 filtered.qdd, cfg))
        path = _write_report(args.report, args, base, res, names, nominal, fit,
                             validation if val is not None else None)
        print(f"\nwrote {path}")
    if args.out:
        _write_params(args.out, args, base, res, names, arm.model)
        print(f"\nwrote {args.out}")
    return 0


def _read_joints(path: str, names: tuple[str, ...], args: argparse.Namespace) -> Any:
    """The joint log at ``path`` in the model's order and the truth beside it (None for a
    CSV log): a CSV file through ``--columns``, a rosbag2 or ROS 1 bag through ``--topic``."""
    from dampest_ros.io.arm import read_joint_bag
    from dampest_ros.io.arm_csv import read_joint_csv
    from dampest_ros.io.csv import is_csv, load_column_map

    if is_csv(path):
        cmap = load_column_map(args.columns) if args.columns else None
        return read_joint_csv(path, names, cmap), None
    return read_joint_bag(path, names, args.topic)


def _write_params(path: str, args: argparse.Namespace, base: Any, res: Any,
                  names: tuple[str, ...], arm: Any) -> None:
    """The arm model file (the one arm_estimator_node saves and takes as its prior) with the
    WLS estimate as theta, and the OLS and physically consistent fits beside it."""
    import numpy as np

    from dampest_ros.core.arm.model import arm_model_identity
    from dampest_ros.core.arm.online import ArmEstimate
    from dampest_ros.io.arm import joint_list, save_arm_model

    kept = [base.names[k] for k in base.independent]
    est = ArmEstimate(tuple(names), kept, res.wls.theta, res.wls.std,
                      np.ones(base.size, dtype=bool), base.mapping(),
                      identity=arm_model_identity(str(args.arm), arm, kept),
                      coulomb_width=float(args.coulomb_width))
    save_arm_model(path, est, str(args.arm), {
        "source": f"dampest arm identify {args.bag}",
        "ols": [float(x) for x in res.ols.theta],
        "consistent": [float(x) for x in res.consistent.theta],
        "consistent_status": res.consistent.status,
        "consistent_full": {"names": list(base.names),
                            "values": [float(x) for x in res.consistent.full]},
        "noise_estimate": [float(x) for x in res.noise],
        **({"lock": list(joint_list(args.lock))} if joint_list(args.lock) else {})})


def _write_report(out_dir: str, args: argparse.Namespace, base: Any, res: Any,
                  names: tuple[str, ...], nominal: np.ndarray, fit: Any,
                  validation: Any) -> Any:
    """index.html in the style of the vehicle reports: the trajectory, measured and model
    torque with the residual and the base parameters with σ against the nominal (``fit``:
    the filtered data and the WLS model's torque on them), the base parameters' table, the
    mapping, and the validation RMSE with a figure of measured and predicted torque."""
    import html
    from pathlib import Path

    import numpy as np
    from matplotlib.figure import Figure

    from dampest_ros.report.arm import parameter_figure, torque_figure, trajectory_figure
    from dampest_ros.report.figures import CSS

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    def tab(header: tuple[str, ...], rows: list[tuple[object, ...]]) -> str:
        def cell(x: object) -> str:
            return f"{x:.4g}" if isinstance(x, float) else html.escape(str(x))
        head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
        body = "".join("<tr>" + "".join(f"<td>{cell(c)}</td>" for c in r) + "</tr>"
                       for r in rows)
        return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"

    ind = [base.names[k] for k in base.independent]
    nom = base.of(nominal)
    parts = [f"<html><head><meta charset='utf-8'><title>arm identification</title>"
             f"<style>{CSS}</style></head><body>",
             f"<h1>Arm identification: {html.escape(str(args.arm))}</h1>",
             f"<p class='meta'>{html.escape(str(args.bag))}; {base.size} base parameters; rows "
             f"per joint {res.rows.tolist()}; cutoff {args.cutoff:g} Hz, {args.rate_out:g} Hz"
             "</p>"]
    filtered, model_tau = fit
    figures = (trajectory_figure(filtered.t, filtered.q, names, out / "trajectory.png"),
               torque_figure(filtered.t, filtered.tau, model_tau, names,
                             out / "fit_torque.png"),
               parameter_figure(ind, res.wls.theta, res.wls.std, nom, out / "parameters.png"))
    parts += ["<h2>Identification data and fit</h2>"] + [
        f"<img src='{f}' alt='{f[:-4]}'>" for f in figures]
    if validation is not None:
        t, measured, shown, rows, floor_from = validation
        k = slice(0, min(len(t), int(20.0 / max(float(np.median(np.diff(t))), 1e-9))))
        fig = Figure(figsize=(11, 7.5))
        axes = fig.subplots(3, 2, sharex=True).T.ravel()
        for j, ax in enumerate(axes[:len(names)]):
            ax.plot(t[k] - t[0], measured[k, j], lw=0.6, color="0.6", label="measured")
            ax.plot(t[k] - t[0], shown["WLS"][k, j], lw=1.0, color="tab:red", label="WLS")
            ax.plot(t[k] - t[0], shown["nominal"][k, j], lw=1.0, ls="--", color="tab:blue",
                    label="nominal")
            ax.set_ylabel(f"{names[j]} (N m)", fontsize=8)
            ax.grid(alpha=0.3)
        axes[0].legend(loc="upper right", fontsize=8)
        fig.suptitle(f"Validation torque, first 20 s of {args.validate}")
        fig.savefig(out / "torque.png", dpi=90)
        parts += [f"<h2>Validation on {html.escape(str(args.validate))}</h2>",
                  f"<p class='note'>Noise floor: {html.escape(floor_from)}.</p>",
                  tab(("parameters", "joint", "RMSE N m", "RMSE moving", "RMSE / noise floor"),
                      rows), "<img src='torque.png' alt='validation torque'>"]
    parts += ["<h2>Base parameters</h2>",
              f"<p class='note'>Physically consistent fit: {html.escape(res.consistent.status)}"
              ".</p>",
              tab(("base parameter", "OLS", "WLS", "σ", "consistent", "nominal"),
                  [(f"b{k + 1} {ind[k]}", float(res.ols.theta[k]), float(res.wls.theta[k]),
                    float(res.wls.std[k]), float(res.consistent.theta[k]), float(nom[k]))
                   for k in range(base.size)]),
              "<h2>Base parameters in the full ones</h2><pre>"
              + html.escape("\n".join(base.mapping())) + "</pre>",
              "<p class='note'>Not identifiable (in no base parameter): "
              + html.escape(", ".join(base.unidentifiable())) + "</p></body></html>"]
    path = out / "index.html"
    path.write_text("\n".join(parts))
    return path
