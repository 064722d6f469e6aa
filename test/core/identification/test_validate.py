"""Validation metrics (dampest_ros.core.identification.validate) on known signals and on simulated
data."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.identification import validate as val
from dampest_ros.core.physics import frames
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.simulation.effects import Effects, true_vehicle
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.simulate import run
from dampest_ros.core.simulation.trajectory import Trajectory
from dampest_ros.io.yaml_io import load_vehicle


def samples_from(traj: Trajectory) -> Samples:
    """Samples straight from the simulator's ground truth (one segment).

    Trajectory.tau is the mean thrust over [t, t + dt]; ν and ν̇ are at t.
    """
    euler = frames.euler_from_matrix(frames.quat_to_matrix(traj.quaternion))
    return Samples(traj.t, traj.nu, traj.nu_dot, traj.tau, euler, traj.position[:, 2],
                   np.zeros(len(traj), dtype=np.int64))


@pytest.fixture(scope="module")
def vehicle() -> Vehicle:
    return load_vehicle("bluerov2_heavy")


@pytest.fixture(scope="module")
def sim(heavy_b60: tuple[Trajectory, object]) -> Samples:
    """60 s of protocol B at 50 Hz, noise-free (the session's :func:`heavy_b60`)."""
    return samples_from(heavy_b60[0])


# --- free run ------------------------------------------------------------------------------


def test_free_run_with_true_theta_reproduces_the_measured_velocity(
        vehicle: Vehicle, sim: Samples) -> None:
    # τ is the step mean, so hold it over the step: the free run is then the simulator's
    # own RK4 up to the attitude interpolation and the motor lag inside a step.
    # Measured NRMSE (RMSE / std of ν) u…r: 0.0011 0.0007 0.0045 0.011 0.0052 0.00015; roll
    # is the largest because nothing but the weak damping at low |p| pulls an error back
    # (the attitude, hence the restoring moment, is the measured one).
    err = val.free_run_error(sim, vehicle.damping, vehicle.body, vehicle.theta, tau_hold="zero")
    assert np.all(err["nrmse"] < 0.02), err["nrmse"]
    assert np.all(err["nse"] > 0.999)
    nu = val.free_run(sim, vehicle.damping, vehicle.body, vehicle.theta, 0, tau_hold="zero")
    assert nu.shape == (len(sim), 6)
    np.testing.assert_array_equal(nu[0], sim.nu[0])
    # linear interpolation of τ lags the step mean by half a step: worse in every DOF
    # (measured NRMSE 0.012 0.011 0.043 0.10 0.058 0.008)
    lin = val.free_run_error(sim, vehicle.damping, vehicle.body, vehicle.theta)
    assert np.all(lin["nrmse"] > err["nrmse"]) and np.all(lin["nrmse"] < 0.2)


def test_free_run_sub_steps_a_model_too_stiff_for_the_sample_step(
        vehicle: Vehicle, sim: Samples) -> None:
    # every 5th row (10 Hz) and a yaw damping N_r = 40 N·m·s/rad: h·ρ ≈ 7 > 2.785, where one
    # RK4 step per sample diverges (it did before the sub-steps: inf in every DOF)
    ten = Samples(sim.t[::5], sim.nu[::5], sim.nu_dot[::5], sim.tau[::5], sim.euler[::5],
                  sim.depth[::5], sim.segment[::5])
    stiff = vehicle.theta.copy()
    stiff[vehicle.damping.parameter_names.index("N_r")] = 40.0
    steps = val.rk4_substeps(ten.nu, np.diff(ten.t), vehicle.damping, vehicle.body, stiff)
    assert steps.min() == steps.max() == 4  # measured: ρ ≈ 70 1/s everywhere
    err = val.free_run_error(ten, vehicle.damping, vehicle.body, stiff)
    assert np.all(np.isfinite(err["nrmse"])) and np.all(np.isnan(err["diverged_after"]))
    assert np.all(err["nrmse"] < 1.1), err["nrmse"]  # measured 0.24–1.03: wrong, not diverged
    # the 50 Hz run of the true model takes one step per sample: the path it always took
    assert val.rk4_substeps(sim.nu, np.diff(sim.t), vehicle.damping, vehicle.body,
                            vehicle.theta).max() == 1


def test_free_run_of_an_unstable_model_says_when_it_diverged(vehicle: Vehicle,
                                                              sim: Samples) -> None:
    unstable = vehicle.theta.copy()
    unstable[vehicle.damping.parameter_names.index("N_rr")] = -50.0  # energy in at any |r|
    err = val.free_run_error(sim, vehicle.damping, vehicle.body, unstable)
    assert np.all(np.isinf(err["rmse"]))
    after = err["diverged_after"]
    assert np.all(after == after[0]) and 0.0 < after[0] < sim.t[-1] - sim.t[0]


def test_free_run_with_wrong_quadratic_damping_is_clearly_worse(
        vehicle: Vehicle, sim: Samples) -> None:
    true = val.free_run_error(sim, vehicle.damping, vehicle.body, vehicle.theta,
                            tau_hold="zero")["nrmse"]
    theta = vehicle.theta.copy()
    theta[vehicle.damping.slice("quadratic")] *= 1.3
    wrong = val.free_run_error(sim, vehicle.damping, vehicle.body, theta, tau_hold="zero")["nrmse"]
    # measured NRMSE with the +30 % error: 0.18 0.12 0.22 0.50 0.52 0.14
    assert np.all(wrong > 20 * true), (wrong, true)
    assert wrong.max() > 0.3


def test_free_run_with_fluid_memory(vehicle: Vehicle) -> None:
    # the memory states are integrated with ν; the true model with its kernel reproduces ν,
    # the model without it does not
    effects = Effects(memory=({"dof": "u", "rate": 1.0, "c": 30.0},
                              {"dof": "r", "rate": 2.0, "c": 2.0}))
    truth = true_vehicle(vehicle, effects)
    s = samples_from(run(vehicle, make_excitation("B", vehicle, 30.0, seed=4), effects))
    err = val.free_run_error(s, truth.damping, truth.body, truth.theta, tau_hold="zero")
    assert np.all(err["nrmse"] < 0.02), err["nrmse"]
    no_mem = truth.theta.copy()
    no_mem[truth.damping.slice("freq")] = 0.0
    bad = val.free_run_error(s, truth.damping, truth.body, no_mem, tau_hold="zero")
    assert bad["nrmse"][0] > 10 * err["nrmse"][0]


def test_free_run_rows_and_errors(vehicle: Vehicle, sim: Samples) -> None:
    rows = val.longest_segment(sim, 10.0)
    assert (rows.start, rows.stop) == (0, 501)
    nu = val.free_run(sim, vehicle.damping, vehicle.body, vehicle.theta, rows)
    assert nu.shape == (501, 6)
    two = Samples.concatenate([sim.take(slice(0, 100)), sim.take(slice(100, None))])
    with pytest.raises(ConfigError, match="gap"):
        val.free_run(two, vehicle.damping, vehicle.body, vehicle.theta, slice(50, 150))
    with pytest.raises(ConfigError, match="segment"):
        val.free_run(two, vehicle.damping, vehicle.body, vehicle.theta, 2)
    # an energy-generating model diverges: NaN after the divergence, not an exception
    bad = -10 * vehicle.theta
    out = val.free_run(sim, vehicle.damping, vehicle.body, bad, tau_hold="zero")
    assert np.isnan(out[-1]).all()


# --- force domain --------------------------------------------------------------------------


def test_predicted_force_is_the_model_force(vehicle: Vehicle, sim: Samples) -> None:
    _, y_hat = val.predicted_force(sim, vehicle.damping, vehicle.body, vehicle.theta,
                                        chunk=700)
    np.testing.assert_allclose(y_hat, vehicle.damping.force(sim.nu, vehicle.theta),
                               rtol=1e-12, atol=1e-12)
    # chunked parallel filtering equals filtering the whole segment away from its start
    # (there the first chunk's edge treatment differs: measured over the first 1.3 s)
    a = val.predicted_force(sim, vehicle.damping, vehicle.body, vehicle.theta, 2.0, 700)
    b = val.predicted_force(sim, vehicle.damping, vehicle.body, vehicle.theta, 2.0)
    for x, z in zip(a, b, strict=True):
        np.testing.assert_allclose(x[100:], z[100:], rtol=0, atol=1e-6 * np.abs(z).max())
    # with the true θ the data demand nearly that force (τ is a step mean, ν̇ is not)
    m = val.metrics(*val.predicted_force(sim, vehicle.damping, vehicle.body, vehicle.theta, 2.0))
    assert np.all(m["nse"] > 0.95), m["nse"]


def test_metrics_perfect_and_known_residual() -> None:
    rate = 50.0
    t = np.arange(2000) / rate
    y = np.stack([np.sin(0.3 * (i + 1) * t) * (i + 1) + 0.5 * i for i in range(6)], axis=1)
    m = val.metrics(y, y)
    np.testing.assert_array_equal(m["nse"], 1.0)
    np.testing.assert_array_equal(m["rmse"], 0.0)
    np.testing.assert_array_equal(m["peak_error"], 0.0)
    c = np.array([0.1, -0.2, 0.3, -0.4, 0.5, -0.6])
    m = val.metrics(y, y - c)  # residual r = y − ŷ = c
    std = y.std(axis=0)
    np.testing.assert_allclose(m["rmse"], np.abs(c), rtol=1e-12)
    np.testing.assert_allclose(m["nrmse"], np.abs(c) / std, rtol=1e-12)
    np.testing.assert_allclose(m["nse"], 1.0 - c**2 / std**2, rtol=1e-12)
    np.testing.assert_allclose(m["peak_error"], np.abs(c), rtol=1e-12)
    np.testing.assert_allclose(m["bias"], c, rtol=1e-12)
    assert np.isnan(m["steady_bias"]).all()
    # steady stretches: first half at rest (ν̇ = 0) with residual c, second half accelerating
    # with residual −5c: the steady bias sees only c
    nu_dot = np.zeros_like(y)
    nu_dot[1000:] = np.cos(2.0 * t[1000:, None])
    r = np.where(np.arange(2000)[:, None] < 1000, c, -5 * c)
    m = val.metrics(y, y - r, nu_dot, rate)
    np.testing.assert_allclose(m["steady_bias"], c, rtol=1e-12)
    np.testing.assert_allclose(m["steady_fraction"], 0.5)
    np.testing.assert_allclose(m["bias"], -2 * c, rtol=1e-12)


def test_steady_mask_needs_long_enough_stretches() -> None:
    a = np.ones((100, 6))
    a[10:15] = 0.0  # 5 samples: too short at 10 Hz for 1 s
    a[40:60] = 0.0  # 20 samples: a stretch
    m = val.steady_mask(a, 10.0, level=0.1, min_duration=1.0)
    expected = np.zeros(100, dtype=bool)
    expected[40:60] = True
    np.testing.assert_array_equal(m, np.repeat(expected[:, None], 6, axis=1))


def test_whiteness_of_white_noise_and_of_correlated_noise() -> None:
    rng = np.random.default_rng(0)
    e = rng.normal(size=(20000, 6))
    w = val.residual_whiteness(e, 50.0, max_lag=2.0)
    assert w.acf.shape == (101, 6) and w.lags[-1] == pytest.approx(2.0)
    np.testing.assert_allclose(w.acf[0], 1.0)
    assert w.bound == pytest.approx(1.96 / np.sqrt(20000), rel=1e-3)
    # ~95 % of the lags inside the bounds
    assert np.all(w.fraction_outside <= 0.12), w.fraction_outside
    assert 0.01 <= w.fraction_outside.mean() <= 0.09
    # lag-k autocorrelation equals the direct sum
    x = e[:, 2] - e[:, 2].mean()
    direct = np.dot(x[:-7], x[7:]) / np.dot(x, x)
    assert w.acf[7, 2] == pytest.approx(direct, rel=1e-9)
    # AR(1) with coefficient 0.9: correlated over ~10 samples
    from scipy import signal

    ar = signal.lfilter([1.0], [1.0, -0.9], e, axis=0)
    assert np.all(val.residual_whiteness(ar, 50.0, 0.5).fraction_outside > 0.8)


def test_residual_spectrum_integrates_to_the_variance() -> None:
    rng = np.random.default_rng(1)
    sigma = np.array([1.0, 2.0, 0.5, 0.1, 3.0, 1.5])
    e = rng.normal(size=(50000, 6)) * sigma
    f, p = val.residual_spectrum(e, 50.0, window=10.0)
    assert p.shape == (len(f), 6) and f[-1] == pytest.approx(25.0)
    var = np.sum(p, axis=0) * (f[1] - f[0])
    np.testing.assert_allclose(var, sigma**2, rtol=0.05)


def test_frf_error_of_exact_scaled_and_delayed_predictions(vehicle: Vehicle,
                                                           sim: Samples) -> None:
    y, _ = val.predicted_force(sim, vehicle.damping, vehicle.body, vehicle.theta, 2.0)
    fr = val.frf_error(sim, y, y, sim.rate, f_max=2.0)
    assert fr.band.any(axis=0).all()
    np.testing.assert_allclose(fr.median_gain_db, 0.0, atol=1e-9)
    np.testing.assert_allclose(fr.median_phase_deg, 0.0, atol=1e-6)
    fr = val.frf_error(sim, y, 1.1 * y, sim.rate, f_max=2.0)
    np.testing.assert_allclose(fr.median_gain_db, 20 * np.log10(1.1), rtol=1e-9)
    # a prediction delayed by one sample lags by 360° f / rate
    late = np.roll(y, 1, axis=0)
    fr = val.frf_error(sim, y, late, sim.rate, f_max=2.0)
    expected = -360.0 * fr.f[:, None] / sim.rate
    assert np.all(np.abs(fr.phase_deg - expected)[fr.band] < 3.0)


def test_energy_consistency(vehicle: Vehicle, sim: Samples) -> None:
    frac, lowest = val.energy_consistency(sim, vehicle.damping, vehicle.theta, chunk=1000)
    assert frac == 0.0 and lowest >= 0.0
    theta = vehicle.theta.copy()
    theta[vehicle.damping.parameter_names.index("Y_v")] = -200.0  # generates power in sway
    frac, lowest = val.energy_consistency(sim, vehicle.damping, theta, chunk=1000)
    assert 0.0 < frac < 1.0 and lowest < 0.0
