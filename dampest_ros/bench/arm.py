"""The arm rows: identification of long 1 kHz UR5 joint logs (group ``arm``), and ours beside
FIGAROH and MuJoCo's sysid on the same simulated data (group ``arm_peers``; ``make
bench-peers`` installs the peers from requirements/peers.txt)."""

from __future__ import annotations

import argparse
import time
from typing import Any

from dampest_ros.bench.runner import child


def arm_identify(hours: str) -> dict[str, float]:
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


def arm_rows(args: argparse.Namespace, tmp: str) -> list[tuple[str, ...]]:
    """Arm identification of ``--hours`` of 1 kHz joint data."""
    rows: list[tuple[str, ...]] = []
    for hours in args.hours:
        arm = child("arm.arm_identify", str(hours))
        rows.append((f"arm identify {hours:g} h of 1 kHz UR5 joint data (arrays)",
                     f"{arm['seconds']:.1f} s", f"{arm['samples']:.0f} samples, WLS "
                     f"max |error|/sigma {arm['max_z']:.1f}", "≤ 10 s", f"{arm['peak_mb']:.0f}"))
    return rows


# --- side by side with the peers (group arm_peers; make bench-peers installs them) ----------

#: Methods of :func:`arm_peer`: ours (WLS), FIGAROH, MuJoCo's sysid.
PEERS = ("ours", "figaroh", "mujoco_sysid")
#: Row selections of :func:`arm_peer` for the estimators that fit filtered samples: ``ours``
#: leaves out the rows the friction model does not cover (|q̇_j| < 0.1 rad/s and 2 / cutoff
#: s around a reversal of q̇_j: :func:`~dampest_ros.core.arm.identify.usable_rows`), ``all``
#: fits every row (FIGAROH's own). MuJoCo's sysid rolls the model out: no selection.
ROWS = ("ours", "all")


def _peer_data(seconds: float) -> tuple[Any, Any, Any, Any]:
    """The peers' common data: ``seconds`` of a UR5 run on a random FFS trajectory (5
    harmonics, 0.1 Hz, |q̇| ≤ 1 rad/s) and 20 s of another (4 harmonics, 0.125 Hz) for
    validation, 1 kHz, realistic encoders and torque sensors (noise and offsets)."""
    import numpy as np

    from dampest_ros.core.arm.ffs import random_trajectory
    from dampest_ros.core.arm.simulate import REALISTIC, simulate_arm
    from dampest_ros.io.arm import load_arm

    arm = load_arm("ur5")
    train = simulate_arm(arm.mjcf, arm.model, arm.dynamics, random_trajectory(
        np.zeros(6), 5, 0.1, np.full(6, 1.0), np.random.default_rng(3)), seconds, 1000.0,
        REALISTIC, seed=1)
    val = simulate_arm(arm.mjcf, arm.model, arm.dynamics, random_trajectory(
        np.zeros(6), 4, 0.125, np.full(6, 1.0), np.random.default_rng(7)), 20.0, 1000.0,
        REALISTIC, seed=2)
    return arm, train, val, REALISTIC


