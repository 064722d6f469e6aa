"""Arm identification against MuJoCo truth: exact on noise-free data, at the noise floor on
realistic data, physically consistent always."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.arm.base import base_parameters
from dampest_ros.core.arm.ffs import random_trajectory
from dampest_ros.core.arm.fit import (
    JointNormals,
    fit_base,
    fit_consistent,
    pseudo_inertia_eigenvalues,
)
from dampest_ros.core.arm.identify import (
    IdentifyConfig,
    filter_joints,
    identify_arm,
    predict,
    torque_rmse,
)
from dampest_ros.core.arm.regressor import full_parameters, regressor
from dampest_ros.core.arm.simulate import REALISTIC, simulate_arm
from dampest_ros.io.arm import load_arm


@pytest.fixture(scope="module")
def ur5():  # type: ignore[no-untyped-def]
    arm = load_arm("ur5")
    return arm, base_parameters(arm.model)


def _joint(base, name: str) -> int:  # type: ignore[no-untyped-def]
    return [base.names[i] for i in base.independent].index(name)


def test_base_parameters_recombine_the_full_set(ur5) -> None:  # type: ignore[no-untyped-def]
    arm, base = ur5
    assert base.size == 58  # 36 rigid-body combinations + Ia of joints 3-6 + Fv, Fc, off x 6
    rng = np.random.default_rng(7)
    q, qd, qdd = (rng.normal(size=(30, 6)) for _ in range(3))
    Y = regressor(arm.model, q, qd, qdd)
    pi = full_parameters(arm.model, arm.dynamics, rng.normal(size=6))
    assert np.abs(base.columns(Y) @ base.of(pi) - Y @ pi).max() < 1e-12
    assert any(" + 0.425 " in line or " - 0.425 " in line for line in base.mapping())
    assert "shoulder_pan_joint.m" in base.unidentifiable()


def test_noise_free_data_give_the_truth(ur5) -> None:  # type: ignore[no-untyped-def]
    arm, base = ur5
    traj = random_trajectory(np.zeros(6), 5, 0.1, np.full(6, 1.5), np.random.default_rng(3))
    run = simulate_arm(arm.mjcf, arm.model, arm.dynamics, traj, 20.0)
    normals = JointNormals.empty(6, 84)
    normals.add(regressor(arm.model, run.q, run.qd, run.qdd), run.tau,
                np.abs(run.qd) >= 0.1)
    fit = fit_base(normals, base, weighted=False)
    truth = base.of(full_parameters(arm.model, arm.dynamics))
    assert np.linalg.norm(fit.theta - truth) <= 1e-6 * np.linalg.norm(truth)
    big = np.abs(truth) > 1e-3
    assert np.all(np.abs(fit.theta - truth)[big] <= 1e-6 * np.abs(truth)[big])
    assert np.all(np.abs(fit.theta - truth)[~big] <= 1e-6)
    for j, name in enumerate(arm.model.names):
        for term, value in (("Fv", arm.dynamics.damping[j]), ("Fc", arm.dynamics.frictionloss[j])):
            assert fit.theta[_joint(base, f"{name}.{term}")] == pytest.approx(value, rel=0.01)
    # physically consistent from a nominal 20 % off: the same base parameters, physical links
    nominal = full_parameters(arm.model, arm.dynamics)
    nominal[:60] *= 1.2
    pc = fit_consistent(normals, base, fit_base(normals, base), nominal)
    assert np.linalg.norm(pc.theta - truth) <= 1e-6 * np.linalg.norm(truth)
    assert pseudo_inertia_eigenvalues(pc.full[:60]).min() > 0
    assert pc.converged and pc.status == "converged"


def test_realistic_noise_reaches_the_noise_floor(ur5) -> None:  # type: ignore[no-untyped-def]
    arm, base = ur5
    cfg = IdentifyConfig()
    traj = random_trajectory(np.zeros(6), 5, 0.1, np.full(6, 1.5), np.random.default_rng(3))
    run = simulate_arm(arm.mjcf, arm.model, arm.dynamics, traj, 40.0, 1000.0, REALISTIC, seed=1)
    nominal = full_parameters(arm.model, arm.dynamics)
    nominal[:60] *= 1.2  # a nominal model 20 % off
    res = identify_arm(arm.model, base, filter_joints(run.t, run.position, run.effort, cfg),
                       nominal, cfg)
    truth = base.of(full_parameters(arm.model, arm.dynamics, REALISTIC.torque_offset))
    z = (res.wls.theta - truth) / res.wls.std
    assert np.sqrt(np.mean(z ** 2)) < 2.0 and np.abs(z).max() < 5.0
    assert pseudo_inertia_eigenvalues(res.consistent.full[:60]).min() > 0
    assert np.all(res.consistent.full[60:].reshape(6, 4)[:, :3] > 0)
    # validation on another FFS trajectory: RMSE per joint against the sensor's noise
    val = random_trajectory(np.zeros(6), 4, 0.125, np.full(6, 1.2), np.random.default_rng(4))
    vrun = simulate_arm(arm.mjcf, arm.model, arm.dynamics, val, 16.0, 1000.0, REALISTIC, seed=2)
    fv = filter_joints(vrun.t, vrun.position, vrun.effort, IdentifyConfig(rate_out=1000.0))
    sigma = np.asarray(REALISTIC.torque_sigma)

    def ratio(theta: np.ndarray) -> np.ndarray:
        tau = predict(arm.model, base, theta, fv.q, fv.qd, fv.qdd, cfg)
        return torque_rmse(vrun.effort[fv.index], tau, fv.qd, cfg.min_speed)[0] / sigma

    wls, ols, pc = ratio(res.wls.theta), ratio(res.ols.theta), ratio(res.consistent.theta)
    assert np.all(wls <= 1.05) and np.all(pc <= 1.05)
    # the consistent fit is never worse than OLS by more than the RMSE's own sigma
    n = len(fv.t)
    assert np.all(pc <= ols * (1.0 + 1.0 / np.sqrt(2 * n)) + 1e-12)
    assert ratio(base.of(nominal)).max() > 2.0  # the 20 %-off nominal is visibly worse


def test_filtering_in_windows_equals_one_pass() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(60_000) / 1000.0
    pos = np.cumsum(rng.normal(size=(60_000, 2)), axis=0) * 1e-3 + np.sin(t)[:, None]
    eff = rng.normal(size=(60_000, 2)) + np.cos(t)[:, None]
    one = filter_joints(t, pos, eff, IdentifyConfig(chunk_seconds=1e9))
    win = filter_joints(t, pos, eff, IdentifyConfig(chunk_seconds=7.0))
    for name, tol in (("q", 1e-12), ("qd", 1e-10), ("qdd", 1e-8), ("tau", 1e-10)):
        assert np.abs(getattr(one, name) - getattr(win, name)).max() < tol, name
    assert np.allclose(one.noise, win.noise, rtol=1e-12)
    assert one.noise == pytest.approx([1.0, 1.0], rel=0.02)  # the white noise's own sigma
