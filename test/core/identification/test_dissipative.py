"""The dissipativity constraint: the projection of an estimate onto νᵀD(ν)ν ≥ 0."""

from __future__ import annotations

import numpy as np
from scipy import optimize

from dampest_ros.core.identification.dissipative import (
    dissipation_points,
    envelope,
    power_rows,
    project,
)
from dampest_ros.core.online.estimator import restrict
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.io.yaml_io import load_vehicle

# flown extremes (m/s, rad/s): min and max per DOF
FLOWN = np.array([[-0.6, -0.4, -0.3, -0.5, -0.5, -0.8], [0.8, 0.4, 0.3, 0.5, 0.5, 0.8]])


def linear_quadratic() -> tuple[DampingModel, np.ndarray]:
    v = load_vehicle("bluerov2_heavy")
    return restrict(v.damping, v.theta, ["linear", "quadratic"])


def correlated_cov(p: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(p, p))
    return np.asarray(A @ A.T / p + 0.1 * np.eye(p))


def test_a_dissipative_estimate_is_returned_unchanged() -> None:
    model, theta = linear_quadratic()
    projected, why = project(theta, correlated_cov(len(theta), 1), model, FLOWN)
    assert why == {}
    assert projected is theta


def test_the_projection_is_the_information_weighted_nearest_dissipative_estimate() -> None:
    """KKT conditions checked independently of the solver: the projected θ is dissipative on
    the grid, and H (θ − θ̂) = Σ μ_k g_k with μ ≥ 0 over the active constraints only."""
    model, theta = linear_quadratic()
    names = model.parameter_names
    bad = theta.copy()
    bad[names.index("X_u")] = -30.0  # generates energy at slow surge
    bad[names.index("N_rr")] = -2.0  # and in fast yaw
    cov = correlated_cov(len(theta), 2)
    projected, why = project(bad, cov, model, FLOWN)
    assert {"X_u", "N_rr"} <= set(why)
    assert "held by dissipativity" in why["X_u"]
    G = power_rows(model, envelope(FLOWN))
    P = G @ projected
    scale = np.abs(G) @ np.abs(projected)
    assert np.all(P >= -1e-9 * scale)
    assert len(dissipation_points(model, projected, np.zeros((0, 6)), FLOWN)[0]) == 0
    H = np.linalg.inv(cov)
    grad = H @ (projected - bad)
    active = P <= 1e-7 * scale
    assert active.any()
    _, res = optimize.nnls(G[active].T, grad)
    assert res <= 1e-6 * np.linalg.norm(grad)
    # the truth is dissipative, so it is no nearer to θ̂ in the metric H
    d_proj, d_true = projected - bad, theta - bad
    assert d_proj @ H @ d_proj <= d_true @ H @ d_true


def test_the_kept_grid_follows_the_model_and_the_envelope() -> None:
    """The power rows of the last grid are kept: changing the envelope or the model and
    coming back gives the points a fresh computation gives."""
    model, theta = linear_quadratic()
    other, other_theta = linear_quadratic()
    bad = theta.copy()
    bad[model.parameter_names.index("X_u")] = -30.0
    none = np.zeros((0, 6))
    wide = FLOWN * 2.0

    def points(m: DampingModel, th: np.ndarray, flown: np.ndarray) -> np.ndarray:
        return dissipation_points(m, th, none, flown)[0]

    first = points(model, bad, FLOWN)
    assert len(first) > 0
    # the truth, from the rows of the whole grid: −30 X_u generates energy at slow surge
    G = power_rows(model, envelope(FLOWN))
    P = G @ bad
    assert len(first) == int(np.sum(P < -1e-9 * (np.abs(G) @ np.abs(bad))))
    wider = points(model, bad, wide)
    assert len(wider) == int(np.sum(power_rows(model, envelope(wide)) @ bad
                                    < -1e-9 * (np.abs(power_rows(model, envelope(wide)))
                                               @ np.abs(bad))))
    assert len(points(other, other_theta, FLOWN)) == 0
    assert points(model, bad, FLOWN).tobytes() == first.tobytes()
