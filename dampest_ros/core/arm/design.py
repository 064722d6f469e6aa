"""Excitation design: FFS coefficients that minimise the condition number of the base
regressor (friction columns included) over one period, within joint position, velocity,
acceleration and torque limits (Swevers et al. 1997; Gautier & Khalil 1992).

Limits are met by construction: any coefficient vector is first scaled per joint so that its
position excursion, |q̇| and |q̈| over one period reach at most the limits, then as a whole
until the nominal model's torque does too (while optimising on the condition number's grid,
for the result on a grid ten times finer). The optimiser (scipy L-BFGS-B on
log cond, numerical gradient) therefore searches shapes without constraints, and a random
trajectory put through the same scaling is the fair baseline.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from dampest_ros.core.arm.base import BaseParameters
from dampest_ros.core.arm.ffs import FourierTrajectory
from dampest_ros.core.arm.model import ArmModel
from dampest_ros.core.arm.regressor import regressor

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class DesignLimits:
    """Bounds a designed trajectory keeps, per joint (shapes (n,)).

    Attributes
    ----------
    lower, upper : ndarray
        Position bounds (rad).
    velocity : ndarray
        |q̇| bound (rad/s).
    acceleration : ndarray
        |q̈| bound (rad/s²).
    effort : ndarray
        |τ| bound of the nominal model (N m).
    """

    lower: FloatArray
    upper: FloatArray
    velocity: FloatArray
    acceleration: FloatArray
    effort: FloatArray

    def violations(self, q: FloatArray, qd: FloatArray, qdd: FloatArray, tau: FloatArray,
                   names: tuple[str, ...], tol: float = 1e-9) -> list[str]:
        """What a sampled trajectory exceeds: one phrase per joint and quantity, empty if
        nothing (shapes (N, n); rad, rad/s, rad/s², N m)."""
        out: list[str] = []
        checks = (("position", q.min(axis=0) < self.lower - tol, q.min(axis=0), self.lower,
                   "rad (below the lower limit)"),
                  ("position", q.max(axis=0) > self.upper + tol, q.max(axis=0), self.upper,
                   "rad (above the upper limit)"),
                  ("|velocity|", np.abs(qd).max(axis=0) > self.velocity * (1 + tol),
                   np.abs(qd).max(axis=0), self.velocity, "rad/s"),
                  ("|acceleration|", np.abs(qdd).max(axis=0) > self.acceleration * (1 + tol),
                   np.abs(qdd).max(axis=0), self.acceleration, "rad/s²"),
                  ("|torque|", np.abs(tau).max(axis=0) > self.effort * (1 + tol),
                   np.abs(tau).max(axis=0), self.effort, "N m"))
        for what, bad, value, limit, unit in checks:
            out.extend(f"{names[j]} {what} {value[j]:.4g} exceeds {limit[j]:.4g} {unit}"
                       for j in np.flatnonzero(bad))
        return out


def default_limits(arm: ArmModel, center: FloatArray | None = None, span: float = 1.0,
                   velocity: float = 1.0, acceleration: float = 4.0) -> DesignLimits:
    """Design limits of an arm: ±span around ``center`` (within the URDF's range), at most
    ``velocity`` and ``acceleration`` per joint (and the URDF's velocity limit), the URDF's
    effort limits.

    Parameters
    ----------
    arm : ArmModel
    center : ndarray, shape (n,), optional
        Middle of the position range (rad); zero by default.
    span : float
        Half-width of the position range (rad).
    velocity, acceleration : float
        rad/s, rad/s².

    Returns
    -------
    DesignLimits
    """
    c = np.zeros(arm.n) if center is None else np.asarray(center, dtype=float)
    return DesignLimits(np.maximum(c - span, arm.lower), np.minimum(c + span, arm.upper),
                        np.minimum(velocity, arm.velocity_limit), np.full(arm.n, acceleration),
                        arm.effort_limit.copy())


@dataclass(frozen=True)
class Design:
    """Result of :func:`design_excitation`.

    Attributes
    ----------
    trajectory : FourierTrajectory
        The designed trajectory (within the limits).
    start : FourierTrajectory
        The random trajectory the optimiser started from (same limits).
    cond_start, cond : float
        Condition number of the base regressor over one period, before and after.
    cond_random : float
        Median condition number of ``baseline`` random trajectories within the same limits.
    iterations : int
    """

    trajectory: FourierTrajectory
    start: FourierTrajectory
    cond_start: float
    cond: float
    cond_random: float
    iterations: int


class _Problem:
    """Scaling to the limits and the base regressor's condition number on a period grid."""

    def __init__(self, arm: ArmModel, base: BaseParameters | None, nominal: FloatArray,
                 limits: DesignLimits, template: FourierTrajectory, points: int) -> None:
        self.arm, self.base, self.nominal, self.limits = arm, base, nominal, limits
        self.template = template
        self.t = np.linspace(0.0, template.period, points, endpoint=False)
        # the limits are checked on a grid 10 × finer than the condition number's
        self.check = np.linspace(0.0, template.period, 10 * points, endpoint=False)

    def scaled(self, x: FloatArray, fine: bool = False) -> FourierTrajectory:
        """The trajectory of coefficients x, scaled per joint to the kinematic limits and as
        a whole to the torque limits, on the condition number's grid (while optimising) or
        the fine one (the result)."""
        grid = self.check if fine else self.t
        traj = self.template.with_coefficients(x)
        q, qd, qdd = traj.evaluate(grid)
        lim = self.limits
        center = 0.5 * (lim.lower + lim.upper)
        # q − q0 scales with the coefficients: |q0 − centre| + s max|q − q0| ≤ half-range
        room = 0.5 * (lim.upper - lim.lower) - np.abs(traj.q0 - center)
        s = np.min([room / np.maximum(np.abs(q - traj.q0).max(axis=0), 1e-12),
                    lim.velocity / np.maximum(np.abs(qd).max(axis=0), 1e-12),
                    lim.acceleration / np.maximum(np.abs(qdd).max(axis=0), 1e-12)], axis=0)
        L = traj.harmonics
        # 0.2 % margin: the maxima between grid points are higher by < 0.05 %
        traj = traj.with_coefficients(np.tile(np.repeat(0.998 * s, L), 2) * x)
        full = traj.coefficients

        def over(alpha: float) -> float:
            """max_j,t |τ| / limit at amplitude α (the nominal model's torque)."""
            q, qd, qdd = traj.with_coefficients(alpha * full).evaluate(grid)
            return float(np.max(np.abs(regressor(self.arm, q, qd, qdd) @ self.nominal)
                                / lim.effort))

        if over(1.0) > 1.0:
            # τ is not linear in the amplitude: bisect for the largest α within the limits
            lo, hi = 0.0, 1.0
            for _ in range(12):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if over(mid) <= 1.0 else (lo, mid)
            traj = traj.with_coefficients(lo * full)
        return traj

    def cond(self, traj: FourierTrajectory) -> float:
        """Condition number of the stacked base regressor over the period grid."""
        q, qd, qdd = traj.evaluate(self.t)
        assert self.base is not None
        W = self.base.columns(regressor(self.arm, q, qd, qdd)).reshape(-1, self.base.size)
        if not np.all(np.isfinite(W)):
            return float("inf")
        # cond(W) = sqrt(λ_max / λ_min) of WᵀW (b × b: cheaper than the SVD of W)
        lam = np.linalg.eigvalsh(W.T @ W)
        return float(np.sqrt(lam[-1] / lam[0])) if lam[0] > 0 else float("inf")

    def objective(self, x: FloatArray) -> float:
        """log cond of the scaled trajectory (log: the optimiser sees orders of magnitude);
        an unexcited base parameter counts as cond 1e17."""
        return float(np.log(min(self.cond(self.scaled(x)), 1e17)))


def design_excitation(arm: ArmModel, base: BaseParameters, nominal: FloatArray,
                      limits: DesignLimits, harmonics: int = 5, base_frequency: float = 0.1,
                      center: FloatArray | None = None, seed: int = 0,
                      iterations: int = 60, points: int | None = None,
                      baseline: int = 8) -> Design:
    """Optimise FFS coefficients for the base regressor's condition number.

    Parameters
    ----------
    arm : ArmModel
    base : BaseParameters
    nominal : ndarray, shape (14 n,)
        Full parameters for the torque limit check.
    limits : DesignLimits
    harmonics : int
        L.
    base_frequency : float
        f_f (Hz).
    center : ndarray, shape (n,), optional
        q0 (rad); the middle of the position limits by default.
    seed : int
        Seed of the random start.
    iterations : int
        L-BFGS-B iterations (over its restarts).
    baseline : int
        Random trajectories whose median condition number is the reference.
    points : int, optional
        Grid points per period of the condition number (default 10 per harmonic); the
        limits hold on a grid ten times finer.

    Returns
    -------
    Design

    Raises
    ------
    ValueError
        If the limits cannot be met (a torque limit below what holding the arm at q0
        takes; names each joint and quantity) or leave no exciting motion.
    """
    q0 = 0.5 * (limits.lower + limits.upper) if center is None else np.asarray(center, float)
    n = arm.n
    template = FourierTrajectory(q0, np.zeros((n, harmonics)), np.zeros((n, harmonics)),
                                 float(base_frequency))
    problem = _Problem(arm, base, nominal, limits, template, points or 10 * harmonics)
    rng = np.random.default_rng(seed)
    randoms = [problem.scaled(rng.uniform(-1.0, 1.0, 2 * n * harmonics), fine=True)
               for _ in range(max(baseline, 1))]
    start = randoms[0]
    # L-BFGS-B stops when a line search fails at a kink of the scaling (a max over the
    # grid); it restarts from where it stopped until the iterations are spent or a restart
    # gains nothing
    x, f, used = problem.scaled(start.coefficients).coefficients, np.inf, 0
    while used < iterations:
        sol = scipy.optimize.minimize(problem.objective, x, method="L-BFGS-B",
                                      options={"maxiter": iterations - used, "eps": 1e-6})
        used += max(int(sol.nit), 1)
        if not sol.fun < f - 1e-4:
            break
        x, f = problem.scaled(sol.x).coefficients, float(sol.fun)
    best = problem.scaled(x, fine=True)
    q, qd, qdd = best.evaluate(problem.check)
    bad = limits.violations(q, qd, qdd, regressor(arm, q, qd, qdd) @ nominal, arm.names)
    if bad:
        raise ValueError("no trajectory around q0 = " + np.array2string(q0, precision=3)
                         + " rad fits the limits (the nominal model needs more even at small "
                         "amplitude): " + "; ".join(bad))
    cond = problem.cond(best)
    if not cond < 1e17:
        raise ValueError("the limits leave no motion that excites every base parameter "
                         "(torque limits barely above holding the arm at q0?); widen them")
    return Design(best, start, problem.cond(start), cond,
                  float(np.median([problem.cond(r) for r in randoms])), used)


def within_limits(arm: ArmModel, trajectory: FourierTrajectory, limits: DesignLimits,
                  nominal: FloatArray) -> FourierTrajectory:
    """A trajectory's coefficients scaled per joint to the kinematic limits and as a whole to
    the torque limits of the nominal model (the shape kept, the amplitude as large as the
    limits allow; q0 unchanged).

    Parameters
    ----------
    arm : ArmModel
    trajectory : FourierTrajectory
    limits : DesignLimits
    nominal : ndarray, shape (14 n,)

    Returns
    -------
    FourierTrajectory
    """
    problem = _Problem(arm, None, nominal, limits, trajectory, 10 * trajectory.harmonics)
    return problem.scaled(trajectory.coefficients, fine=True)


def regressor_cond(arm: ArmModel, base: BaseParameters, trajectory: FourierTrajectory,
                   points: int | None = None) -> float:
    """Condition number of the base regressor of a trajectory over one period."""
    problem = _Problem(arm, base, np.zeros(14 * arm.n), default_limits(arm), trajectory,
                       points or 10 * trajectory.harmonics)
    return problem.cond(trajectory)
