"""The dissipativity constraint νᵀD(ν)ν ≥ 0: where an estimate generates energy, which
coefficients make it, and the closest estimate that does not.

For the static terms the power the damping takes out of the motion is linear in θ:
νᵀD(ν)ν = g(ν)ᵀθ with g(ν) = Φ(ν)ᵀν (:func:`power_rows`), so "dissipative at the velocities
ν_k" is the set of linear inequalities g(ν_k)ᵀθ ≥ 0. The batch fit imposes them on its
normal equations (:func:`dampest_ros.core.identification.batch.fit`); the online estimate is
projected onto them in the metric of its information matrix (:func:`project`), which for a
forgetting factor of 1 is the same problem. Both check every point of a grid over the flown envelope
(:func:`envelope`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from statistics import NormalDist

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import DOF_NAMES
from dampest_ros.core.signals.samples import CHUNK

FloatArray = NDArray[np.float64]
#: Rounds of :func:`impose` and the worst points each adds to the constraint.
ROUNDS, PER_ROUND = 5, 100


def power_rows(model: DampingModel, nu: FloatArray) -> FloatArray:
    """g(ν) with νᵀD(ν)ν = g(ν)ᵀθ for the static terms, shape (n, p).

    g(ν) = Φ(ν)ᵀν with zero memory states: the memory columns are 0, so fluid memory is left
    out of the dissipativity constraint (its passivity is c ≥ 0 on its own).

    Parameters
    ----------
    nu : ndarray, shape (n, 6)
        Velocities (m/s, rad/s).
    """
    z = np.zeros((len(nu), len(model.memory_rates)))
    X = model.regressor_entries(nu, z if z.shape[1] else None)
    rows, params = model.pattern
    g = np.zeros((len(nu), model.n_params))
    for i in range(6):
        # Σ_i ν_i (Φ(ν)θ)_i = (Φ(ν)ᵀν)ᵀθ, over the entries of Φ's row i (a row-major slice)
        entries = slice(*np.searchsorted(rows, [i, i + 1]))
        g[:, params[entries]] += X[:, entries] * nu[:, i:i + 1]
    return g


def envelope(nu: FloatArray, scales: Sequence[float] = (1.0, 0.01)) -> FloatArray:
    """Grid over the flown envelope, shape (len(scales) · 5⁶, 6) (m/s, rad/s).

    Per DOF its smallest, half of it, 0, half its largest and its largest flown value, all
    combinations, once per scale. The default adds the same grid at 1 % of that size, where
    the terms of lowest order (linear) carry the power: a negative linear coefficient that the
    quadratic hides at speed still generates energy there.

    Parameters
    ----------
    nu : ndarray, shape (N, 6)
        Flown velocities.
    scales : sequence of float
        Sizes of the grid relative to the flown range.
    """
    lo, hi = nu.min(axis=0), nu.max(axis=0)
    axes = np.stack([lo, lo / 2, np.zeros(6), hi / 2, hi], axis=1)
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 6)
    return np.concatenate([s * grid for s in scales])


#: Rows where an estimate generates energy, shape (n, 6), and their power νᵀD(ν)ν, shape (n,).
Violations = tuple[FloatArray, FloatArray]


def dissipation_points(model: DampingModel, theta: FloatArray, data: FloatArray,
                       flown: FloatArray | None = None, chunk: int = CHUNK,
                       on_data: Violations | None = None
                       ) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Velocities where ``theta`` generates energy, worst first, shape (n, 6), with whether
    each is a data sample (else an :func:`envelope` grid point), shape (n,).

    The check covers every row of ``data`` and the whole grid over the envelope of ``flown``
    (default: of ``data``); a point counts when νᵀD(ν)ν < 0 by more than 1e-9 of the power its
    terms carry (rounding of an active constraint).

    Parameters
    ----------
    model : DampingModel
    theta : ndarray, shape (p,)
    data : ndarray, shape (N, 6)
        Sample velocities (m/s, rad/s); may be empty when ``flown`` is given.
    flown : ndarray, shape (M, 6), optional
        Velocities whose per-DOF extremes bound the grid (e.g. the (2, 6) min/max).
    chunk : int
        Velocities per evaluation of the regressor.
    on_data : Violations, optional
        :func:`violations` of ``data``, found where the data are held (e.g. log by log, on
        the workers of a pooled fit), in the order of ``data``'s rows.
    """
    grid = (_grid_rows(model, flown, chunk) if flown is not None
            else _chunk_rows(model, envelope(data), chunk))
    found = [on_data if on_data is not None else violations(model, theta, data, chunk),
             _violating(grid, theta)]
    pts, power = np.concatenate([f[0] for f in found]), np.concatenate([f[1] for f in found])
    order = np.argsort(power)
    return pts[order], (np.arange(len(power)) < len(found[0][1]))[order]


