"""Excitation design, shared by the arm and the vehicle: finite-Fourier-series (FFS)
coefficients that minimise the condition number of a regressor over one period (``cond``) or
maximise the log determinant of its information matrix (``dopt``, D-optimal), within
position, velocity, acceleration and effort limits (Swevers et al. 1997; Gautier & Khalil
1992).

The FFS (:class:`FourierTrajectory`): for coordinate j, with ω_f = 2π f_f the base angular
frequency and L harmonics,

    q_j(t)  = q0_j + Σ_l [ a_jl / (l ω_f) sin(l ω_f t) − b_jl / (l ω_f) cos(l ω_f t) ]
    q̇_j(t)  = Σ_l [ a_jl cos(l ω_f t) + b_jl sin(l ω_f t) ]
    q̈_j(t)  = Σ_l l ω_f [ −a_jl sin(l ω_f t) + b_jl cos(l ω_f t) ]

so the trajectory repeats every 1/f_f seconds and the data of whole periods average
periodic noise out (Swevers et al. 1997). What is excited is the
caller's: ``regressor(q, q̇, q̈)`` gives the stacked regressor whose conditioning counts (the
arm's base regressor with friction columns, the vehicle's damping regressor), and
``effort(q, q̇, q̈)`` what the nominal model needs to fly it (joint torques, thruster thrusts).

Limits are met by construction: any coefficient vector is first scaled per coordinate so
that its position excursion, |q̇| and |q̈| over one period reach at most the limits, then as a
whole until the nominal effort does too (while optimising on the condition number's grid,
for the result on a grid ten times finer). The optimiser (scipy L-BFGS-B on log cond or
−log det, numerical gradient) therefore searches shapes without constraints, and random
coefficients put through the same scaling are the fair baseline.

The two objectives differ in what they reward. The condition number is the spread of the
information matrix WᵀW's eigenvalues: it rewards balance and is blind to the overall size of
the information. D-optimality, log det WᵀW, is the (negative log) volume of the parameters'
confidence ellipsoid under white noise: it rewards every direction's information, the weakest
included. Its columns are normalised by the median column RMS of the random baseline
(W ↦ W S⁻¹, S fixed per problem), which only shifts log det by a constant, so the optimum is
the same and the number is readable: 0 is a trajectory whose columns are orthogonal with the
random ones' energy.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
#: (q, q̇, q̈), each (N, n) → an array of N rows per sample: the stacked regressor (R, p)
#: or the effort (N, m).
Kinematic = Callable[[FloatArray, FloatArray, FloatArray], FloatArray]
#: The design objectives: the condition number (minimised) and D-optimality (log det of the
#: column-normalised information matrix, maximised).
OBJECTIVES = ("cond", "dopt")


@dataclass(frozen=True)
class FourierTrajectory:
    """An FFS trajectory for n joints.

    Attributes
    ----------
    q0 : ndarray, shape (n,)
        Offset (rad).
    a, b : ndarray, shape (n, L)
        Velocity amplitudes of the cosine and sine terms of harmonic l (rad/s).
    base_frequency : float
        f_f (Hz); the period is 1 / f_f.
    """

    q0: FloatArray
    a: FloatArray
    b: FloatArray
    base_frequency: float

    @property
    def period(self) -> float:
        """1 / f_f (s)."""
        return 1.0 / self.base_frequency

    @property
    def harmonics(self) -> int:
        """L."""
        return int(self.a.shape[1])

    def basis(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """sin and cos of every harmonic at t, and l ω_f.

        Parameters
        ----------
        t : ndarray, shape (N,)
            Time (s).

        Returns
        -------
        s, c : ndarray, shape (N, L)
            sin(l ω_f t), cos(l ω_f t).
        lw : ndarray, shape (L,)
            l ω_f (rad/s).
        """
        lw = 2.0 * np.pi * self.base_frequency * np.arange(1, self.harmonics + 1, dtype=float)
        phase = np.outer(np.asarray(t, dtype=float), lw)
        return np.sin(phase), np.cos(phase), lw

    def evaluate(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """q, q̇, q̈ at the given times.

        Parameters
        ----------
        t : ndarray, shape (N,)
            Time (s).

        Returns
        -------
        q, qd, qdd : ndarray, shape (N, n)
            rad, rad/s, rad/s².
        """
        s, c, lw = self.basis(t)
        # q = q0 + Σ (a sin − b cos) / (l ω_f)
        q = self.q0 + s @ (self.a / lw).T - c @ (self.b / lw).T
        # q̇ = Σ a cos + b sin
        qd = c @ self.a.T + s @ self.b.T
        # q̈ = Σ l ω_f (−a sin + b cos)
        qdd = -s @ (self.a * lw).T + c @ (self.b * lw).T
        return q, qd, qdd

    def with_coefficients(self, x: FloatArray) -> FourierTrajectory:
        """The same offset and frequency with coefficients x = [a.ravel(), b.ravel()]."""
        n, L = self.a.shape
        x = np.asarray(x, dtype=float)
        return FourierTrajectory(self.q0, x[:n * L].reshape(n, L), x[n * L:].reshape(n, L),
                                 self.base_frequency)

    @property
    def coefficients(self) -> FloatArray:
        """[a.ravel(), b.ravel()], shape (2 n L,)."""
        return np.concatenate([self.a.ravel(), self.b.ravel()])


@dataclass(frozen=True)
class DesignLimits:
    """Bounds a designed trajectory keeps, per coordinate (shapes (n,); ±inf: none) and
    per effort channel (shape (m,)).

    Attributes
    ----------
    lower, upper : ndarray
        Position bounds (rad or m).
    velocity : ndarray
        |q̇| bound (rad/s or m/s).
    acceleration : ndarray
        |q̈| bound (rad/s² or m/s²).
    effort : ndarray
        |effort| bound of the nominal model (N m, N).
    """

    lower: FloatArray
    upper: FloatArray
    velocity: FloatArray
    acceleration: FloatArray
    effort: FloatArray

    def violations(self, q: FloatArray, qd: FloatArray, qdd: FloatArray, tau: FloatArray,
                   names: tuple[str, ...], tol: float = 1e-9,
                   effort_names: tuple[str, ...] | None = None,
                   units: tuple[str, str, str, str] = ("rad", "rad/s", "rad/s²", "N m")
                   ) -> list[str]:
        """What a sampled trajectory exceeds: one phrase per coordinate (effort channel) and
        quantity, empty if nothing.

        Parameters
        ----------
        q, qd, qdd : ndarray, shape (N, n)
        tau : ndarray, shape (N, m)
            The nominal effort.
        names : tuple of str
            The n coordinates.
        tol : float
        effort_names : tuple of str, optional
            The m effort channels (default: ``names``).
        units : (str, str, str, str)
            Of position, velocity, acceleration and effort.
        """
        out: list[str] = []
        pos, vel, acc, eff = units
        checks = ((names, "position", q.min(axis=0) < self.lower - tol, q.min(axis=0),
                   self.lower, f"{pos} (below the lower limit)"),
                  (names, "position", q.max(axis=0) > self.upper + tol, q.max(axis=0),
                   self.upper, f"{pos} (above the upper limit)"),
                  (names, "|velocity|", np.abs(qd).max(axis=0) > self.velocity * (1 + tol),
                   np.abs(qd).max(axis=0), self.velocity, vel),
                  (names, "|acceleration|",
                   np.abs(qdd).max(axis=0) > self.acceleration * (1 + tol),
                   np.abs(qdd).max(axis=0), self.acceleration, acc),
                  (effort_names or names, "|effort|" if effort_names else "|torque|",
                   np.abs(tau).max(axis=0) > self.effort * (1 + tol),
                   np.abs(tau).max(axis=0), self.effort, eff))
        for who, what, bad, value, limit, unit in checks:
            out.extend(f"{who[j]} {what} {value[j]:.4g} exceeds {limit[j]:.4g} {unit}"
                       for j in np.flatnonzero(bad))
        return out


@dataclass(frozen=True)
class Design:
    """Result of :func:`optimise`.

    Attributes
    ----------
    trajectory : FourierTrajectory
        The designed trajectory (within the limits).
    start : FourierTrajectory
        The random trajectory the optimiser started from (same limits).
    cond_start, cond : float
        Condition number of the regressor over one period, before and after.
    cond_random : float
        Median condition number of ``baseline`` random trajectories within the same limits.
    iterations : int
    objective : str
        What was optimised, one of :data:`OBJECTIVES`.
    logdet_start, logdet, logdet_random : float
        log det (WₙᵀWₙ / R) of the start, the result and the median of the random ones, W's
        R rows over one period and its columns divided by the random trajectories' median
        column RMS (so that the numbers of two designs of one problem and seed compare).
    """

    trajectory: FourierTrajectory
    start: FourierTrajectory
    cond_start: float
    cond: float
    cond_random: float
    iterations: int
    objective: str
    logdet_start: float
    logdet: float
    logdet_random: float


class DesignProblem:
    """Scaling to the limits and the regressor's condition number on a period grid.

    Parameters
    ----------
    regressor : callable or None
        (q, q̇, q̈) → stacked regressor (R, p) (None: scaling only).
    effort : callable
        (q, q̇, q̈) → nominal effort (N, m).
    limits : DesignLimits
    template : FourierTrajectory
        q0, the number of harmonics and the base frequency.
    points : int
        Grid points per period of the condition number.
    """

    def __init__(self, regressor: Kinematic | None, effort: Kinematic, limits: DesignLimits,
                 template: FourierTrajectory, points: int) -> None:
        self.regressor, self.effort, self.limits = regressor, effort, limits
        self.template = template
        self.t = np.linspace(0.0, template.period, points, endpoint=False)
        # the limits are checked on a grid 10 × finer than the condition number's
        self.check = np.linspace(0.0, template.period, 10 * points, endpoint=False)

    def scaled(self, x: FloatArray, fine: bool = False) -> FourierTrajectory:
        """The trajectory of coefficients x, scaled per coordinate to the kinematic limits
        and as a whole to the effort limits, on the condition number's grid (while
        optimising) or the fine one (the result)."""
        grid = self.check if fine else self.t
        traj = self.template.with_coefficients(x)
        q, qd, qdd = traj.evaluate(grid)
        lim = self.limits
        bounded = np.isfinite(lim.lower) & np.isfinite(lim.upper)
        lower, upper = np.where(bounded, lim.lower, 0.0), np.where(bounded, lim.upper, 0.0)
        center = 0.5 * (lower + upper)
        # q − q0 scales with the coefficients: |q0 − centre| + s max|q − q0| ≤ half-range
        room = np.where(bounded, 0.5 * (upper - lower) - np.abs(traj.q0 - center), np.inf)
        s = np.min([room / np.maximum(np.abs(q - traj.q0).max(axis=0), 1e-12),
                    lim.velocity / np.maximum(np.abs(qd).max(axis=0), 1e-12),
                    lim.acceleration / np.maximum(np.abs(qdd).max(axis=0), 1e-12)], axis=0)
        L = traj.harmonics
        # 0.2 % margin: the maxima between grid points are higher by < 0.05 %
        traj = traj.with_coefficients(np.tile(np.repeat(0.998 * s, L), 2) * x)
        full = traj.coefficients

        def over(alpha: float) -> float:
            """max over channels and t of |effort| / limit at amplitude α."""
            q, qd, qdd = traj.with_coefficients(alpha * full).evaluate(grid)
            return float(np.max(np.abs(self.effort(q, qd, qdd)) / lim.effort))

        if over(1.0) > 1.0:
            # the effort is not linear in the amplitude: bisect for the largest α within
            lo, hi = 0.0, 1.0
            for _ in range(12):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if over(mid) <= 1.0 else (lo, mid)
            traj = traj.with_coefficients(lo * full)
        return traj

    def information(self, traj: FourierTrajectory) -> FloatArray:
        """Eigenvalues of the information matrix WᵀW / R of the stacked regressor over the
        period grid, ascending, shape (p,); NaN if W is not finite."""
        assert self.regressor is not None
        W = self.regressor(*traj.evaluate(self.t))
        if not np.all(np.isfinite(W)):
            return np.full(W.shape[1], np.nan)
        # eigenvalues of WᵀW (p × p: cheaper than the SVD of W)
        return np.asarray(np.linalg.eigvalsh(W.T @ W / len(W)), dtype=float)

    def column_rms(self, traj: FourierTrajectory) -> FloatArray:
        """RMS of each column of the stacked regressor over the period grid, shape (p,)."""
        assert self.regressor is not None
        W = self.regressor(*traj.evaluate(self.t))
        return np.asarray(np.sqrt(np.mean(W ** 2, axis=0)), dtype=float)

    def cond(self, traj: FourierTrajectory) -> float:
        """Condition number of the stacked regressor over the period grid."""
        lam = self.information(traj)
        if not np.all(np.isfinite(lam)):
            return float("inf")
        # cond(W) = sqrt(λ_max / λ_min) of WᵀW
        return float(np.sqrt(lam[-1] / lam[0])) if lam[0] > 0 else float("inf")

    def logdet(self, traj: FourierTrajectory, scale: FloatArray) -> float:
        """log det (Wₙᵀ Wₙ / R), Wₙ = W diag(scale)⁻¹ (−inf if singular or not finite).

        Parameters
        ----------
        traj : FourierTrajectory
        scale : ndarray, shape (p,)
            Column units (those of W), fixed per problem.
        """
        lam = self.information(traj)
        if not (np.all(np.isfinite(lam)) and lam[0] > 0):
            return float("-inf")
        return float(np.sum(np.log(lam)) - 2.0 * np.sum(np.log(scale)))

    def objective(self, x: FloatArray) -> float:
        """log cond of the scaled trajectory (log: the optimiser sees orders of magnitude);
        an unexcited parameter counts as cond 1e17."""
        return float(np.log(min(self.cond(self.scaled(x)), 1e17)))

    def d_objective(self, x: FloatArray, scale: FloatArray) -> float:
        """−log det of the scaled trajectory's column-normalised information matrix; an
        unexcited parameter counts as an eigenvalue 1e-34 (cond 1e17) of the strongest."""
        lam = self.information(self.scaled(x))
        if not np.all(np.isfinite(lam)) or lam[-1] <= 0:
            return float(-scale.size * np.log(1e-34))
        lam = np.maximum(lam, 1e-34 * lam[-1])
        return float(-(np.sum(np.log(lam)) - 2.0 * np.sum(np.log(scale))))


def optimise(problem: DesignProblem, names: tuple[str, ...], seed: int = 0,
             iterations: int = 60, baseline: int = 8,
             effort_names: tuple[str, ...] | None = None,
             units: tuple[str, str, str, str] = ("rad", "rad/s", "rad/s²", "N m"),
             objective: str = "cond") -> Design:
    """Optimise the FFS coefficients of ``problem`` for its regressor's condition number
    (``cond``) or the log det of its column-normalised information matrix (``dopt``).

    Parameters
    ----------
    problem : DesignProblem
    names : tuple of str
        The coordinates (for the error message).
    seed : int
        Seed of the random start and the random baseline (uniform coefficients in ±1).
    iterations : int
        L-BFGS-B iterations (over its restarts).
    baseline : int
        Random trajectories whose median condition number is the reference.
    effort_names, units
        As :meth:`DesignLimits.violations`.
    objective : str
        One of :data:`OBJECTIVES`.

    Returns
    -------
    Design

    Raises
    ------
    ValueError
        If the objective is unknown, the limits cannot be met (an effort limit below what
        holding still at q0 takes; names each coordinate and quantity) or leave no motion
        that excites every parameter.
    """
    if objective not in OBJECTIVES:
        raise ValueError(f"unknown design objective {objective!r}; use one of "
                         + ", ".join(OBJECTIVES))
    n, L = problem.template.a.shape
    rng = np.random.default_rng(seed)
    randoms = [problem.scaled(rng.uniform(-1.0, 1.0, 2 * n * L), fine=True)
               for _ in range(max(baseline, 1))]
    start = randoms[0]
    rms = np.median([problem.column_rms(r) for r in randoms], axis=0)
    scale = np.where(rms > 1e-12 * rms.max(), rms, 1.0)
    fun = (problem.objective if objective == "cond"
           else functools.partial(problem.d_objective, scale=scale))
    # L-BFGS-B stops when a line search fails at a kink of the scaling (a max over the
    # grid); it restarts from where it stopped until the iterations are spent or a restart
    # gains nothing
    x, f, used = problem.scaled(start.coefficients).coefficients, np.inf, 0
    while used < iterations:
        sol = scipy.optimize.minimize(fun, x, method="L-BFGS-B",
                                      options={"maxiter": iterations - used, "eps": 1e-6})
        used += max(int(sol.nit), 1)
        if not sol.fun < f - 1e-4:
            break
        x, f = problem.scaled(sol.x).coefficients, float(sol.fun)
    best = problem.scaled(x, fine=True)
    q, qd, qdd = best.evaluate(problem.check)
    bad = problem.limits.violations(q, qd, qdd, problem.effort(q, qd, qdd), names,
                                    effort_names=effort_names, units=units)
    if bad:
        raise ValueError("no trajectory around q0 = " + np.array2string(best.q0, precision=3)
                         + f" {units[0]} fits the limits (the nominal model needs more even at "
                         "small amplitude): " + "; ".join(bad))
    cond = problem.cond(best)
    if not cond < 1e17:
        raise ValueError("the limits leave no motion that excites every parameter (effort "
                         "limits barely above holding still at q0?); widen them")
    return Design(best, start, problem.cond(start), cond,
                  float(np.median([problem.cond(r) for r in randoms])), used, objective,
                  problem.logdet(start, scale), problem.logdet(best, scale),
                  float(np.median([problem.logdet(r, scale) for r in randoms])))
