"""The block-robust covariance and the sensor-bias refits' statistics and covariance
(dampest_ros.core.identification.covariance)."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.identification.batch import FitOptions, fit
from dampest_ros.core.identification.covariance import (
    bias_covariance,
    bias_offsets,
    bias_rows,
    bias_statistics,
    block_count,
    pooled_bias,
    robust_covariance,
    settled_block,
)
from dampest_ros.core.identification.quadratic import solve_normal
from dampest_ros.core.identification.regression import accumulate, block_index, iter_regression
from dampest_ros.core.physics.frames import euler_from_matrix, quat_to_matrix
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.extent import Extent
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


def two_segments(vehicle: Vehicle) -> Samples:
    """Two 40 s flights (2000 samples) as the two segments of one log, the second 0.7 s
    after the first."""
    a, b = (x.take(np.arange(2000)) for x in (flight(vehicle, 6), flight(vehicle, 7, 40.7)))
    b.segment += 1
    return Samples.concatenate([a, b])


def test_blocks_start_with_each_segment_whatever_comes_before(vehicle: Vehicle) -> None:
    """5 s blocks: 8 per 40 s segment, the second segment's first block starts at its first
    sample (not on the first segment's grid), and a segment's blocks are the same alone;
    their count from the samples' extent is the same."""
    samples = two_segments(vehicle)
    idx = block_index(samples, 5.0)
    first = samples.segment == 0
    assert idx.max() == 15 and np.all(idx[~first] >= 8)
    assert block_count(Extent.of(samples), 5.0) == 16
    np.testing.assert_array_equal(idx[~first] - 8,
                                  block_index(samples.take(np.flatnonzero(~first)), 5.0))
    # 4, 4.5 and 5.02 s into the second segment (44.7, 45.2, 45.72 s: 8, 9, 9 on the first's
    # grid)
    np.testing.assert_array_equal(idx[~first][[200, 225, 251]], [8, 8, 9])


def test_the_block_equations_give_each_blocks_score_of_the_residuals(vehicle: Vehicle
                                                                     ) -> None:
    """s_b = Σ_i w_i (h_bi − G_bi θ) equals Σ_{n ∈ b} Σ_i w_i Φ_niᵀ (y_ni − Φ_ni θ) formed from
    the regression rows, with a guard between folds (its rows are in no fold, but in a
    block), to 1e-9 of the largest score."""
    samples, model, body = two_segments(vehicle), vehicle.damping, vehicle.body
    ne = accumulate(samples, model, body, cutoff=2.0, guard=50, block=5.0)
    assert ne.blocks is not None and ne.blocks.G.shape == (16, 6, 12, 12)
    theta = 1.1 * vehicle.theta
    weights = np.array([1.0, 2.0, 0.5, 30.0, 20.0, 40.0])
    free = np.ones(model.n_params, dtype=bool)
    free[3] = False
    idx = block_index(samples, 5.0)
    want = np.zeros((16, 11))
    for rows, Phi, y in iter_regression(samples, model, body, cutoff=2.0, decimate=True):
        g = np.einsum("nip,ni,i->np", Phi[:, :, free], y - Phi @ theta, weights)
        np.add.at(want, idx[rows], g)
    got = ne.blocks.scores(theta, weights, free)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.abs(want).max())
    assert ne.n.sum() < sum(len(r) for r, _, _ in iter_regression(
        samples, model, body, cutoff=2.0, decimate=True))  # the guard's rows: in no fold


def test_blocks_with_the_normal_equations_give_the_passs_covariance(vehicle: Vehicle
                                                                   ) -> None:
    """Two segments, 2 s blocks (the floor of a 2 Hz low-pass, so settled whatever the
    rank): the robust covariance from the blocks formed with the normal equations equals
    the one whose blocks a pass over the samples forms, to 1e-10; a pass is taken only
    without them."""
    samples, model, body = two_segments(vehicle), vehicle.damping, vehicle.body
    opts = FitOptions(cutoff=2.0, block=2.0)
    extent = Extent.of(samples)
    assert settled_block(extent, opts, model.n_params) == 2.0
    assert settled_block(extent, FitOptions(cutoff=2.0), model.n_params) == 0.0
    with_blocks = accumulate(samples, model, body, cutoff=2.0, block=2.0)
    without = accumulate(samples, model, body, cutoff=2.0)
    theta = fit(samples, model, body, opts, normal=without).theta
    weights, free = np.ones(6), np.ones(model.n_params, dtype=bool)
    basis = np.eye(model.n_params)
    passes: list[int] = []

    def counted(fn):  # type: ignore[no-untyped-def]
        passes.append(1)
        return [fn(samples, 0)]

    got = robust_covariance(extent, model, body, theta, weights, with_blocks, free, basis,
                            opts, counted)
    assert not passes
    want = robust_covariance(extent, model, body, theta, weights, without, free, basis,
                             opts, counted)
    assert passes == [1]
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10 * np.abs(want).max())
