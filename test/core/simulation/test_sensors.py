"""Sensor models (dampest_ros.core.simulation.sensors): frames, physics, interpolation, noise,
rates."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pytest

from dampest_ros.core.physics.frames import matrix_from_euler, matrix_to_quat
from dampest_ros.core.signals.measurements import (
    ImuSeries,
    JointSeries,
    OdometrySeries,
    PressureSeries,
    TwistSeries,
)
from dampest_ros.core.simulation.sensors import (
    UNUSED_VARIANCE,
    SensorBias,
    SensorConfig,
    measure,
    sample_times,
)
from dampest_ros.core.simulation.stream import LiveSimulation
from dampest_ros.core.simulation.trajectory import Trajectory
from dampest_ros.io.yaml_io import load_vehicle

RHO, G = 1025.0, 9.81
ATM = 101325.0

#: Every noise source off, dropouts off.
EXACT = SensorConfig(gyro_noise=0.0, gyro_bias_walk=0.0, accel_noise=0.0, accel_bias_walk=0.0,
                     orientation_noise=0.0, dvl_noise=0.0, dvl_dropout_rate=0.0,
                     pressure_noise=0.0, rpm_noise=0.0)

Fn = Callable[[np.ndarray], np.ndarray]


def make_traj(duration: float, dt: float, nu: Fn, nu_dot: Fn, euler: Fn | None = None,
              position: Fn | None = None, n_thrusters: int = 0) -> Trajectory:
    """A hand-built ground truth: ν(t), ν̇(t), Euler angles (φ, θ, ψ)(t) and NED position."""
    n = round(duration / dt) + 1
    t = np.arange(n) * dt
    angles = euler(t) if euler is not None else np.zeros((n, 3))
    pos = position(t) if position is not None else np.zeros((n, 3))
    return Trajectory(
        t=t,
        position=pos,
        quaternion=matrix_to_quat(matrix_from_euler(angles)),
        nu=nu(t),
        nu_dot=nu_dot(t),
        tau=np.zeros((n, 6)),
        rotor_speed=np.tile(t[:, None], (1, n_thrusters)) * (1.0 + np.arange(n_thrusters)),
        thrust=np.tile(3.0 * t[:, None], (1, n_thrusters)) - np.arange(n_thrusters),
        current=np.zeros((n, 3)),
        memory=np.zeros((n, 0)),
        thruster_names=tuple(f"thruster_{i}" for i in range(n_thrusters)),
    )


def const(values: list[float]) -> Fn:
    return lambda t: np.tile(np.asarray(values, dtype=float), (len(t), 1))


def at_rest(duration: float = 2.0, dt: float = 0.01, depth: float = 0.0,
            euler: list[float] | None = None, n_thrusters: int = 0) -> Trajectory:
    return make_traj(duration, dt, const([0.0] * 6), const([0.0] * 6),
                     euler=const(euler or [0.0, 0.0, 0.0]), position=const([3.0, -2.0, depth]),
                     n_thrusters=n_thrusters)


# --- frames and physics --------------------------------------------------------------------


def test_at_rest_level_reads_plus_g_up_and_hydrostatic_pressure() -> None:
    rec = measure(at_rest(depth=10.0), RHO, G, EXACT)
    imu = rec["imu/data"]
    assert isinstance(imu, ImuSeries)
    np.testing.assert_allclose(imu.linear_acceleration, np.tile([0.0, 0.0, G], (401, 1)),
                               rtol=0, atol=1e-12)
    np.testing.assert_array_equal(np.abs(imu.angular_velocity), 0.0)
    pressure = rec["pressure"]
    assert isinstance(pressure, PressureSeries)
    np.testing.assert_array_equal(pressure.fluid_pressure, ATM + RHO * G * 10.0)
    assert pressure.variance == 0.0
    # facing north (ψ = 0 NED) is yaw +90° in ENU: q_xyzw = [0, 0, sin 45°, cos 45°]
    s = np.sqrt(0.5)
    np.testing.assert_allclose(imu.orientation, np.tile([0.0, 0.0, s, s], (401, 1)), atol=1e-15)
    odom = rec["truth/odom"]
    assert isinstance(odom, OdometrySeries)
    # NED (3, −2, 10) → ENU (−2, 3, −10)
    np.testing.assert_allclose(odom.position, np.tile([-2.0, 3.0, -10.0], (101, 1)), atol=1e-12)


def test_pitched_up_at_rest_reads_gravity_on_forward_axis() -> None:
    theta = np.deg2rad(30.0)  # nose up (positive pitch in FRD/NED)
    rec = measure(at_rest(euler=[0.0, theta, 0.0]), RHO, G, EXACT)
    imu = rec["imu/data"]
    assert isinstance(imu, ImuSeries)
    # f = −Rᵀ[0, 0, g] = [g sin θ, 0, −g cos θ] FRD = [g sin θ, 0, g cos θ] FLU
    np.testing.assert_allclose(imu.linear_acceleration[0],
                               [G * np.sin(theta), 0.0, G * np.cos(theta)], atol=1e-12)


def test_surge_and_sway_signs_in_ros_frames() -> None:
    surge = measure(make_traj(2.0, 0.01, const([1.0, 0, 0, 0, 0, 0]), const([0.0] * 6),
                              position=lambda t: np.column_stack([t, 0 * t, 0 * t])),
                    RHO, G, EXACT)
    dvl = surge["dvl/twist"]
    assert isinstance(dvl, TwistSeries)
    assert dvl.frame_id == "dvl_link"
    np.testing.assert_allclose(dvl.linear, np.tile([1.0, 0.0, 0.0], (17, 1)), atol=1e-12)
    odom = surge["truth/odom"]
    assert isinstance(odom, OdometrySeries)
    # heading north at 1 m/s: ENU y grows, x and z stay
    np.testing.assert_allclose(odom.position[:, 1], odom.stamp, atol=1e-12)
    np.testing.assert_allclose(odom.position[:, [0, 2]], 0.0, atol=1e-12)
    np.testing.assert_allclose(odom.linear[-1], [1.0, 0.0, 0.0], atol=1e-12)

    sway = measure(make_traj(2.0, 0.01, const([0, 1.0, 0, 0, 0, 0]), const([0.0] * 6),
                             position=lambda t: np.column_stack([0 * t, t, 0 * t])),
                   RHO, G, EXACT)
    dvl = sway["dvl/twist"]
    assert isinstance(dvl, TwistSeries)
    # starboard (+y FRD) is −y FLU
    np.testing.assert_allclose(dvl.linear, np.tile([0.0, -1.0, 0.0], (17, 1)), atol=1e-12)
    odom = sway["truth/odom"]
    assert isinstance(odom, OdometrySeries)
    # moving east (NED y) is ENU +x
    np.testing.assert_allclose(odom.position[:, 0], odom.stamp, atol=1e-12)


def test_turning_right_at_constant_yaw_rate() -> None:
    u, r = 1.0, 0.1

    def circle(t: np.ndarray) -> np.ndarray:
        return np.column_stack([u / r * np.sin(r * t), u / r * (1 - np.cos(r * t)), 0 * t])

    # dt = 0.05 so that the 50 Hz truth and 200 Hz IMU samples fall between the steps
    traj = make_traj(20.0, 0.05, const([u, 0, 0, 0, 0, r]), const([0.0] * 6),
                     euler=lambda t: np.column_stack([0 * t, 0 * t, r * t]), position=circle)
    rec = measure(traj, RHO, G, EXACT)
    imu, odom = rec["imu/data"], rec["truth/odom"]
    assert isinstance(imu, ImuSeries) and isinstance(odom, OdometrySeries)
    # a right turn (r > 0 FRD) is a negative yaw rate about FLU z
    np.testing.assert_allclose(imu.angular_velocity, np.tile([0, 0, -r], (len(imu), 1)),
                               atol=1e-12)
    # centripetal ω × v = [0, r u, 0] FRD (towards starboard) = [0, −r u, 0] FLU, plus +g
    np.testing.assert_allclose(imu.linear_acceleration,
                               np.tile([0, -r * u, G], (len(imu), 1)), atol=1e-12)
    # position interpolated between the 0.05 s steps follows the circle (ENU = [e, n, −d])
    ned = circle(odom.stamp)
    np.testing.assert_allclose(odom.position, ned[:, [1, 0, 2]] * [1, 1, -1], atol=1e-9)
    # ENU yaw = π/2 − ψ; quaternion about z: [0, 0, sin(yaw/2), cos(yaw/2)]
    yaw = np.pi / 2 - r * odom.stamp
    expect = np.column_stack([0 * yaw, 0 * yaw, np.sin(yaw / 2), np.cos(yaw / 2)])
    np.testing.assert_allclose(odom.orientation, expect, atol=1e-8)
    np.testing.assert_allclose(odom.angular, np.tile([0, 0, -r], (len(odom), 1)), atol=1e-12)


def test_hermite_interpolation_of_specific_force() -> None:
    traj = make_traj(10.0, 0.01,
                     nu=lambda t: np.column_stack([np.sin(t)] + [0 * t] * 5),
                     nu_dot=lambda t: np.column_stack([np.cos(t)] + [0 * t] * 5),
                     position=lambda t: np.column_stack([1 - np.cos(t), 0 * t, 0 * t]))
    rec = measure(traj, RHO, G, EXACT)
    imu, odom = rec["imu/data"], rec["truth/odom"]
    assert isinstance(imu, ImuSeries) and isinstance(odom, OdometrySeries)
    assert len(imu) == 2001  # 200 Hz: half the samples fall between the 0.01 s steps
    err = imu.linear_acceleration[:, 0] - np.cos(imu.stamp)
    assert np.max(np.abs(err)) < 1e-6
    # bound on the cubic Hermite slope error: √3/216 · h³ · max|f⁗| ≈ 8e-9
    assert np.max(np.abs(err)) < 1e-8
    np.testing.assert_allclose(odom.linear[:, 0], np.sin(odom.stamp), atol=1e-9)
    np.testing.assert_allclose(odom.position[:, 1], 1 - np.cos(odom.stamp), atol=1e-9)


def test_biases_are_frd_and_appear_in_flu() -> None:
    bias = SensorBias(gyro=(0.01, 0.02, 0.03), accel=(0.1, 0.2, 0.3), dvl=(0.05, 0.06, 0.07))
    rec = measure(at_rest(), RHO, G, EXACT, bias)
    imu, dvl = rec["imu/data"], rec["dvl/twist"]
    assert isinstance(imu, ImuSeries) and isinstance(dvl, TwistSeries)
    np.testing.assert_allclose(imu.angular_velocity[7], [0.01, -0.02, -0.03], atol=1e-15)
    np.testing.assert_allclose(imu.linear_acceleration[7], [0.1, -0.2, G - 0.3], atol=1e-12)
    np.testing.assert_allclose(dvl.linear[3], [0.05, -0.06, -0.07], atol=1e-15)


def test_thruster_state_is_rad_per_s_and_window_mean_of_step_means() -> None:
    # Four steps of dt = 0.03 s; rotor_speed/thrust hold the step MEANS over [t_k, t_k + dt],
    # so the truth is piecewise constant on [0, .03), [.03, .06), [.06, .09), [.09, .12].
    traj = replace(at_rest(duration=0.09, dt=0.03, n_thrusters=2),
                   rotor_speed=np.array([[1.0, 10.0], [2.0, 20.0], [4.0, 40.0], [8.0, 80.0]]),
                   thrust=np.array([[3.0, 0.5], [-3.0, 0.5], [0.0, 0.5], [6.0, 0.5]]))
    js = measure(traj, RHO, G, replace(EXACT, thruster_rate=50.0))["thrusters/state"]
    assert isinstance(js, JointSeries)
    assert js.names == ("thruster_0", "thruster_1")
    assert js.frame_id == "base_link"
    # 50 Hz: stamp s reports the mean over [s − 0.02, s]; first stamp t0 + 1/rate, last at the
    # end of the last step (0.12). Windows straddling a step edge average the two halves:
    #   [0, .02] → 1     [.02, .04] → (1 + 2)/2    [.04, .06] → 2
    #   [.06, .08] → 4   [.08, .10] → (4 + 8)/2    [.10, .12] → 8
    np.testing.assert_allclose(js.stamp, [0.02, 0.04, 0.06, 0.08, 0.10, 0.12], rtol=0,
                               atol=1e-15)
    n = np.array([1.0, 1.5, 2.0, 4.0, 6.0, 8.0])
    # velocity in rad/s: 2π n (n in rev/s); thruster 1 spins 10× thruster 0
    np.testing.assert_allclose(js.velocity, 2 * np.pi * np.column_stack([n, 10.0 * n]),
                               rtol=0, atol=1e-12)
    # thrust: 3 | (3 − 3)/2 | −3 | 0 | (0 + 6)/2 | 6; a constant stays constant
    np.testing.assert_allclose(js.effort, [[3.0, 0.5], [0.0, 0.5], [-3.0, 0.5], [0.0, 0.5],
                                           [3.0, 0.5], [6.0, 0.5]], rtol=0, atol=1e-12)


def test_thruster_window_mean_matches_brute_force_average() -> None:
    # Steps (0.03 s) and windows (1/40 s) misaligned; average the piecewise-constant step
    # means by the midpoint rule on a 1/6000 s grid, on which every step edge and window edge
    # lies, so the quadrature is exact.
    rng = np.random.default_rng(3)
    base = at_rest(duration=0.6, dt=0.03, n_thrusters=3)
    traj = replace(base, rotor_speed=rng.normal(size=base.rotor_speed.shape),
                   thrust=rng.normal(size=base.thrust.shape))
    js = measure(traj, RHO, G, replace(EXACT, thruster_rate=40.0))["thrusters/state"]
    assert isinstance(js, JointSeries)
    np.testing.assert_allclose(js.stamp, np.arange(1, 26) / 40.0, rtol=0, atol=1e-12)
    h = 1.0 / 6000.0
    for k, s in enumerate(js.stamp):
        mid = s - 1.0 / 40.0 + h * (np.arange(150) + 0.5)
        step = np.floor(mid / 0.03).astype(int)
        np.testing.assert_allclose(js.effort[k], traj.thrust[step].mean(axis=0), atol=1e-12)
        np.testing.assert_allclose(js.velocity[k],
                                   2 * np.pi * traj.rotor_speed[step].mean(axis=0), atol=1e-12)


def test_frames_ids_and_covariances() -> None:
    cfg = SensorConfig()
    rec = measure(at_rest(), RHO, G, cfg)
    assert [rec[k].frame_id for k in ("truth/odom", "imu/data", "dvl/twist", "pressure",
                                      "thrusters/state")] == \
        ["odom", "imu_link", "dvl_link", "pressure_link", "base_link"]
    odom, imu, dvl, p = rec["truth/odom"], rec["imu/data"], rec["dvl/twist"], rec["pressure"]
    assert isinstance(odom, OdometrySeries) and odom.child_frame_id == "base_link"
    assert isinstance(imu, ImuSeries)
    np.testing.assert_allclose(imu.angular_velocity_covariance, (np.eye(3) * 0.002**2).ravel())
    np.testing.assert_allclose(imu.linear_acceleration_covariance, (np.eye(3) * 0.02**2).ravel())
    np.testing.assert_allclose(imu.orientation_covariance, (np.eye(3) * 0.002**2).ravel())
    assert isinstance(dvl, TwistSeries)
    np.testing.assert_allclose(dvl.covariance.reshape(6, 6),
                               np.diag([0.005**2] * 3 + [UNUSED_VARIANCE] * 3))
    assert isinstance(p, PressureSeries) and p.variance == 400.0
    for series in rec.values():
        series.validate()


def test_shared_covariances_survive_select() -> None:
    # 9 IMU messages: as many as the 9 covariance entries, which must not be masked
    imu = measure(at_rest(duration=0.04), RHO, G)["imu/data"]
    assert isinstance(imu, ImuSeries) and len(imu) == 9
    kept = imu.select(np.arange(9) % 2 == 0)
    assert isinstance(kept, ImuSeries) and len(kept) == 5
    np.testing.assert_array_equal(kept.angular_velocity_covariance,
                                  imu.angular_velocity_covariance)
    kept.validate()


# --- noise ---------------------------------------------------------------------------------


def test_gyro_and_accel_noise_statistics_at_rest() -> None:
    cfg = SensorConfig()
    imu = measure(at_rest(duration=20.0), RHO, G, cfg, seed=3)["imu/data"]
    assert isinstance(imu, ImuSeries)
    assert len(imu) == 4001
    gyro_std = imu.angular_velocity.std(axis=0)
    np.testing.assert_allclose(gyro_std, 0.002, rtol=0.10)
    accel_err = imu.linear_acceleration - [0.0, 0.0, G]
    np.testing.assert_allclose(accel_err.std(axis=0), 0.02, rtol=0.10)
    assert np.all(np.abs(imu.angular_velocity.mean(axis=0)) < 3 * 0.002 / np.sqrt(4001) + 1e-4)


def test_bias_random_walk_increments() -> None:
    cfg = SensorConfig(gyro_noise=0.0, gyro_bias_walk=0.01, accel_noise=0.0,
                       accel_bias_walk=0.1, imu_rate=100.0)
    imu = measure(at_rest(duration=100.0, dt=0.1), RHO, G, cfg, seed=5)["imu/data"]
    assert isinstance(imu, ImuSeries)
    # bias starts at zero; increments per sample have std σ_w √Δt
    np.testing.assert_allclose(imu.angular_velocity[0], 0.0, atol=0)
    step = np.diff(imu.angular_velocity, axis=0).std(axis=0)
    np.testing.assert_allclose(step, 0.01 * np.sqrt(0.01), rtol=0.05)
    step = np.diff(imu.linear_acceleration, axis=0).std(axis=0)
    np.testing.assert_allclose(step, 0.1 * np.sqrt(0.01), rtol=0.05)


def test_orientation_noise_is_a_small_rotation_of_the_given_size() -> None:
    cfg = SensorConfig(orientation_noise=0.01)
    imu = measure(at_rest(duration=20.0, euler=[0.2, -0.1, 1.0]), RHO, G, cfg, seed=2)
    clean = measure(at_rest(duration=20.0, euler=[0.2, -0.1, 1.0]), RHO, G, EXACT)
    a, b = imu["imu/data"], clean["imu/data"]
    assert isinstance(a, ImuSeries) and isinstance(b, ImuSeries)
    np.testing.assert_allclose(np.linalg.norm(a.orientation, axis=1), 1.0, atol=1e-12)
    # relative rotation b⁻¹ a, small angle: rotation vector ≈ 2 × its vector part
    x0, y0, z0, w0 = b.orientation.T
    x1, y1, z1, w1 = a.orientation.T
    rel = np.column_stack([
        w0 * x1 - x0 * w1 - y0 * z1 + z0 * y1,
        w0 * y1 + x0 * z1 - y0 * w1 - z0 * x1,
        w0 * z1 - x0 * y1 + y0 * x1 - z0 * w1,
    ]) * 2.0
    np.testing.assert_allclose(rel.std(axis=0), 0.01, rtol=0.10)
    assert np.all(np.abs(rel.mean(axis=0)) < 1e-3)


def test_dvl_dropouts_remove_messages_at_the_expected_fraction() -> None:
    rate, mean = 0.2, 1.0
    # a fast DVL, so that dropouts shorter than a ping (which remove nothing) are rare
    cfg = SensorConfig(dvl_dropout_rate=rate, dvl_dropout_mean=mean, dvl_rate=50.0, imu_rate=1.0)
    duration = 5000.0
    dvl = measure(at_rest(duration=duration, dt=0.5), RHO, G, cfg, seed=11)["dvl/twist"]
    assert isinstance(dvl, TwistSeries)
    grid = sample_times(0.0, duration, 50.0)
    assert len(grid) == 250001
    # gaps are missing messages on the grid, never NaN
    assert np.all(np.isfinite(dvl.linear))
    assert np.all(np.isin(dvl.stamp, grid))
    lost = 1.0 - len(dvl) / len(grid)
    expected = rate * mean / (1.0 + rate * mean)  # 1/6; ~830 cycles → ±6 % (1σ)
    assert abs(lost - expected) < 0.15 * expected
    gaps = np.diff(dvl.stamp)
    gaps = gaps[gaps > 1.5 / 50.0]
    # about rate · duration / (1 + rate · mean) ≈ 833 ± 29 dropouts, of mean length ≈ 1 s
    assert 740 < len(gaps) < 930
    assert abs(np.mean(gaps - 1.0 / 50.0) - mean) < 0.12 * mean

    off = measure(at_rest(duration=100.0), RHO, G, SensorConfig(dvl_dropout_rate=0.0))
    assert len(off["dvl/twist"]) == 801


def test_dvl_noise_std() -> None:
    cfg = SensorConfig(dvl_dropout_rate=0.0, dvl_rate=5.0)
    dvl = measure(at_rest(duration=400.0, dt=0.1), RHO, G, cfg, seed=4)["dvl/twist"]
    assert isinstance(dvl, TwistSeries)
    assert len(dvl) == 2001
    np.testing.assert_allclose(dvl.linear.std(axis=0), 0.005, rtol=0.10)
    np.testing.assert_array_equal(dvl.angular, 0.0)


# --- rates, seeds, config ------------------------------------------------------------------


def test_sample_counts_follow_the_rates() -> None:
    rec = measure(at_rest(duration=20.0), RHO, G, SensorConfig(dvl_dropout_rate=0.0))
    # thrusters/state: 50 Hz windows [s − 0.02, s] inside [0, 20.01], so s = 0.02 … 20.00
    assert {k: len(v) for k, v in rec.items()} == {
        "truth/odom": 1001, "imu/data": 4001, "dvl/twist": 161, "pressure": 401,
        "thrusters/state": 1000}
    cfg = SensorConfig(imu_rate=100.0, dvl_rate=5.0, pressure_rate=10.0, thruster_rate=25.0,
                       truth_rate=7.0, dvl_dropout_rate=0.0)
    rec = measure(at_rest(duration=1.01), RHO, G, cfg)
    assert {k: len(v) for k, v in rec.items()} == {
        "truth/odom": 8, "imu/data": 102, "dvl/twist": 6, "pressure": 11, "thrusters/state": 25}
    np.testing.assert_allclose(rec["truth/odom"].stamp, np.arange(8) / 7.0, atol=0)
    # thruster messages close a window of one period: stamps t0 + k/25, k = 1 … 25, the last
    # at the end of the last step (1.01 + dt = 1.02 s)
    np.testing.assert_allclose(rec["thrusters/state"].stamp, np.arange(1, 26) / 25.0,
                               rtol=0, atol=1e-12)
    assert np.all(np.diff(rec["imu/data"].stamp) > 0)


def test_sample_times_grid() -> None:
    np.testing.assert_array_equal(sample_times(1.0, 2.0, 4.0), [1.0, 1.25, 1.5, 1.75, 2.0])
    assert len(sample_times(0.0, 600.0000000001, 200.0)) == 120001
    assert len(sample_times(0.0, 599.9999999999, 200.0)) == 120001
    assert len(sample_times(0.0, 0.0, 200.0)) == 1


def test_seeds_reproduce_and_differ() -> None:
    traj = at_rest(duration=5.0, n_thrusters=2)
    a, b = measure(traj, RHO, G, seed=7), measure(traj, RHO, G, seed=7)
    c = measure(traj, RHO, G, seed=8)
    for topic in a:
        for name, arr in a[topic].arrays().items():
            np.testing.assert_array_equal(arr, b[topic].arrays()[name])
    for topic in ("imu/data", "dvl/twist", "pressure", "thrusters/state"):
        assert len(a[topic]) > 0
    ia, ic = a["imu/data"], c["imu/data"]
    assert isinstance(ia, ImuSeries) and isinstance(ic, ImuSeries)
    assert not np.array_equal(ia.angular_velocity, ic.angular_velocity)
    pa, pc = a["pressure"], c["pressure"]
    assert isinstance(pa, PressureSeries) and isinstance(pc, PressureSeries)
    assert not np.array_equal(pa.fluid_pressure, pc.fluid_pressure)


def test_streams_are_independent_per_sensor() -> None:
    traj = at_rest(duration=30.0)
    base = measure(traj, RHO, G, SensorConfig(), seed=1)
    other = measure(traj, RHO, G, SensorConfig(dvl_noise=0.05, dvl_rate=5.0,
                                               dvl_dropout_rate=0.5, pressure_noise=1.0),
                    seed=1)
    for name, arr in base["imu/data"].arrays().items():
        np.testing.assert_array_equal(arr, other["imu/data"].arrays()[name])
    # no noise on the gyro leaves the accelerometer's noise unchanged
    quiet_gyro = measure(traj, RHO, G, SensorConfig(gyro_noise=0.0), seed=1)
    a, b = base["imu/data"], quiet_gyro["imu/data"]
    assert isinstance(a, ImuSeries) and isinstance(b, ImuSeries)
    np.testing.assert_array_equal(a.linear_acceleration, b.linear_acceleration)
    # dropouts come from their own stream: the kept DVL samples keep their noise
    no_drop = measure(traj, RHO, G, SensorConfig(dvl_dropout_rate=0.0), seed=1)["dvl/twist"]
    drop = measure(traj, RHO, G, SensorConfig(dvl_dropout_rate=0.5), seed=1)["dvl/twist"]
    assert isinstance(no_drop, TwistSeries) and isinstance(drop, TwistSeries)
    assert len(drop) < len(no_drop)
    keep = np.isin(no_drop.stamp, drop.stamp)
    np.testing.assert_array_equal(no_drop.linear[keep], drop.linear)


def test_config_from_dict_and_validation() -> None:
    cfg = SensorConfig.from_dict({"imu_rate": 100, "dvl_noise": 0.01})
    assert cfg.imu_rate == 100.0 and isinstance(cfg.imu_rate, float)
    assert cfg.dvl_noise == 0.01 and cfg.pressure_rate == 20.0
    with pytest.raises(ValueError, match="imu_rat"):
        SensorConfig.from_dict({"imu_rat": 100})
    with pytest.raises(ValueError, match="dvl_rate"):
        SensorConfig(dvl_rate=0.0)
    with pytest.raises(ValueError, match="gyro_noise"):
        SensorConfig(gyro_noise=-1.0)
    with pytest.raises(ValueError, match="truth_rate"):
        SensorConfig.from_dict({"truth_rate": "fast"})
    bias = SensorBias.from_dict({"gyro": [1, 2, 3]})
    assert bias.gyro == (1.0, 2.0, 3.0) and bias.dvl == (0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="mag"):
        SensorBias.from_dict({"mag": [0, 0, 0]})
    with pytest.raises(ValueError, match="accel"):
        SensorBias(accel=(1.0, 2.0))  # type: ignore[arg-type]


def test_bad_trajectory_is_rejected() -> None:
    traj = at_rest(n_thrusters=2)
    traj.thruster_names = ("only_one",)
    with pytest.raises(ValueError, match="rotor_speed"):
        measure(traj, RHO, G)
    with pytest.raises(ValueError, match="rho"):
        measure(at_rest(), 0.0, G)


def test_single_sample_trajectory() -> None:
    rec = measure(at_rest(duration=0.0, depth=2.0), RHO, G, EXACT)
    assert all(len(v) == 1 for v in rec.values())
    p = rec["pressure"]
    assert isinstance(p, PressureSeries)
    assert p.fluid_pressure[0] == ATM + RHO * G * 2.0


def test_live_simulation_messages_do_not_depend_on_the_advance_span() -> None:
    """One advance over 400 integration steps (more than the stream's thruster history of
    256) gives the same thruster telemetry as advancing 0.1 s at a time."""
    v = load_vehicle("bluerov2_heavy")
    one, steps = LiveSimulation(v, "B", 10.0, seed=3), LiveSimulation(v, "B", 10.0, seed=3)
    long = one.advance(8.0)["thrusters/state"]
    parts = [steps.advance(0.1 * (k + 1))["thrusters/state"] for k in range(80)]
    effort = np.concatenate([p.effort for p in parts if len(p.stamp)])
    stamp = np.concatenate([p.stamp for p in parts if len(p.stamp)])
    assert isinstance(long, JointSeries)
    np.testing.assert_array_equal(long.stamp, stamp)
    np.testing.assert_allclose(long.effort, effort, rtol=0, atol=1e-9)
    assert np.abs(long.effort).max() > 1.0  # the vehicle is being flown
