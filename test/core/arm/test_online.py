"""Online arm identification on the vehicle's RLS: a 1 kg payload picked up mid-run is
alarmed within 5 s and the parameters it changes are tracked to 5 % within 20 s; from the
default prior the estimate reaches the batch fit on the UR5 and on an outside arm."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dampest_ros.core.arm.base import base_parameters
from dampest_ros.core.arm.ffs import random_trajectory
from dampest_ros.core.arm.identify import IdentifyConfig, filter_joints, identify_arm
from dampest_ros.core.arm.model import mjcf
from dampest_ros.core.arm.online import (
    ArmEstimator,
    default_rls,
    initial_noise_var,
    prior_std,
)
from dampest_ros.core.arm.regressor import full_parameters
from dampest_ros.core.arm.simulate import REALISTIC, simulate_arm
from dampest_ros.io.arm import load_arm, load_trajectory


def test_payload_step_is_alarmed_and_tracked() -> None:
    arm = load_arm("ur5")
    base = base_parameters(arm.model)
    traj = random_trajectory(np.zeros(6), 5, 0.1, np.full(6, 1.5), np.random.default_rng(3))
    run = simulate_arm(arm.mjcf, arm.model, arm.dynamics, traj, 62.0, 1000.0, REALISTIC,
                       seed=1, payload=(1.0, 40.0))
    full = full_parameters(arm.model, arm.dynamics, np.asarray(REALISTIC.torque_offset))
    before = base.of(full)
    full[10 * 5] += 1.0  # the point mass at the last link's origin: its mass only
    after = base.of(full)
    est = ArmEstimator(arm.model, base, before, np.abs(before) + 1e-2, IdentifyConfig())
    at_40 = None
    for k in range(0, len(run.t), 250):  # 0.25 s pieces, as a node would hand them over
        est.add(run.t[k:k + 250], run.position[k:k + 250], run.effort[k:k + 250])
        if at_40 is None and run.t[min(k + 249, len(run.t) - 1)] >= 39.9:
            at_40 = est.theta.copy()
    assert at_40 is not None and len(est.alarms) == 1
    assert 40.0 < est.alarms[0] <= 45.0
    # the estimate lags the data by the filter margin and a hop (about 2 s): the state at
    # 62 s is the data up to 60 s, 20 s after the step
    assert est.emitted >= 59.5
    change = np.abs(after - before)
    affected = (change > 0.05 * np.abs(after)) & (change > 5.0 * est.std)
    names = [base.names[i] for i in base.independent[affected]]
    assert {"elbow_joint.m", "elbow_joint.mz", "shoulder_pan_joint.Ia"} <= set(names)
    assert np.all(np.abs(est.theta - after)[affected] <= 0.05 * np.abs(after)[affected])
    # before the step the estimate held the truth (no false alarm, no drift)
    assert np.all(np.abs(at_40 - before)[affected] <= 0.02 * np.abs(before)[affected])


def test_jittered_stamps_are_resampled_and_only_real_gaps_restart_the_stream() -> None:
    """Samples at 250 Hz whose instants jitter by ±1 ms (±25 %; each is the 1 ms step before,
    at or after its nominal one) with 0.5 s lost at 15 s: before, every jittered step
    restarted the filter (a 'gap'), so nothing was estimated. Now the one real gap is
    counted, the jitter is resampled, and the estimate holds the truth within 5 σ."""
    arm = load_arm("ur5")
    base = base_parameters(arm.model)
    traj = random_trajectory(np.zeros(6), 5, 0.1, np.full(6, 1.5), np.random.default_rng(3))
    run = simulate_arm(arm.mjcf, arm.model, arm.dynamics, traj, 32.0, 1000.0, REALISTIC,
                       seed=1)
    k = np.arange(1, len(run.t) // 4 - 1) * 4
    k = k + np.random.default_rng(5).integers(-1, 2, len(k))
    k = k[(run.t[k] < 15.0) | (run.t[k] >= 15.5)]
    truth = base.of(full_parameters(arm.model, arm.dynamics, np.asarray(REALISTIC.torque_offset)))
    est = ArmEstimator(arm.model, base, truth * 1.2, np.abs(truth) + 1e-2,
                       IdentifyConfig(rate_out=50.0))
    used = sum(est.add(run.t[k[i:i + 60]], run.position[k[i:i + 60]], run.effort[k[i:i + 60]])
               for i in range(0, len(k), 60))  # 0.25 s pieces
    assert est.gaps == 1 and not est.alarms
    assert used >= 50 * 24  # 31 s of data, less the gap and the filter margins around it
    z = (est.theta - truth) / est.std
    assert np.abs(z).max() < 5.0, dict(zip([base.names[i] for i in base.independent], z,
                                           strict=True))


def test_the_default_prior_does_not_pin_what_is_nominally_zero() -> None:
    """The default prior σ was |θ| + 0.01: a torque offset (nominal 0) could not leave 0.
    Now every base parameter may move its joint's torque by 10 % of the effort limit: an
    offset, whose column is 1, gets exactly that; a Coulomb term (column sign q̇) |θ| + it."""
    arm = load_arm("ur5")
    base = base_parameters(arm.model)
    theta = base.of(full_parameters(arm.model, arm.dynamics))
    std = prior_std(arm.model, base, theta)
    kept = [base.names[i] for i in base.independent]
    for j, name in enumerate(arm.model.names):
        e = arm.model.effort_limit[j]
        assert std[kept.index(f"{name}.off")] == pytest.approx(0.1 * e, rel=1e-12)
        assert std[kept.index(f"{name}.Fc")] == pytest.approx(
            arm.dynamics.frictionloss[j] + 0.1 * e, rel=1e-12)
    assert initial_noise_var(arm.model, base, theta) == pytest.approx(
        [(0.01 * e) ** 2 for e in arm.model.effort_limit], rel=1e-12)


def _online_against_batch(arm, run, prior: np.ndarray, **rls) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    """Median and largest |online − batch| / σ_batch after the first 60 s of a run, the
    online estimator started from the nominal ``prior`` with the default σ."""
    base = base_parameters(arm)
    cfg = IdentifyConfig()
    first = run.t < 60.0
    batch = identify_arm(arm, base, filter_joints(run.t[first], run.position[first],
                                                  run.effort[first], cfg), prior, cfg).wls
    theta0 = base.of(prior)
    est = ArmEstimator(arm, base, theta0, prior_std(arm, base, theta0), cfg,
                       default_rls(arm, base, theta0, **rls))
    for k in range(0, len(run.t), 250):  # 0.25 s pieces, as the node hands them over
        est.add(run.t[k:k + 250], run.position[k:k + 250], run.effort[k:k + 250])
    assert est.emitted == pytest.approx(60.0) and not est.alarms
    z = np.abs(est.theta - batch.theta) / batch.std
    return float(np.median(z)), float(z.max())


def test_a_designed_ur5_trajectory_converges_online_from_the_default_prior() -> None:
    """60 s of a designed excitation (test/data/ur5_excite.yaml, `dampest arm design`) from
    the default prior: the σ of |θ| + 0.01 and one noise variance (0.01 N² m²) for every
    joint, weights adapted, ended 2.7 σ (median) and 17.7 σ (worst) from the batch fit;
    with today's σ but that one variance 3.5 and 19.0 σ (0.69 and 3.46 σ with fixed
    weights). With the variances from the effort limits: 0.40 and 0.98 σ; with fixed
    weights 0.47 and 1.36 σ."""
    arm = load_arm("ur5")
    traj, _ = load_trajectory(Path(__file__).parents[2] / "data" / "ur5_excite.yaml", 6)
    run = simulate_arm(arm.mjcf, arm.model, arm.dynamics, traj, 62.0, 1000.0, REALISTIC,
                       seed=1)
    nominal = full_parameters(arm.model, arm.dynamics)
    median, worst = _online_against_batch(arm.model, run, nominal)
    assert median <= 0.6 and worst <= 1.5  # measured 0.40, 0.98
    median, worst = _online_against_batch(arm.model, run, nominal,
                                          adapt_weights=False)
    assert median <= 0.7 and worst <= 2.0  # measured 0.47, 1.36


@pytest.mark.parametrize("name", ["ur10", "panda", "xarm7"])
def test_an_outside_arm_converges_online_from_its_urdf(name: str, outside_arm, outside
                                                       ) -> None:  # type: ignore[no-untyped-def]
    """The UR10 of example-robot-data states no joint friction: from its URDF the old prior
    pinned viscous and Coulomb friction at 0 (62 σ median, 925 σ worst after 60 s). Now the
    online estimate ends within 0.3 σ (median) and 1.1 σ (worst) of the batch fit. The Panda
    (7 joints, fingers locked) and the xArm7, refused before (the RLS took six rows, the
    vehicle's DOFs): 0.27 σ and 0.94 σ, 0.19 σ and 1.14 σ."""
    path, lock = outside_arm(name)
    desc = load_arm(path, lock=lock)
    arm = desc.model
    dyn, sensors = outside.joint_terms(arm), outside.sensors(arm)
    run = simulate_arm(mjcf(arm, dyn), arm, dyn,
                       outside.trajectory(arm, full_parameters(arm, dyn), 5, 0.1, 3), 62.0,
                       1000.0, sensors, seed=1)
    nominal = full_parameters(arm, desc.dynamics)  # the URDF's: no armature; the UR10's
    assert not nominal[10 * arm.n:].any() or name != "ur10"  # friction 0
    median, worst = _online_against_batch(arm, run, nominal)
    print(f"\n{name}: median {median:.2f} sigma, worst {worst:.2f} sigma")
    # measured: ur10 0.29, 1.07; panda 0.27, 0.94; xarm7 0.19, 1.14
    assert median <= 0.5 and worst <= 1.5
