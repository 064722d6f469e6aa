"""Pooled identification over several logs and the drift test
(dampest_ros.core.identification.pool)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from dampest_ros.core.identification.batch import FitOptions, fit
from dampest_ros.core.identification.pool import (
    MapLogs,
    drift,
    log_statistics,
    map_here,
    pooled_fit,
)
from dampest_ros.core.physics.frames import euler_from_matrix, quat_to_matrix
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.simulate import run
from dampest_ros.io.yaml_io import load_vehicle

OPTIONS = FitOptions(method="wls", cutoff=2.0, gyro_bias=0.0, dvl_bias=0.0)


@pytest.fixture(scope="module")
def vehicle() -> Vehicle:
    return load_vehicle("bluerov2_heavy")


def noisy_log(vehicle: Vehicle, seed: int, scale: float = 1.0, start: float = 0.0
              ) -> Samples:
    """60 s of protocol B whose τ satisfies Fossen's equation with damping ``scale`` × the
    vehicle's, plus white force noise of 2 % of each DOF's RMS force (seeded)."""
    traj = run(vehicle, make_excitation("B", vehicle, 60.0, seed=seed), dt=0.02)
    R = quat_to_matrix(traj.quaternion)
    tau = (traj.nu_dot @ vehicle.body.M.T + vehicle.body.coriolis_force(traj.nu)
           + vehicle.damping.force(traj.nu, scale * vehicle.theta) + vehicle.body.restoring(R))
    rng = np.random.default_rng(seed)
    tau = tau + 0.02 * np.sqrt(np.mean(tau**2, axis=0)) * rng.standard_normal(tau.shape)
    return Samples(traj.t + start, traj.nu, traj.nu_dot, tau, euler_from_matrix(R),
                   traj.position[:, 2], np.zeros(len(traj.t), dtype=np.int64))


def test_the_pooled_fit_is_the_fit_of_all_samples_at_once(vehicle: Vehicle) -> None:
    samples = [noisy_log(vehicle, k, start=100.0 * k) for k in range(3)]
    logs = [log_statistics(f"log{k}", s, vehicle.damping, vehicle.body, OPTIONS)
            for k, s in enumerate(samples)]
    pooled = pooled_fit(logs, vehicle.damping, vehicle.body, OPTIONS, map_here(samples))
    once = fit(Samples.concatenate(samples), vehicle.damping, vehicle.body, OPTIONS)
    np.testing.assert_allclose(pooled.theta, once.theta, rtol=1e-10, atol=0)
    np.testing.assert_allclose(pooled.std, once.std, rtol=1e-10, atol=0)
    np.testing.assert_allclose(pooled.r2, once.r2, rtol=1e-12)
    assert pooled.n == once.n == sum(g.fit.n for g in logs)  # decimated samples


@pytest.mark.parametrize(("block", "passes"), [(10.0, 4), (2.0, 3)])
def test_the_pooled_covariance_is_formed_log_by_log(vehicle: Vehicle, block: float,
                                                    passes: int) -> None:
    """With the sensor-bias budget on and logs longer than three refit stretches (so each log
    is refitted on three stretches of it), the bias refits' statistics are each log's,
    summed, the pooled extent, the dissipativity check's scan of the samples and the
    pure-axis check's sums run log by log through map_logs, and the σ are those of all
    samples at once. The robust covariance's blocks come with each log's statistics when
    their length is settled before the fit (2 s blocks, the floor); 10 s blocks are
    shortened for 60 s logs by the rank, so the covariance takes a pass of its own."""
    options = FitOptions(method="wls", cutoff=2.0, bias_stretch=900, block=block)
    samples = [noisy_log(vehicle, k, start=100.0 * k) for k in range(4)]
    logs = [log_statistics(f"log{k}", s, vehicle.damping, vehicle.body, options)
            for k, s in enumerate(samples)]
    visits: list[int] = []
    here = map_here(samples)

    def map_logs(fn: Any) -> list[Any]:
        visits.extend(range(len(logs)))
        return here(fn)

    counted: MapLogs = map_logs
    pooled = pooled_fit(logs, vehicle.damping, vehicle.body, options, counted)
    whole = Samples.concatenate(samples)
    once = fit(whole, vehicle.damping, vehicle.body, options)
    assert all(len(s) > 3 * options.bias_stretch for s in samples)
    assert all(g.bias is not None and g.bias.base is not None for g in logs)
    np.testing.assert_allclose(pooled.theta, once.theta, rtol=1e-10, atol=0)
    np.testing.assert_allclose(pooled.std, once.std, rtol=1e-10, atol=0)
    # the extent's; the robust pass, if any; the dissipativity scan; the pure-axis check
    assert visits == [0, 1, 2, 3] * passes
    assert all((g.normal.blocks is not None) == (passes == 3) for g in logs)
    without = fit(whole, vehicle.damping, vehicle.body,
                  FitOptions(method="wls", cutoff=2.0, gyro_bias=0.0, dvl_bias=0.0,
                             block=block))
    assert np.all(once.std >= without.std) and np.any(once.std > 1.01 * without.std)


def test_a_20_percent_change_is_found_between_the_right_logs(vehicle: Vehicle) -> None:
    """Five logs a day apart; from the fourth on the damping is 1.2 × (a new payload)."""
    day = 86400.0
    changed = [log_statistics(f"day{k}", noisy_log(vehicle, 10 + k, 1.2 if k >= 3 else 1.0,
                                                   day * k), vehicle.damping, vehicle.body,
                              OPTIONS) for k in range(5)]
    d = drift(changed)
    names = d.names
    # the coefficients that carry the force (quadratic surge, sway, heave, linear heave)
    for n in ("X_uu", "Y_vv", "Z_ww", "Z_w"):
        j = names.index(n)
        assert d.moved[j], n
        assert d.change_after[j] == 2, n
        before = vehicle.theta[j]
        assert d.shift[j] == pytest.approx(0.2 * before, abs=4 * d.shift_std[j]), n
    same = [log_statistics(f"day{k}", noisy_log(vehicle, 10 + k, 1.0, day * k),
                           vehicle.damping, vehicle.body, OPTIONS) for k in range(5)]
    quiet = drift(same)
    assert not quiet.moved.any(), [n for n, m in zip(quiet.names, quiet.moved, strict=True)
                                   if m]
    assert np.all(quiet.change_after == -1)


def test_a_coefficient_fewer_than_two_logs_identify_is_not_tested(vehicle: Vehicle) -> None:
    """K_pp identified in one log of two, N_rr in none: degrees of freedom 0, no χ² and no
    p-value, never 'changed', and the table says why instead of printing dof −1."""
    from dataclasses import replace

    from dampest_ros.cli.pool import drift_table

    logs = [log_statistics(f"day{k}", noisy_log(vehicle, 20 + k), vehicle.damping,
                           vehicle.body, OPTIONS) for k in range(2)]
    names = logs[0].fit.names
    kpp, nrr = names.index("K_pp"), names.index("N_rr")
    held = []
    for k, log in enumerate(logs):  # held at the prior, as a fit without excitation holds it
        flags = {**log.fit.flags, "N_rr": "not excited"}
        if k == 1:
            flags["K_pp"] = "not excited"
        held.append(replace(log, fit=replace(log.fit, flags=flags)))
    d = drift(held)
    for j in (kpp, nrr):
        assert d.dof[j] == 0 and np.isnan(d.chi2[j]) and np.isnan(d.p_value[j])
        assert not d.moved[j]
    assert d.dof[names.index("X_uu")] == 1 and np.isfinite(d.p_value[names.index("X_uu")])
    text = drift_table(d, logs[0].fit)
    assert "not tested: identified in 1 of 2 logs" in text
    assert "not tested: identified in 0 of 2 logs" in text
    assert " -1 " not in text