def violations(model: DampingModel, theta: FloatArray, nu: FloatArray, chunk: int = CHUNK
               ) -> Violations:
    """The rows of ``nu``, shape (N, 6), where ``theta`` generates energy, in their order."""
    return scan(model, nu, chunk)(theta)


def scan(model: DampingModel, nu: FloatArray, chunk: int = CHUNK
         ) -> Callable[[FloatArray], Violations]:
    """:func:`violations` of the rows of ``nu``, shape (N, 6), at any θ, their power rows
    g(ν) formed once: the rounds of :func:`impose` scan the same velocities."""
    return partial(_violating, _chunk_rows(model, nu, chunk))


def _violating(rows: list[tuple[FloatArray, FloatArray]], theta: FloatArray) -> Violations:
    """The velocities of ``rows`` (:func:`_chunk_rows`) where νᵀD(ν)ν = gᵀθ < 0 beyond
    rounding, and that power."""
    pts, power = [np.zeros((0, 6))], [np.zeros(0)]
    for nu, g in rows:
        P = g @ theta
        bad = P < -1e-9 * (np.abs(g) @ np.abs(theta))
        pts.append(nu[bad])
        power.append(P[bad])
    return np.concatenate(pts), np.concatenate(power)


def _chunk_rows(model: DampingModel, nu: FloatArray, chunk: int
                ) -> list[tuple[FloatArray, FloatArray]]:
    """(ν, g(ν)) per chunk of ``chunk`` velocities, g of shape (chunk, p)."""
    return [(nu[k:k + chunk], power_rows(model, nu[k:k + chunk]))
            for k in range(0, len(nu), chunk)]


# the grid of the last (model, flown envelope, chunk) and its power rows: the online
# projection checks each estimate on the same grid until a new extreme is flown
_last_grid: list[tuple[DampingModel, bytes, int, list[tuple[FloatArray, FloatArray]]]] = []


def _grid_rows(model: DampingModel, flown: FloatArray, chunk: int
               ) -> list[tuple[FloatArray, FloatArray]]:
    """:func:`_chunk_rows` of the :func:`envelope` of ``flown``, the last one kept."""
    lo_hi = np.stack([flown.min(axis=0), flown.max(axis=0)]).tobytes()
    if _last_grid and _last_grid[0][0] is model and _last_grid[0][1:3] == (lo_hi, chunk):
        return _last_grid[0][3]
    rows = _chunk_rows(model, envelope(flown), chunk)
    _last_grid[:] = [(model, lo_hi, chunk, rows)]
    return rows


def misfit_report(model: DampingModel, theta: FloatArray, pts: FloatArray,
                  on_data: NDArray[np.bool_], cov: FloatArray, free: NDArray[np.bool_]
                  ) -> dict[str, str]:
    """Name the parameters that make the unconstrained ``theta`` generate energy.

    At each violating velocity (``pts``, worst first) the parameter with the most negative
    share θ_j g_j(ν) of νᵀD(ν)ν is the one the constraint holds; the first point that names
    it gives the reason.
    """
    names = model.parameter_names
    z = NormalDist().inv_cdf(0.975)
    std = np.sqrt(np.abs(np.diag(cov)))
    share = power_rows(model, pts) * theta  # (n, p): θ_j g_j(ν)
    share[:, ~free] = 0.0
    out: dict[str, str] = {}
    for k in range(len(pts)):
        j = int(np.argmin(share[k]))
        if share[k, j] >= 0 or names[j] in out:
            continue
        where = ", ".join(f"{n} {v:+.2g}" for n, v in zip(DOF_NAMES, pts[k], strict=True)
                          if v) or "rest"
        out[names[j]] = (
            f"held by dissipativity: unconstrained {names[j]} = {theta[j]:.4g} ± "
            f"{z * std[j]:.2g} gives νᵀD(ν)ν = {share[k].sum():.3g} W < 0 at ν = ({where}"
            f"{', a sample' if on_data[k] else ', flown envelope'}); a structural misfit: the "
            "terms lack what the data need (run the structure search, identify --select)")
    return out