def _figaroh(arm: Any, data: Any, use: Any) -> Any:
    """FIGAROH's base-parameter least squares on our filtered samples: its regressor
    (Pinocchio per sample, with viscous and Coulomb friction, armature and offset columns),
    its elimination of zero columns and its double QR decomposition (base parameters and
    their least-squares estimate) on the rows ``use`` (M, n) of bool; returns the
    prediction function of the estimate."""
    from figaroh.identification.parameter import (
        add_standard_additional_parameters,
        get_standard_parameters,
    )
    from figaroh.tools.qrdecomposition import QRDecomposer
    from figaroh.tools.regressor import (
        build_regressor_basic,
        build_regressor_reduced,
        get_index_eliminate,
    )

    model, pdata = arm.model.pinocchio()

    class Robot:  # what FIGAROH's regressor builder reads of a robot
        def __init__(self) -> None:
            self.model, self.data = model, pdata

    robot = Robot()
    config = {"has_friction": True, "has_actuator_inertia": True, "has_joint_offset": True,
              "act_idxv": list(range(arm.model.n)), "is_joint_torques": True}
    W = build_regressor_basic(robot, data.q, data.qd, data.qdd, config)
    standard = get_standard_parameters(model, config)
    standard.update(add_standard_additional_parameters(model, config))
    eliminated, active = get_index_eliminate(W, standard, tol_e=1e-3)
    decomposer = QRDecomposer(tolerance=1e-6)
    # FIGAROH stacks the rows joint after joint: τ = [τ_1(t_1..t_N), τ_2(...), ...]
    keep = use.T.ravel()
    _, _, _, phi, _ = decomposer.double_decomposition(
        data.tau.T.ravel()[keep], build_regressor_reduced(W, eliminated)[keep], active,
        standard)
    kept = list(decomposer.get_base_indices())

    def predict(q: Any, qd: Any, qdd: Any) -> Any:
        Wv = build_regressor_reduced(build_regressor_basic(robot, q, qd, qdd, config),
                                     eliminated)[:, kept]
        return (Wv @ phi).reshape(arm.model.n, -1).T

    return predict


