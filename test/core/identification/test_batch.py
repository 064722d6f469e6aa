"""Batch identification (dampest_ros.core.identification.batch) on exact simulator samples."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from dampest_ros.core.identification.batch import FitOptions, fit, fit_statistics
from dampest_ros.core.identification.covariance import bias_statistics
from dampest_ros.core.identification.dissipative import envelope
from dampest_ros.core.identification.regression import accumulate, iter_regression
from dampest_ros.core.online.estimator import restrict
from dampest_ros.core.physics.alpha import Alpha
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.frames import euler_from_matrix, quat_to_matrix
from dampest_ros.core.physics.terms import CrossSpec, cross_term
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.extent import Extent
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.simulate import run
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
    assert f.flags["K_p"].startswith(f"held at prior {vehicle.theta[f.names.index('K_p')]:.4g}"
                                     " (no excitation")
    i = f.names.index("K_pp")
    assert f.theta[i] == vehicle.theta[i] and np.isnan(f.std[i])
    assert list(f.names[j] for j in np.flatnonzero(f.held)) == ["K_p", "K_pp"]
    assert list(f.names[j] for j in np.flatnonzero(~f.identified)) == ["K_p", "K_pp"]


def with_extra_force(s: Samples, extra: np.ndarray) -> Samples:
    """The samples with ``extra`` (n, 6) added to τ: a force the model's terms lack."""
    return Samples(s.t, s.nu, s.nu_dot, s.tau + extra, s.euler, s.depth, s.segment)


@pytest.fixture(scope="module")
def torpedo() -> tuple[Vehicle, Samples]:
    """MuJoCo's torpedo_auv (physics we did not write), protocol B, 120 s, seed 2, exact ν,
    ν̇ and τ: its ellipsoid drag and fin lift are not of the preset's linear + quadratic form
    (the vehicle here has those two terms only)."""
    pytest.importorskip("mujoco")
    full = load_vehicle("torpedo_auv")
    damping, theta = restrict(full.damping, full.theta, ["linear", "quadratic"])
    v = replace(full, damping=damping, theta=theta)
    traj = run(v, make_excitation("B", v, 120.0, seed=2), dt=0.02, backend="mujoco")
    R = quat_to_matrix(traj.quaternion)
    return v, Samples(traj.t, traj.nu, traj.nu_dot, traj.tau, euler_from_matrix(R),
                      traj.position[:, 2], np.zeros(len(traj.t), dtype=np.int64))


def test_a_dof_fitted_exactly_does_not_hide_the_others(vehicle: Vehicle) -> None:
    """Why (1): with the noise variance floored at 1e-12, surge, roll and pitch, which the
    structure fits exactly, weighed 1e12 and the richly excited sway, heave and yaw columns
    were reported as "no excitation: its regressor column is zero"."""
    s = exact_samples(vehicle)
    nu = s.nu
    extra = np.zeros_like(nu)  # cross-flow forces the diagonal model lacks, in Y, Z and N
    extra[:, 1] = 30.0 * nu[:, 1] * np.abs(nu[:, 5])
    extra[:, 2] = 20.0 * nu[:, 2] * np.abs(nu[:, 0])
    extra[:, 5] = 10.0 * nu[:, 5] * np.abs(nu[:, 1])
    data = with_extra_force(s, extra)
    wls = fit(data, vehicle.damping, vehicle.body, replace(EXACT, method="wls"),
              prior=vehicle.theta)
    assert not any("no excitation" in why for why in wls.flags.values()), wls.flags
    # each parameter acts in one row: the per-DOF weights cannot move it; WLS = OLS
    ols = fit(data, vehicle.damping, vehicle.body, EXACT, prior=vehicle.theta)
    assert np.all(np.abs(wls.theta - ols.theta) <= 1e-6 * (np.abs(ols.theta) + wls.std))
    exact = [vehicle.damping.parameter_names.index(n) for n in ("X_uu", "K_pp", "M_qq")]
    np.testing.assert_allclose(wls.theta[exact], vehicle.theta[exact], rtol=1e-8)


def test_noiseless_foreign_physics_wls_equals_ols_within_sigma(
        torpedo: tuple[Vehicle, Samples]) -> None:
    """On MuJoCo's noiseless data the default (WLS) equals OLS within its σ."""
    v, s = torpedo
    wls = fit(s, v.damping, v.body, FitOptions(dissipative=False), prior=v.theta)
    ols = fit(s, v.damping, v.body, FitOptions(method="ols", dissipative=False),
              prior=v.theta)
    assert np.all(np.abs(wls.theta - ols.theta) <= wls.std)
    assert not any("no excitation" in why for why in wls.flags.values())


