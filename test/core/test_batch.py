"""Batch identification (dampest_ros.core.batch) on exact simulator samples."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.batch import FitOptions, accumulate, fit, iter_regression
from dampest_ros.core.excitation import make_excitation
from dampest_ros.core.frames import euler_from_matrix, quat_to_matrix
from dampest_ros.core.samples import Samples
from dampest_ros.core.simulate import run
from dampest_ros.core.vehicle import Vehicle
from dampest_ros.io.yaml_io import load_vehicle

EXACT = FitOptions(method="ols", cutoff=0.0, gyro_bias=0.0, dvl_bias=0.0)


@pytest.fixture(scope="module")
def vehicle() -> Vehicle:
    return load_vehicle("platform_a")


def exact_samples(vehicle: Vehicle, duration: float = 200.0, still: int | None = None
                  ) -> Samples:
    """ν, ν̇ of a simulated run and the τ that makes Fossen's equation hold exactly at each
    sample (the trajectory's τ is a step mean); ``still`` zeroes one DOF's motion."""
    traj = run(vehicle, make_excitation("B", vehicle, duration, seed=2), dt=0.02)
    nu, nu_dot = traj.nu.copy(), traj.nu_dot.copy()
    if still is not None:
        nu[:, still] = nu_dot[:, still] = 0.0
    R = quat_to_matrix(traj.quaternion)
    tau = (nu_dot @ vehicle.body.M.T + vehicle.body.coriolis_force(nu)
           + vehicle.damping.force(nu, vehicle.theta) + vehicle.body.restoring(R))
    return Samples(traj.t, nu, nu_dot, tau, euler_from_matrix(R), traj.position[:, 2],
                   np.zeros(len(traj.t), dtype=np.int64))


def test_exact_data_give_the_exact_coefficients(vehicle: Vehicle) -> None:
    s = exact_samples(vehicle)
    for method in ("ols", "wls", "bounded"):
        f = fit(s, vehicle.damping, vehicle.body,
                FitOptions(method=method, cutoff=0.0, gyro_bias=0.0, dvl_bias=0.0),
                prior=vehicle.theta)
        np.testing.assert_allclose(f.theta, vehicle.theta, rtol=1e-8, err_msg=method)
        assert not f.flags
    # with the parallel low-pass the regression stays exact (θ is constant)
    f = fit(s, vehicle.damping, vehicle.body, FitOptions(method="ols", cutoff=2.0,
                                                         gyro_bias=0.0, dvl_bias=0.0))
    np.testing.assert_allclose(f.theta, vehicle.theta, rtol=1e-6)


def test_chunking_does_not_change_the_normal_equations(vehicle: Vehicle) -> None:
    s = exact_samples(vehicle, 60.0)
    a = accumulate(s, vehicle.damping, vehicle.body, cutoff=2.0, chunk=500)
    b = accumulate(s, vehicle.damping, vehicle.body, cutoff=2.0, chunk=100000)
    np.testing.assert_allclose(a.A.sum(0), b.A.sum(0), rtol=1e-9)
    np.testing.assert_allclose(a.b.sum(0), b.b.sum(0), rtol=1e-9, atol=1e-9)
    rows = [r for r, _, _ in iter_regression(s, vehicle.damping, vehicle.body, cutoff=2.0,
                                             decimate=True)]
    assert all(np.all(np.asarray(r) % 6 == 0) for r in rows)  # 50 Hz, 2 Hz → every 6th


def test_map_with_a_tight_prior_returns_the_prior_and_bounds_hold(vehicle: Vehicle) -> None:
    s = exact_samples(vehicle, 60.0)
    prior = vehicle.theta * 1.5
    f = fit(s, vehicle.damping, vehicle.body, FitOptions(method="map", cutoff=0.0,
                                                         gyro_bias=0.0, dvl_bias=0.0),
            prior=prior, prior_std=np.full(len(prior), 1e-9))
    np.testing.assert_allclose(f.theta, prior, rtol=1e-6)
    # bounded least squares keeps dissipative signs even when the data push the other way
    noisy = Samples(s.t, s.nu, s.nu_dot, s.tau - 40.0 * s.nu * np.abs(s.nu), s.euler,
                    s.depth, s.segment)
    fb = fit(noisy, vehicle.damping, vehicle.body,
             FitOptions(method="bounded", cutoff=0.0, gyro_bias=0.0, dvl_bias=0.0))
    assert np.all(fb.theta >= -1e-12)
    fo = fit(noisy, vehicle.damping, vehicle.body, EXACT)
    assert fo.theta.min() < 0


def test_an_unexcited_dof_is_flagged_not_reported(vehicle: Vehicle) -> None:
    s = exact_samples(vehicle, 60.0, still=3)  # no roll motion at all
    f = fit(s, vehicle.damping, vehicle.body, EXACT, prior=vehicle.theta)
    assert set(f.flags) == {"K_p", "K_pp"}
    assert "no excitation" in f.flags["K_p"]
    i = f.names.index("K_pp")
    assert f.theta[i] == vehicle.theta[i] and np.isnan(f.std[i])