def _mujoco_sysid(arm: Any, run: Any, seconds: float, iterations: int) -> Any:
    """MuJoCo's sysid (Gauss–Newton on rollouts) on the first ``seconds`` of the raw 1 kHz
    run, cut into 1 s windows, each a rollout from the measured state (position, its central
    difference) driven by the measured torque, scored on the measured joint positions. Per
    link its pseudo-inertia parameterisation (written through the body's full inertia: the
    arm's MJCF has no geoms to infer inertias from, which sysid's own body modifier needs),
    per joint damping, armature and friction loss, per motor a torque bias (the sensor
    offset). Start: every link 20 % heavier, every joint term 1.5× + 0.01, no bias. Returns
    the identified full parameter vector (ours: inertias about the joint frames, Ia, Fv, Fc,
    offset)."""
    from functools import partial

    import mujoco
    import numpy as np
    from mujoco import sysid

    from dampest_ros.core.arm.mjinverse import body_parameters, joint_bodies
    from dampest_ros.core.arm.model import joint_dynamics

    names = arm.model.names
    mj: Any = mujoco  # the stubs lack the spec API
    spec = mj.MjSpec.from_string(arm.mjcf)
    for n in names:
        spec.add_sensor(name=f"{n}_pos", type=mj.mjtSensor.mjSENS_JOINTPOS,
                        objtype=mj.mjtObj.mjOBJ_JOINT, objname=n)
    for a in spec.actuators:
        a.biastype = mj.mjtBias.mjBIAS_AFFINE  # force = ctrl + biasprm[0]
    model = spec.compile()

    def inertia(s: Any, p: Any, body: str) -> None:
        pi = sysid.model_modifier.pi_from_theta(p.value)  # m, m c, inertia about the origin
        b = s.body(body)
        b.mass, b.ipos = pi[0], pi[1:4] / pi[0]
        b.inertia[:], b.iquat[:] = 0.0, [1.0, 0.0, 0.0, 0.0]
        c = pi[1:4] / pi[0]
        S = np.array([[0.0, -c[2], c[1]], [c[2], 0.0, -c[0]], [-c[1], c[0], 0.0]])
        Ic = pi[4:].reshape(3, 3) + pi[0] * S @ S  # about the centre: I_o + m S(c) S(c)
        b.fullinertia[:] = [Ic[0, 0], Ic[1, 1], Ic[2, 2], Ic[0, 1], Ic[0, 2], Ic[1, 2]]

    def joint_term(s: Any, p: Any, name: str, attr: str) -> None:
        value = np.array(getattr(s.joint(name), attr), dtype=float)
        value.ravel()[0] = p.value[0]  # damping is a polynomial: its linear coefficient
        setattr(s.joint(name), attr, value if value.ndim else float(value))

    def bias(s: Any, p: Any, name: str) -> None:
        s.actuator(name).biasprm[0] = p.value[0]

    params = sysid.ParameterDict()
    for n in names:
        p = sysid.body_inertia_param(spec, model, f"link_{n}", sysid.InertiaType.Pseudo,
                                     modifier=partial(inertia, body=f"link_{n}"))
        p.value[0] += 0.5 * np.log(1.2)  # the scale α: mass = e^{2α}
        params.add(p)
        for attr, high in (("damping", 20.0), ("armature", 2.0), ("frictionloss", 20.0)):
            nominal = float(np.ravel(getattr(spec.joint(n), attr))[0])
            params.add(sysid.Parameter(
                f"{n}_{attr}", nominal=nominal, min_value=0.0, max_value=high,
                modifier=partial(joint_term, name=n, attr=attr)))
            params[f"{n}_{attr}"].value[:] = 1.5 * nominal + 0.01
        params.add(sysid.Parameter(f"{n}_offset", nominal=0.0, min_value=-3.0, max_value=3.0,
                                   modifier=partial(bias, name=n)))
    step = 1000  # 1 s windows of 1 kHz samples
    stop = int(seconds * 1000)
    velocity = np.gradient(run.position[:stop], 1e-3, axis=0)
    starts = range(0, stop - step, step)
    windows = [slice(k, k + step) for k in starts]
    ms = sysid.ModelSequences(
        "ur5", spec, [f"w{k}" for k in starts],
        [sysid.create_initial_state(model, run.position[k], velocity[k]) for k in starts],
        [sysid.TimeSeries(run.t[w] - run.t[w][0], run.effort[w]) for w in windows],
        [sysid.TimeSeries.from_names(run.t[w] - run.t[w][0], run.position[w], model)
         for w in windows])
    found, _ = sysid.optimize(initial_params=params,
                              residual_fn=sysid.build_residual_fn(models_sequences=[ms]),
                              optimizer="mujoco", verbose=False, max_iters=iterations)
    fitted = sysid.apply_param_modifiers(found, spec)
    bodies, _ = joint_bodies(fitted, names)
    dyn = joint_dynamics(fitted, names)
    # effort = τ − bias: the sensor offset is minus the motor's bias
    off = -np.array([found[f"{n}_offset"].value[0] for n in names])
    return np.concatenate([np.concatenate([body_parameters(fitted, b) for b in bodies]),
                           np.stack([dyn.armature, dyn.damping, dyn.frictionloss, off],
                                    axis=1).ravel()])


