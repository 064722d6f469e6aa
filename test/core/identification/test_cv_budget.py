"""The number of terms from the data: guarded time folds, held-out errors per fold, the
one-standard-error rule, and the uncapped selection on a law with a known support."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.identification.cv_budget import (
    fold_errors,
    guarded_folds,
    one_se_size,
    scaled_lstsq,
)
from dampest_ros.core.identification.selection import select_terms
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import RigidBody
from dampest_ros.core.physics.terms import linear_term, quadratic_term
from dampest_ros.io.yaml_io import load_vehicle
from test.core.identification.test_selection import RATE, smooth, synthetic


def test_guarded_folds_are_contiguous_and_leave_the_guard_out() -> None:
    fold = guarded_folds(100, 4, 3)
    # boundaries at 25, 50, 75: samples 22..27, 47..52, 72..77 belong to no fold
    assert np.flatnonzero(fold < 0).tolist() == [*range(22, 28), *range(47, 53),
                                                 *range(72, 78)]
    assert [int((fold == f).sum()) for f in range(4)] == [22, 19, 19, 22]
    assert np.all(np.diff(fold[fold >= 0]) >= 0)
    np.testing.assert_array_equal(guarded_folds(10, 2, 0), [0] * 5 + [1] * 5)


def regression(seed: int, n: int = 4000, m: int = 12, noise: float = 0.5
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-fold normal equations (5 contiguous folds) of y = X β + e, β = (3, 0, −2, 0, 0,
    1.5, 0 …) on m correlated columns: the true support is {0, 2, 5}."""
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, m)) @ (np.eye(m) + 0.3 * rng.normal(size=(m, m)))
    beta = np.zeros(m)
    beta[[0, 2, 5]] = [3.0, -2.0, 1.5]
    y = X @ beta + noise * rng.normal(size=n)
    fold = guarded_folds(n, 5, 0)
    A = np.array([X[fold == f].T @ X[fold == f] for f in range(5)])
    b = np.array([X[fold == f].T @ y[fold == f] for f in range(5)])
    c = np.array([y[fold == f] @ y[fold == f] for f in range(5)])
    return A, b, c


def test_fold_errors_are_each_folds_residual_from_the_others_fit() -> None:
    A, b, c = regression(1)
    e = fold_errors(A, b, c, [0, 2])
    G, g = A.sum(0), b.sum(0)
    for f in range(5):
        S = np.ix_([0, 2], [0, 2])
        theta = np.linalg.solve((G - A[f])[S], (g - b[f])[[0, 2]])
        direct = c[f] - 2 * b[f][[0, 2]] @ theta + theta @ A[f][S] @ theta
        assert e[f] == pytest.approx(direct, rel=1e-10)
    np.testing.assert_array_equal(fold_errors(A, b, c, []), c)


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_one_se_rule_on_a_greedy_path_chooses_the_true_support(seed: int) -> None:
    """Greedy forward path over all 12 columns (each step the column of least held-out
    RSS): the one-SE size keeps exactly the three true columns, seeds 1–5."""
    A, b, c = regression(seed)
    path: list[int] = []
    errors = [fold_errors(A, b, c, path)]
    while len(path) < A.shape[1]:
        rest = [k for k in range(A.shape[1]) if k not in path]
        best = min(rest, key=lambda k: fold_errors(A, b, c, [*path, k]).sum())
        path.append(best)
        errors.append(fold_errors(A, b, c, path))
    k = one_se_size(np.array(errors))
    assert sorted(path[:k]) == [0, 2, 5]


def test_uncapped_selection_keeps_the_base_and_adds_exactly_the_true_terms() -> None:
    """300 s, every DOF moving, a law of the base's form plus three library terms (lift
    Z ← 40 u·w, cross-flow N ← 8 r|v|, K ← 3 p‖ω‖), 2 % noise: with keep_base and no cap the
    search adds exactly those three and keeps all twelve base terms, seeds 1–3."""
    body: RigidBody = load_vehicle("bluerov2_heavy").body
    base = DampingModel([linear_term(), quadratic_term()])
    for seed in (1, 2, 3):
        rng = np.random.default_rng(seed)
        nu = smooth(rng, int(300 * RATE), np.array([0.4, 0.3, 0.3, 0.4, 0.4, 0.4]), 0.5)
        law = np.array([10.0, 20.0, 20.0, 2.0, 2.0, 2.0]) * nu + 60.0 * nu * np.abs(nu)
        law[:, 2] += 40.0 * nu[:, 0] * nu[:, 2]
        law[:, 5] += 8.0 * nu[:, 5] * np.abs(nu[:, 1])
        law[:, 3] += 3.0 * nu[:, 3] * np.linalg.norm(nu[:, 3:], axis=1)
        sel = select_terms(synthetic(body, nu, law, 0.02, seed), base, body, memory_dofs=(),
                           keep_base=True)
        added = sel.added(base)
        assert {i: v for i, v in added.items() if v} == {2: ["Z_uxw"], 3: ["K_pW"],
                                                          5: ["N_rv"]}, seed
        assert set(base.parameter_names) <= set(sel.model.parameter_names)


def test_scaled_lstsq_is_numpys_minimum_norm_least_squares_many_at_once() -> None:
    """Stacked normal equations of random designs (columns scaled 1e-3…1e3): the same
    solutions as numpy.linalg.lstsq of each column-scaled system to 1e-10; a zero column
    gets a zero entry and a repeated one the minimum-norm split; vector and matrix right
    sides agree."""
    rng = np.random.default_rng(4)
    X = rng.normal(size=(5, 200, 6)) * np.logspace(-3, 3, 6)
    X[3, :, 2] = 0.0  # a column the data leave at zero
    X[4, :, 5] = X[4, :, 4]  # two equal columns
    y = rng.normal(size=(5, 200, 2))
    G, B = np.swapaxes(X, 1, 2) @ X, np.swapaxes(X, 1, 2) @ y
    x = scaled_lstsq(G, B)
    for k in range(5):
        live = np.diag(G[k]) > 0
        d = 1.0 / np.sqrt(np.diag(G[k])[live])
        want = np.zeros((6, 2))
        want[live] = np.linalg.lstsq(G[k][np.ix_(live, live)] * np.outer(d, d),
                                     B[k][live] * d[:, None], rcond=1e-13)[0] * d[:, None]
        np.testing.assert_allclose(x[k], want, rtol=1e-9, atol=1e-12 * np.abs(want).max())
    assert np.all(x[3, 2] == 0.0)
    np.testing.assert_allclose(x[4, 4], x[4, 5], rtol=1e-10)
    np.testing.assert_allclose(scaled_lstsq(G, B[..., 0]), x[..., 0], rtol=1e-12, atol=1e-15)
