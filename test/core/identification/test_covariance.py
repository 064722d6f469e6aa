"""The sensor-bias refits' statistics and covariance
(dampest_ros.core.identification.covariance)."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.identification.batch import FitOptions
from dampest_ros.core.identification.covariance import (
    bias_covariance,
    bias_offsets,
    bias_rows,
    bias_statistics,
    pooled_bias,
)
from dampest_ros.core.identification.quadratic import solve_normal
from dampest_ros.core.identification.regression import accumulate
from dampest_ros.core.physics.frames import euler_from_matrix, quat_to_matrix
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.simulate import run
from dampest_ros.io.yaml_io import load_vehicle


@pytest.fixture(scope="module")
def vehicle() -> Vehicle:
    return load_vehicle("bluerov2_heavy")


def flight(vehicle: Vehicle, seed: int, start: float = 0.0) -> Samples:
    """40 s of protocol B at 50 Hz whose τ satisfies Fossen's equation exactly."""
    traj = run(vehicle, make_excitation("B", vehicle, 40.0, seed=seed), dt=0.02)
    R = quat_to_matrix(traj.quaternion)
    tau = (traj.nu_dot @ vehicle.body.M.T + vehicle.body.coriolis_force(traj.nu)
           + vehicle.damping.force(traj.nu, vehicle.theta) + vehicle.body.restoring(R))
    return Samples(traj.t + start, traj.nu, traj.nu_dot, tau, euler_from_matrix(R),
                   traj.position[:, 2], np.zeros(len(traj.t), dtype=np.int64))


def test_a_segment_longer_than_three_stretches_gives_three_stretches_of_it() -> None:
    """Segments of 1000 and 5000 samples, stretches of 1000: the first whole, the second at
    0, 2000 and 4000 of it, each taken stretch its own segment; stretches of 2000 take
    every row (the samples themselves)."""
    n = 6000
    samples = Samples(np.arange(n) * 0.02, np.zeros((n, 6)), np.zeros((n, 6)),
                      np.zeros((n, 6)), np.zeros((n, 3)), np.zeros(n),
                      np.r_[np.zeros(1000), np.ones(5000)].astype(np.int64))
    data, complete = bias_rows(samples, 1000)
    assert not complete
    rows = np.rint(data.t / 0.02).astype(int)
    expected = np.r_[0:1000, 1000:2000, 3000:4000, 5000:6000]
    np.testing.assert_array_equal(rows, expected)
    np.testing.assert_array_equal(data.segment, np.repeat([0, 1, 2, 3], 1000))
    same, complete = bias_rows(samples, 2000)
    assert complete and same is samples


def test_the_statistics_of_two_logs_add_up_to_those_of_both_at_once(vehicle: Vehicle) -> None:
    """Two logs, each its own segment and each cut to three stretches: the statistics of
    the two at once are the sum of each log's (what a pooled fit sums)."""
    opts = FitOptions(cutoff=2.0, bias_stretch=500)
    a, b = flight(vehicle, 1), flight(vehicle, 2, start=100.0)
    b.segment += 1
    both = Samples.concatenate([a, b])
    sa, sb, sab = (bias_statistics(x, vehicle.damping, vehicle.body, opts) for x in (a, b, both))
    assert sa is not None and sb is not None and sab is not None and sab.base is not None
    assert len(sab.A) == 6
    normals = [accumulate(x, vehicle.damping, vehicle.body, cutoff=opts.cutoff) for x in (a, b)]
    summed = pooled_bias([sa, sb], normals)
    assert summed.base is not None
    for got, want in ((summed.A, sab.A), (summed.b, sab.b), (summed.base[0], sab.base[0]),
                      (summed.base[1], sab.base[1])):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    assert bias_statistics(a, vehicle.damping, vehicle.body,
                           FitOptions(cutoff=2.0, gyro_bias=0.0, dvl_bias=0.0)) is None


def test_the_bias_covariance_is_that_of_refits_of_offset_data(vehicle: Vehicle) -> None:
    """Every row taken: Σ_k Δθ_k Δθ_kᵀ, Δθ_k the weighted refit of the data with ν offset
    by σ e_k (normal equations formed afresh from the offset samples) less θ."""
    opts = FitOptions(cutoff=2.0)
    samples = flight(vehicle, 3)
    model, body = vehicle.damping, vehicle.body
    stats = bias_statistics(samples, model, body, opts)
    assert stats is not None and stats.base is None  # every row: differenced from θ
    theta = vehicle.theta
    weights = np.array([1.0, 2.0, 0.5, 30.0, 20.0, 40.0])
    free = np.ones(model.n_params, dtype=bool)
    free[0] = False
    basis = np.eye(int(free.sum()))
    cov = bias_covariance(stats, theta, weights, free, basis)
    expected = np.zeros_like(cov)
    for offset in bias_offsets(opts):
        moved = Samples(samples.t, samples.nu + offset, samples.nu_dot, samples.tau,
                        samples.euler, samples.depth, samples.segment)
        A, b, _ = accumulate(moved, model, body, cutoff=opts.cutoff).total(weights)
        d = solve_normal(A, b, free, theta, basis=basis) - theta
        expected += np.outer(d, d)
    assert np.abs(expected).max() > 0 and cov[0, 0] == 0.0
    np.testing.assert_allclose(cov, expected, rtol=1e-7, atol=1e-9 * np.abs(expected).max())


def test_a_log_taken_whole_pooled_with_one_cut_to_stretches(vehicle: Vehicle) -> None:
    """A log cut to stretches (its refits differenced from its unoffset refit) pooled with
    one taken whole (whose unoffset part is its normal equations'): the statistics of both
    at once."""
    opts = FitOptions(cutoff=2.0, bias_stretch=600)
    a, b = flight(vehicle, 4), flight(vehicle, 5, start=100.0)
    b.segment += 1
    short = b.take(np.arange(1500))  # ≤ 3 stretches: taken whole
    both = Samples.concatenate([a, short])
    model, body = vehicle.damping, vehicle.body
    sa, ss, sab = (bias_statistics(x, model, body, opts) for x in (a, short, both))
    assert sa is not None and ss is not None and sab is not None
    assert sa.base is not None and ss.base is None and sab.base is not None
    normals = [accumulate(x, model, body, cutoff=opts.cutoff) for x in (a, short)]
    summed = pooled_bias([sa, ss], normals)
    assert summed.base is not None
    for got, want in ((summed.A, sab.A), (summed.base[0], sab.base[0]),
                      (summed.base[1], sab.base[1])):
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10 * np.abs(want).max())
