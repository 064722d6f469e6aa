"""The delay between the logged thrust and the force on the vehicle, found by profiling
the information criterion of the fit over shifts of τ (:func:`profile_delay`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.quadratic import solve_normal
from dampest_ros.core.identification.regression import NormalEquations, accumulate
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import RigidBody
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]


def _rss(ne: NormalEquations) -> FloatArray:
    """RSS per DOF of the unweighted least-squares fit on every column, shape (6,)."""
    p = ne.A.shape[-1]
    A = ne.A.sum(axis=(0, 1))
    b = ne.b.sum(axis=(0, 1))
    theta = solve_normal(A, b, np.ones(p, dtype=bool), np.zeros(p))
    return np.asarray(np.maximum(ne.rss(theta), 1e-300))


def shift_tau(samples: Samples, delay: float) -> Samples:
    """Samples whose τ is delayed by ``delay`` seconds within each segment (τ(t − d))."""
    tau = np.empty_like(samples.tau)
    for sl in samples.segments():
        t = samples.t[sl]
        for i in range(6):
            tau[sl, i] = np.interp(t - delay, t, samples.tau[sl, i])
    return Samples(samples.t, samples.nu, samples.nu_dot, tau, samples.euler, samples.depth,
                   samples.segment)


@dataclass(frozen=True)
class DelayEstimate:
    """The delay of the response after τ, with its uncertainty.

    Attributes
    ----------
    delay : float
        Delay (s) that minimises the residual of the fit.
    std : float
        Its standard deviation (s), from the curvature of the profile log-likelihood
        ℓ(d) = −½ n_eff Σ_i log RSS_i(d) at the minimum (n_eff = 2 · cutoff · duration):
        σ² = 1 / (−ℓ''(d̂)); inf where the profile is flat there.
    at_bound : bool
        The minimum is at an end of the searched interval: the delay may lie beyond it.
    bounds : tuple of float
        The searched interval (s).
    """

    delay: float
    std: float
    at_bound: bool
    bounds: tuple[float, float]


#: The delays searched (s): a thruster's ESC latency is tens of ms, a commanded wrench can
#: lead the motion by more than half a second (the controller, the allocator, the motors).
DELAY_BOUNDS = (-0.05, 1.5)


def profile_delay(samples: Samples, model: DampingModel, body: RigidBody, cutoff: float = 2.0,
                  bounds: tuple[float, float] = DELAY_BOUNDS) -> DelayEstimate:
    """Delay (s) of the response after τ that minimises the residual of the fit.

    Each trial shifts the (band-limited) τ and refits by least squares on the decimated,
    low-passed regression; a coarse grid then a bounded scalar search; the standard
    deviation from the profile's curvature (:class:`DelayEstimate`).

    Parameters
    ----------
    samples : Samples
    model : DampingModel
    body : RigidBody
    cutoff : float
        Low-pass of the regression (Hz).
    bounds : tuple of float
        Delays searched (s).

    Returns
    -------
    DelayEstimate
    """
    from scipy import optimize  # slow to import: only where a delay is searched

    def cost(delay: float) -> float:
        rss = _rss(accumulate(shift_tau(samples, delay), model, body, folds=1, cutoff=cutoff))
        # scale-free: sum of the per-DOF log residuals (DOFs with large forces do not rule)
        return float(np.sum(np.log(np.maximum(rss, 1e-300))))

    n_grid = max(12, int(np.ceil((bounds[1] - bounds[0]) / 0.1)) + 1)
    grid = np.linspace(bounds[0], bounds[1], n_grid)
    values = [cost(g) for g in grid]
    k = int(np.argmin(values))
    res = optimize.minimize_scalar(cost, bounds=(grid[max(k - 1, 0)],
                                                 grid[min(k + 1, len(grid) - 1)]),
                                   method="bounded", options={"xatol": 1e-5})
    d = float(res.x)
    h = 0.01
    # c''(d̂) by central differences of c = Σ_i log RSS_i
    curvature = (cost(d + h) - 2.0 * float(res.fun) + cost(d - h)) / h**2
    duration = sum(float(samples.t[sl][-1] - samples.t[sl][0]) for sl in samples.segments())
    n_eff = 2.0 * cutoff * duration if cutoff > 0 else float(len(samples))
    # ℓ'' = −½ n_eff c''  →  σ² = 2 / (n_eff c'')
    std = float(np.sqrt(2.0 / (n_eff * curvature))) if curvature > 0 else float("inf")
    step = grid[1] - grid[0]
    return DelayEstimate(d, std, bool(d - bounds[0] < step / 2 or bounds[1] - d < step / 2),
                         bounds)
