"""DampingIdentifier (dampest_ros.core.identifier) on a seeded native simulation of the
BlueROV2 Heavy: protocol B, 120 s, measured by the simulated sensors and preprocessed."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.identifier import DampingIdentifier
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.preprocess import preprocess
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.sensors import SensorBias, SensorConfig, measure
from dampest_ros.core.simulation.simulate import run
from dampest_ros.io.yaml_io import load_vehicle


@pytest.fixture(scope="module")
def vehicle() -> Vehicle:
    return load_vehicle("bluerov2_heavy")


@pytest.fixture(scope="module")
def flight(vehicle: Vehicle) -> tuple[Samples, Samples]:
    """The first 70 % of the samples to fit, the last 30 % held out."""
    traj = run(vehicle, make_excitation("B", vehicle, 120.0, seed=1), dt=0.02)
    rec = measure(traj, vehicle.body.rho, vehicle.body.gravity, SensorConfig(), SensorBias(),
                  seed=1)
    s = preprocess(rec, vehicle)
    k = int(0.7 * len(s))
    return s.take(slice(0, k)), s.take(slice(k, len(s)))


@pytest.fixture(scope="module")
def batch(vehicle: Vehicle, flight: tuple[Samples, Samples]) -> DampingIdentifier:
    return DampingIdentifier(vehicle).fit(flight[0])


@pytest.fixture(scope="module")
def recursive(vehicle: Vehicle, flight: tuple[Samples, Samples]) -> DampingIdentifier:
    train = flight[0]
    half = len(train) // 2
    est = DampingIdentifier(vehicle, forgetting_factor=1.0)
    return est.partial_fit(train.take(slice(0, half))).partial_fit(
        train.take(slice(half, len(train))))


def test_fit_recovers_the_simulated_coefficients(vehicle: Vehicle,
                                                 batch: DampingIdentifier) -> None:
    assert batch.names_ == vehicle.damping.parameter_names == batch.feature_names
    std = np.sqrt(np.diag(batch.cov_))
    z = (batch.coef_ - vehicle.theta) / std
    assert np.all(np.abs(z) < 3.5), dict(zip(batch.names_, np.round(z, 2), strict=True))
    # the quadratic coefficients to 2 % (X_uu = 141, M_qq = 0.47 ...)
    quad = vehicle.damping.slice("quadratic")
    np.testing.assert_allclose(batch.coef_[quad], vehicle.theta[quad], rtol=0.02)
    assert batch.fit_ is not None and not batch.fit_.flags


def test_partial_fit_with_lambda_one_agrees_with_fit(batch: DampingIdentifier,
                                                    recursive: DampingIdentifier) -> None:
    sb, sr = np.sqrt(np.diag(batch.cov_)), np.sqrt(np.diag(recursive.cov_))
    d = (batch.coef_ - recursive.coef_) / np.hypot(sb, sr)
    assert np.all(np.abs(d) < 3.0), dict(zip(batch.names_, np.round(d, 2), strict=True))
    assert recursive.estimator_ is not None and recursive.fit_ is None
    # cov_ holds the RLS's standard deviations on its diagonal
    np.testing.assert_allclose(np.sqrt(np.diag(recursive.cov_)),
                               recursive.estimator_.theta_std, rtol=1e-12)


def test_partial_fit_continues_where_the_last_call_stopped(
        vehicle: Vehicle, flight: tuple[Samples, Samples]) -> None:
    part = flight[0].take(slice(0, 1000))
    once = DampingIdentifier(vehicle).partial_fit(part)
    twice = DampingIdentifier(vehicle).partial_fit(part.take(slice(0, 437)))
    twice.partial_fit(part.take(slice(437, 1000)))
    np.testing.assert_allclose(twice.coef_, once.coef_, rtol=1e-9, atol=1e-12)
    assert not np.allclose(once.coef_, vehicle.theta, rtol=1e-3)  # not still the prior


def test_score_on_held_out_samples(batch: DampingIdentifier,
                                   flight: tuple[Samples, Samples]) -> None:
    r2 = batch.score(flight[1])
    assert r2.shape == (6,)
    assert np.all(r2 > 0.99), r2


def test_predict_is_the_damping_force_of_the_coefficients(
        vehicle: Vehicle, batch: DampingIdentifier, flight: tuple[Samples, Samples]) -> None:
    held = flight[1]
    f = batch.predict(held)
    assert f.shape == (len(held), 6)
    np.testing.assert_allclose(f, batch.predict(held.nu), rtol=1e-12)
    # the truth's D(ν)ν to within 2 % of the force's RMS per DOF
    truth = vehicle.damping.force(held.nu, vehicle.theta)
    err = np.sqrt(np.mean((f - truth) ** 2, axis=0))
    assert np.all(err < 0.02 * np.sqrt(np.mean(truth**2, axis=0))), err


def test_unfitted_and_bad_options_are_refused(vehicle: Vehicle,
                                              flight: tuple[Samples, Samples]) -> None:
    with pytest.raises(ConfigError, match="not fitted"):
        DampingIdentifier(vehicle).predict(np.zeros((1, 6)))
    with pytest.raises(ConfigError, match="unknown method"):
        DampingIdentifier(vehicle, method="lasso")
    est = DampingIdentifier(vehicle).partial_fit(flight[1].take(slice(0, 200)))
    resampled = flight[1].take(slice(200, 400, 2))  # every other sample: 25 Hz
    with pytest.raises(ConfigError, match="rate"):
        est.partial_fit(resampled)


def test_a_prior_by_name_in_map_and_rls(vehicle: Vehicle,
                                         flight: tuple[Samples, Samples]) -> None:
    held = flight[1]
    names = vehicle.damping.parameter_names
    # a prior far tighter than the data: MAP and the RLS return it
    tight = (names, 1.5 * vehicle.theta, np.full(len(names), 1e-9))
    batch = DampingIdentifier(vehicle, method="map", prior=tight).fit(held)
    recursive = DampingIdentifier(vehicle, prior=tight).partial_fit(held.take(slice(0, 500)))
    for est in (batch, recursive):
        np.testing.assert_allclose(est.coef_, 1.5 * vehicle.theta, rtol=1e-9, atol=1e-12)
    # a prior on one parameter only: X_u = 20 ± 0.2 pulls the data's 13.7 ± 0.5 towards it
    free = DampingIdentifier(vehicle).fit(held).coef_[names.index("X_u")]
    pulled = DampingIdentifier(vehicle, method="map", prior=(["X_u"], np.array([20.0]),
                                                             np.array([0.2]))).fit(held)
    x_u = pulled.coef_[names.index("X_u")]
    assert abs(free - 13.7) < 1.0 and 17.0 < x_u < 20.0, (free, x_u)
    with pytest.raises(ConfigError, match="MAP needs a prior"):
        DampingIdentifier(vehicle, method="map").fit(held)
