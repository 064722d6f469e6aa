"""The delay between the logged thrust and the force on the vehicle, found by profiling
the information criterion of the fit over shifts of τ (:func:`profile_delay`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from dampest_ros.core.identification.quadratic import solve_normal
from dampest_ros.core.identification.regression import NormalEquations, accumulate
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import RigidBody
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]


def _criteria(ne: NormalEquations, idx: NDArray[np.int64], weights: FloatArray, n_eff: float
              ) -> tuple[FloatArray, float, float]:
    """RSS per DOF, BIC and AIC of the least-squares fit on the columns ``idx``."""
    A = np.einsum("i,fipq->pq", weights, ne.A)[np.ix_(idx, idx)]
    b = np.einsum("i,fip->p", weights, ne.b)[idx]
    theta = solve_normal(A, b, np.ones(len(idx), dtype=bool), np.zeros(len(idx)))
    full = np.zeros(ne.A.shape[-1])
    full[idx] = theta
    rss = np.maximum(ne.rss(full), 1e-300)
    n = float(ne.n.sum())
    ll = n_eff * float(np.sum(np.log(rss / n)))
    return rss, ll + len(idx) * float(np.log(n_eff)), ll + 2.0 * len(idx)


def shift_tau(samples: Samples, delay: float) -> Samples:
    """Samples whose τ is delayed by ``delay`` seconds within each segment (τ(t − d))."""
    tau = np.empty_like(samples.tau)
    for sl in samples.segments():
        t = samples.t[sl]
        for i in range(6):
            tau[sl, i] = np.interp(t - delay, t, samples.tau[sl, i])
    return Samples(samples.t, samples.nu, samples.nu_dot, tau, samples.euler, samples.depth,
                   samples.segment)


def profile_delay(samples: Samples, model: DampingModel, body: RigidBody, cutoff: float = 2.0,
                  bounds: tuple[float, float] = (-0.05, 0.5)) -> float:
    """Delay (s) of the response after τ that minimises the residual of the fit.

    Each trial shifts the (band-limited) τ and refits by least squares on the decimated,
    low-passed regression; a coarse grid then a bounded scalar search.
    """
    def cost(delay: float) -> float:
        ne = accumulate(shift_tau(samples, delay), model, body, folds=1, cutoff=cutoff)
        idx = np.arange(model.n_params)
        rss, _, _ = _criteria(ne, idx, np.ones(6), 1.0)
        # scale-free: sum of the per-DOF log residuals (DOFs with large forces do not rule)
        return float(np.sum(np.log(np.maximum(rss, 1e-300))))

    grid = np.linspace(bounds[0], bounds[1], 12)
    values = [cost(g) for g in grid]
    k = int(np.argmin(values))
    res = optimize.minimize_scalar(cost, bounds=(grid[max(k - 1, 0)],
                                                 grid[min(k + 1, len(grid) - 1)]),
                                   method="bounded", options={"xatol": 1e-3})
    return float(res.x)