def impose(theta: FloatArray, pts: FloatArray, model: DampingModel,
           solve: Callable[[FloatArray], FloatArray],
           violating: Callable[[FloatArray], FloatArray]) -> tuple[FloatArray, FloatArray]:
    """Constrain an estimate to νᵀD(ν)ν ≥ 0, adding the worst violating points round by round.

    Each round adds the constraint rows g(ν_k)ᵀθ ≥ 0 of the :data:`PER_ROUND` worst points
    still violated and solves again, for at most :data:`ROUNDS` rounds: the active set of a
    smooth constraint over a grid is small, so a few hundred rows stand for the whole grid.

    Parameters
    ----------
    theta : ndarray, shape (p,)
        The unconstrained estimate.
    pts : ndarray, shape (n, 6)
        Where it generates energy, worst first (:func:`dissipation_points`).
    model : DampingModel
    solve : callable
        ``solve(E)`` → θ minimising the fit's quadratic subject to E θ ≥ 0, E shape (m, p).
    violating : callable
        ``violating(θ)`` → the points where θ still generates energy, worst first.

    Returns
    -------
    theta : ndarray, shape (p,)
    power : ndarray, shape (m, p)
        The constraint rows imposed (m = 0: ``theta`` was dissipative).
    """
    power = np.zeros((0, model.n_params))
    for _ in range(ROUNDS):
        if not len(pts):
            break
        power = np.vstack([power, power_rows(model, pts[:PER_ROUND])])
        theta = solve(power)
        pts = violating(theta)
    return theta, power


def project(theta: FloatArray, cov: FloatArray, model: DampingModel, flown: FloatArray,
            chunk: int = CHUNK) -> tuple[FloatArray, dict[str, str]]:
    """The dissipative estimate closest to ``theta`` in the metric of its information.

    argmin (θ − θ̂)ᵀ P⁻¹ (θ − θ̂) subject to νᵀD(ν)ν ≥ 0 over the grid on the flown envelope:
    for a recursive estimate (P⁻¹ = Σ Φᵀ R⁻¹ Φ + P₀⁻¹, θ̂ its minimiser) this is the batch fit's
    constrained problem on the same normal equations, so a constrained online estimate and
    the constrained batch estimate agree as their unconstrained forms do.

    Parameters
    ----------
    theta : ndarray, shape (p,)
        The estimate θ̂.
    cov : ndarray, shape (p, p)
        Its covariance P (symmetric positive definite).
    model : DampingModel
    flown : ndarray, shape (M, 6)
        Velocities whose per-DOF extremes bound the envelope (m/s, rad/s).
    chunk : int

    Returns
    -------
    theta : ndarray, shape (p,)
        ``theta`` itself when it is dissipative over the envelope.
    constrained : dict of str to str
        The coefficients the constraint holds, with the reason (:func:`misfit_report`).
    """
    # the solvers load scipy (0.3 s): only a projection that has work to do needs them
    from scipy import linalg

    from dampest_ros.core.identification.quadratic import solve_normal
    none = np.zeros((0, 6))
    pts, on_data = dissipation_points(model, theta, none, flown, chunk)
    if not len(pts):
        return theta, {}
    everything = np.ones(len(theta), dtype=bool)
    reasons = misfit_report(model, theta, pts[:1000], on_data[:1000], cov, everything)
    # P⁻¹ by its Cholesky factor; P⁻¹θ̂ = the information-weighted estimate
    H = linalg.cho_solve(linalg.cho_factor(cov), np.eye(len(theta)))
    H = 0.5 * (H + H.T)
    b = H @ theta
    projected, _ = impose(
        theta, pts, model,
        lambda E: solve_normal(H, b, everything, np.zeros(len(theta)), power=E),
        lambda th: dissipation_points(model, th, none, flown, chunk)[0])
    return projected, reasons