def arm_peer(method: str, seconds: str, sysid_seconds: str, iterations: str,
             rows: str = "ours") -> dict[str, float]:
    """Identify the same simulated UR5 data with ``method`` (:data:`PEERS`) on the rows
    ``rows`` (:data:`ROWS`; ours and FIGAROH) and validate on another trajectory: wall time
    of the identification from the filtered samples on (ours, FIGAROH: both get the same
    zero-phase filtered 50 Hz samples; the filter's time is reported apart) or from the raw
    samples on (MuJoCo's sysid, which rolls the model out), the share of rows fitted, and
    per joint the validation torque RMSE over the noise floor (std of the torque sensor's
    error), all predicted through our regressor (for ours and sysid) or FIGAROH's (its
    base parameters)."""
    import numpy as np

    from dampest_ros.core.arm.base import base_parameters
    from dampest_ros.core.arm.identify import (
        IdentifyConfig,
        filter_joints,
        identify_arm,
        predict,
        torque_rmse,
        usable_rows,
    )
    from dampest_ros.core.arm.regressor import full_parameters

    if rows not in ROWS:
        raise ValueError(f"rows {rows!r} is not one of {ROWS}")
    arm, train, val, _ = _peer_data(float(seconds))
    cfg = IdentifyConfig()
    base = base_parameters(arm.model)
    vcfg = IdentifyConfig(rate_out=1000.0)
    fv = filter_joints(val.t, val.position, val.effort, vcfg)
    t0 = time.perf_counter()
    data = filter_joints(train.t, train.position, train.effort, cfg)
    filtered = time.perf_counter() - t0
    t0 = time.perf_counter()
    use = (usable_rows(data.t, data.qd, cfg) if rows == "ours"
           else np.ones(data.qd.shape, dtype=bool))
    if method == "ours":
        theta = identify_arm(arm.model, base, data, full_parameters(arm.model, arm.dynamics),
                             cfg, rows=use).wls.theta
        seconds_taken = time.perf_counter() - t0
        tau = predict(arm.model, base, theta, fv.q, fv.qd, fv.qdd, vcfg)
    elif method == "figaroh":
        fig = _figaroh(arm, data, use)
        seconds_taken = time.perf_counter() - t0
        tau = fig(fv.q, fv.qd, fv.qdd)
    elif method == "mujoco_sysid":
        full = _mujoco_sysid(arm, train, float(sysid_seconds), int(iterations))
        seconds_taken = time.perf_counter() - t0
        tau = predict(arm.model, base, base.of(full), fv.q, fv.qd, fv.qdd, vcfg)
    else:
        raise ValueError(f"method {method!r} is not one of {PEERS}")
    floor = np.std(val.effort - val.tau, axis=0)
    rmse = torque_rmse(val.effort[fv.index], tau, fv.qd, cfg.min_speed)[0]
    out = {"seconds": seconds_taken, "filter_seconds": filtered,
           "rows_used": float(use.mean())}
    out.update({f"rmse_{j}": float(r) for j, r in enumerate(rmse / floor)})
    return out


def arm_peers_rows(args: argparse.Namespace, tmp: str) -> list[tuple[str, ...]]:
    """Ours beside FIGAROH and MuJoCo's sysid on the same UR5 data (make bench-peers), each
    estimator that fits filtered samples on both row selections (:data:`ROWS`), so that
    which rows an estimator is fed and the estimator itself are told apart."""
    rows: list[tuple[str, ...]] = []
    seconds, sysid_seconds, iterations = 60.0, 10.0, 30
    runs = [("ours", "ours", seconds, f"{seconds:g} s"),
            ("ours", "all", seconds, f"{seconds:g} s"),
            ("ours", "ours", sysid_seconds, f"first {sysid_seconds:g} s"),
            ("figaroh", "all", seconds, f"{seconds:g} s"),
            ("figaroh", "ours", seconds, f"{seconds:g} s"),
            ("mujoco_sysid", "ours", sysid_seconds,
             f"first {sysid_seconds:g} s, {iterations} iterations")]
    for method, selection, length, what in runs:
        fed = ("rollouts of the raw samples" if method == "mujoco_sysid"
               else f"{selection} rows")
        label = f"arm peers: estimator {method}, row selection {fed}, on {what} of UR5 data"
        try:
            r = child("arm.arm_peer", method, str(length), str(sysid_seconds),
                      str(iterations), selection)
        except RuntimeError as exc:  # not installed (make bench-peers) or failed
            last = str(exc).strip().splitlines()[-1]
            rows.append((label, "-", f"did not run: {last}", "", ""))
            continue
        ratios = " ".join(f"{r['rmse_' + str(j)]:.3f}" for j in range(6))
        share = "" if method == "mujoco_sysid" else f", {100 * r['rows_used']:.0f} % of rows"
        rows.append((label, f"{r['seconds']:.2f} s",
                     f"validation torque RMSE / noise floor per joint: {ratios} "
                     f"(filter {r['filter_seconds']:.2f} s{share})", "beside ours",
                     f"{r['peak_mb']:.0f}"))
    return rows