def test_same_flags_and_theta_whatever_the_priors_magnitude(
        torpedo: tuple[Vehicle, Samples]) -> None:
    """Why (3): thresholds scaled by |prior| gave different flags for prior ×0.5 and ×2 on
    the same log, and the flagged parameters held at the prior moved the sway R² from 0.31
    to 0.75 (MuJoCo torpedo, 120 s)."""
    v, s = torpedo
    half = fit(s, v.damping, v.body, prior=0.5 * v.theta)
    double = fit(s, v.damping, v.body, prior=2.0 * v.theta)
    assert half.flags == double.flags and half.constrained == double.constrained
    np.testing.assert_allclose(half.theta, double.theta, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(half.r2, double.r2, rtol=1e-9)
    assert not half.held.any()  # every column is excited: nothing takes the prior's value
    # what is flagged is flagged by the data (a wide interval), not by the prior
    assert all("poorly determined" in why for why in half.flags.values())
    assert half.r2[1] > 0.8


def test_small_coefficient_whose_force_is_known_is_identified(vehicle: Vehicle) -> None:
    """A truth of 0 (a linear term a quadratic dominates) is identified when the force it
    contributes is pinned down relative to its DOF's force; a DOF that did not move is not."""
    theta = vehicle.theta.copy()
    theta[vehicle.damping.parameter_names.index("Y_v")] = 0.0
    v = Vehicle(**{**vehicle.__dict__, "theta": theta})
    s = exact_samples(v, 60.0)
    rng = np.random.default_rng(3)
    noisy = with_extra_force(s, rng.normal(0.0, 0.5, s.tau.shape))
    f = fit(noisy, v.damping, v.body, replace(EXACT, method="wls", cutoff=2.0),
            prior=vehicle.theta)
    assert "Y_v" not in f.flags and f.identified[f.names.index("Y_v")]
    assert abs(f.theta[f.names.index("Y_v")]) < 3 * f.std[f.names.index("Y_v")]


def test_collinear_pair_gives_its_combination_not_the_prior(vehicle: Vehicle) -> None:
    """Why (4): with u > 0 only, u|u| (X_uu) and u·u (a bilinear X_uxu) are one column; both
    were held at the prior. Now the sum is estimated and reported, and the members are marked
    as not identified on their own."""
    cross = cross_term([CrossSpec(0, 0, Alpha("lin", 0), "X_uxu")])
    model = DampingModel([*vehicle.damping.terms, cross])
    s = exact_samples(vehicle)
    s = s.take(np.flatnonzero(s.nu[:, 0] > 0.02))  # exact per sample: any subset is exact
    prior = np.append(0.5 * vehicle.theta, 10.0)
    f = fit(s, model, vehicle.body, EXACT, prior=prior)
    i, k = f.names.index("X_uu"), f.names.index("X_uxu")
    truth = vehicle.theta[i]
    assert f.theta[i] != prior[i] and f.theta[k] != prior[k]
    (c,) = f.combinations
    assert sorted(c.names) == ["X_uu", "X_uxu"]
    np.testing.assert_allclose(c.coef, [1.0, 1.0], rtol=1e-6)  # one column: a plain sum
    assert c.value == pytest.approx(truth, rel=1e-8)
    assert f.theta[i] + f.theta[k] == pytest.approx(truth, rel=1e-8)
    assert str(c).startswith(f"X_uu + X_uxu = {truth:.4g} ± ")
    assert not f.identified[i] and not f.identified[k] and not f.held[[i, k]].any()
    assert "only X_uu + X_uxu" in f.flags["X_uu"]
    # the other eleven coefficients are exact and identified
    rest = [j for j in range(len(f.names)) if j not in (i, k)
            and f.names[j] not in f.flags]
    np.testing.assert_allclose(f.theta[rest], vehicle.theta[rest], rtol=1e-6)


def test_collinear_pair_on_foreign_physics(torpedo: tuple[Vehicle, Samples]) -> None:
    """MuJoCo's torpedo with u > 0 only: X_uu and X_uxu again, as an identifiable sum that
    does not depend on the prior; its σ is finite and covers the two fits."""
    v, s = torpedo
    model = DampingModel([*v.damping.terms,
                          cross_term([CrossSpec(0, 0, Alpha("lin", 0), "X_uxu")])])
    s = s.take(np.flatnonzero(s.nu[:, 0] > 0.02))
    opts = FitOptions(cutoff=0.0)
    a = fit(s, model, v.body, opts, prior=np.append(v.theta, 0.0))
    b = fit(s, model, v.body, opts, prior=np.append(2.0 * v.theta, 50.0))
    assert [c.names for c in a.combinations] == [["X_uu", "X_uxu"]]
    assert a.combinations[0].value == pytest.approx(b.combinations[0].value, rel=1e-9)
    assert 0 < a.combinations[0].std < 0.2 * abs(a.combinations[0].value)


def test_estimate_is_dissipative_and_the_misfit_is_reported(vehicle: Vehicle) -> None:
    """Why (5): a negative quadratic coefficient was accepted and printed as identified.
    Data that push K_pp, M_qq, N_rr below 0 (a force the model lacks): the default estimate
    satisfies νᵀD(ν)ν ≥ 0 on every sample and over the flown envelope, and names the
    coefficients the constraint holds as a structural misfit."""
    s = exact_samples(vehicle, 60.0)
    data = with_extra_force(s, -40.0 * s.nu * np.abs(s.nu))
    free = fit(data, vehicle.damping, vehicle.body, replace(EXACT, dissipative=False))
    model = vehicle.damping
    assert model.dissipation(envelope(s.nu), free.theta).min() < 0
    f = fit(data, model, vehicle.body, replace(EXACT, method="wls"))
    P = np.concatenate([model.dissipation(s.nu, f.theta),
                        model.dissipation(envelope(s.nu), f.theta)])
    assert P.min() >= -1e-9 * np.abs(P).max()
    assert f.constrained and set(f.constrained) <= {"K_p", "M_q", "N_r", "K_pp", "M_qq",
                                                     "N_rr"}
    assert all("structural misfit" in why and "--select" in why
               for why in f.constrained.values())
    assert not f.identified[[f.names.index(n) for n in f.constrained]].any()


def test_the_dissipativity_check_scans_the_samples_part_by_part(vehicle: Vehicle) -> None:
    """The same energy-generating data in three segments, each a part that ``map_parts``
    holds (a pooled fit's logs), fitted from their extent and statistics: the parts are
    scanned where they are, in every round of the constraint, and the estimate, its σ and
    the report are those of the samples at once."""
    s = exact_samples(vehicle, 60.0)
    data = with_extra_force(s, -40.0 * s.nu * np.abs(s.nu))
    third = np.arange(len(data)) * 3 // len(data)
    data = Samples(data.t, data.nu, data.nu_dot, data.tau, data.euler, data.depth, third)
    parts = [data.take(third == k) for k in range(3)]
    firsts = [0, len(parts[0]), len(parts[0]) + len(parts[1])]
    maps: list[int] = []

    def map_parts(fn: Callable[[Samples, int], Any]) -> list[Any]:
        maps.append(len(maps))
        return [fn(part, first) for part, first in zip(parts, firsts, strict=True)]

    options = replace(EXACT, method="wls")
    model, body = vehicle.damping, vehicle.body
    split = fit_statistics(Extent.of(data), accumulate(data, model, body, cutoff=options.cutoff),
                           bias_statistics(data, model, body, options), map_parts, model, body,
                           options)
    once = fit(data, model, body, options)
    assert split.constrained and split.constrained == once.constrained
    np.testing.assert_array_equal(split.theta, once.theta)
    np.testing.assert_allclose(split.std, once.std, rtol=1e-10)
    assert len(maps) >= 3  # the robust pass, the scan, a scan after each round of constraint


def test_dissipative_on_foreign_physics(torpedo: tuple[Vehicle, Samples]) -> None:
    """MuJoCo's torpedo with the preset's terms: unconstrained, X_u < 0 generates energy in
    slow surge; the default estimate does not, on the data and over the flown envelope."""
    v, s = torpedo
    model = v.damping
    free = fit(s, model, v.body, FitOptions(dissipative=False))
    assert model.dissipation(envelope(s.nu), free.theta).min() < 0
    f = fit(s, model, v.body)
    P = np.concatenate([model.dissipation(s.nu, f.theta),
                        model.dissipation(envelope(s.nu), f.theta)])
    assert P.min() >= -1e-9 * np.abs(P).max()
    assert "X_u" in f.constrained and "structural misfit" in f.constrained["X_u"]
    # what it costs is surge's fit (the misfit); the DOFs it did not touch keep theirs
    assert f.r2[0] < free.r2[0]
    np.testing.assert_allclose(f.r2[1:4], free.r2[1:4], atol=0.01)


@pytest.mark.parametrize(("blocks", "half_width"), [(10, 2.262157162798205),
                                                     (360, 1.9665939377682302),
                                                     (1, 1.959963984540054),
                                                     (0, 1.959963984540054)])
def test_the_95_percent_quantile_is_students_t_of_the_blocks_else_normal(
        blocks: int, half_width: float) -> None:
    """t_{0.975} with blocks − 1 degrees of freedom (scipy.special's, the numbers of
    scipy.stats.t.ppf), the normal's 1.96 when the block count is unknown."""
    from types import SimpleNamespace

    from dampest_ros.core.identification.batch import Fit

    assert Fit.quantile(SimpleNamespace(blocks=blocks)) == half_width  # type: ignore[arg-type]
