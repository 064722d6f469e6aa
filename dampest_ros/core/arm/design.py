"""Excitation design of an arm: FFS coefficients that minimise the condition number of the
base regressor (friction columns included) over one period, or maximise the log det of its
column-normalised information matrix (D-optimal), within joint position, velocity,
acceleration and torque limits, by the shared design engine
(:mod:`dampest_ros.core.simulation.design`: scaling to the limits, L-BFGS-B, random FFS
coefficients within the same limits as the baseline).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.arm.base import BaseParameters
from dampest_ros.core.arm.ffs import FourierTrajectory
from dampest_ros.core.arm.model import ArmModel
from dampest_ros.core.arm.regressor import regressor
from dampest_ros.core.simulation.design import Design, DesignLimits, DesignProblem, optimise

FloatArray = NDArray[np.float64]

__all__ = ["Design", "DesignLimits", "default_limits", "design_excitation", "regressor_cond",
           "within_limits"]


def default_limits(arm: ArmModel, span: float = 1.0, velocity: float = 1.0,
                   acceleration: float = 4.0) -> DesignLimits:
    """Design limits of an arm: per joint ±span around the middle of its own position range,
    within that range; at most ``velocity`` and ``acceleration`` (and the URDF's velocity
    limit); the URDF's effort limits.

    A joint limited to [0, 3] rad with span 1 ranges over [0.5, 2.5], one limited to ±2π over
    ±1; a joint without limits (URDF ``continuous``) over ±span around 0, and one with a
    single finite limit over span either side of the point of zero nearest within its range.

    Parameters
    ----------
    arm : ArmModel
    span : float
        Half-width of the position range (rad); the default amplitude of a continuous joint.
    velocity, acceleration : float
        rad/s, rad/s².

    Returns
    -------
    DesignLimits
    """
    bounded = np.isfinite(arm.lower) & np.isfinite(arm.upper)
    middle = np.where(bounded, 0.5 * (np.where(bounded, arm.lower, 0.0)
                                      + np.where(bounded, arm.upper, 0.0)),
                      np.clip(0.0, arm.lower, arm.upper))
    return DesignLimits(np.maximum(middle - span, arm.lower),
                        np.minimum(middle + span, arm.upper),
                        np.minimum(velocity, arm.velocity_limit), np.full(arm.n, acceleration),
                        arm.effort_limit.copy())


def _problem(arm: ArmModel, base: BaseParameters | None, nominal: FloatArray,
             limits: DesignLimits, template: FourierTrajectory, points: int) -> DesignProblem:
    """The arm's design problem: the stacked base regressor, the nominal joint torques."""
    def base_regressor(q: FloatArray, qd: FloatArray, qdd: FloatArray) -> FloatArray:
        assert base is not None
        return base.columns(regressor(arm, q, qd, qdd)).reshape(-1, base.size)

    def torque(q: FloatArray, qd: FloatArray, qdd: FloatArray) -> FloatArray:
        return np.asarray(regressor(arm, q, qd, qdd) @ nominal, dtype=float)

    return DesignProblem(base_regressor if base is not None else None, torque, limits,
                         template, points)


def design_excitation(arm: ArmModel, base: BaseParameters, nominal: FloatArray,
                      limits: DesignLimits, harmonics: int = 5, base_frequency: float = 0.1,
                      center: FloatArray | None = None, seed: int = 0,
                      iterations: int = 60, points: int | None = None,
                      baseline: int = 8, objective: str = "cond") -> Design:
    """Optimise FFS coefficients for the base regressor's condition number (``cond``) or
    D-optimality (``dopt``: log det of its column-normalised information matrix).

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
    objective : str
        ``cond`` or ``dopt`` (:data:`dampest_ros.core.simulation.design.OBJECTIVES`).

    Returns
    -------
    Design

    Raises
    ------
    ValueError
        If the objective is unknown, the limits cannot be met (a torque limit below what
        holding the arm at q0 takes; names each joint and quantity) or leave no exciting
        motion.
    """
    q0 = 0.5 * (limits.lower + limits.upper) if center is None else np.asarray(center, float)
    n = arm.n
    template = FourierTrajectory(q0, np.zeros((n, harmonics)), np.zeros((n, harmonics)),
                                 float(base_frequency))
    problem = _problem(arm, base, nominal, limits, template, points or 10 * harmonics)
    return optimise(problem, arm.names, seed=seed, iterations=iterations, baseline=baseline,
                    objective=objective)


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
    problem = _problem(arm, None, nominal, limits, trajectory, 10 * trajectory.harmonics)
    return problem.scaled(trajectory.coefficients, fine=True)


def regressor_cond(arm: ArmModel, base: BaseParameters, trajectory: FourierTrajectory,
                   points: int | None = None) -> float:
    """Condition number of the base regressor of a trajectory over one period."""
    problem = _problem(arm, base, np.zeros(14 * arm.n), default_limits(arm), trajectory,
                       points or 10 * trajectory.harmonics)
    return problem.cond(trajectory)
