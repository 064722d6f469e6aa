"""Excitation design of a vehicle: finite-Fourier-series references optimised for the
conditioning of its damping regressor, by the design engine the arm uses
(:mod:`dampest_ros.core.simulation.design`).

The six FFS coordinates are the body velocities' integrals: q = [x, y, z, φ, θ, ψ] with
q̇ = ν (FRD; m/s, rad/s), so the references are ν_ref = q̇, roll and pitch φ, θ and the depth
z around its mean. Limits: |ν| within the speed limits (the steady speed half the largest
thrust holds, :func:`dampest_ros.core.simulation.excitation.speed_limits`), roll and pitch within
±25°, the depth within ±``depth_span``, and every thruster's thrust for the nominal model's
τ = M ν̇ + C(ν)ν + D(ν)ν + g(η) within ``thrust_share`` of its largest (the rest is the
velocity controller's margin). The regressor is the damping regressor Φ(ν) of the vehicle's
terms (what batch identification fits, :meth:`dampest_ros.core.physics.damping.DampingModel.
regressor`), each row in units of its DOF's thrust range and each column in units of its
RMS over the speed envelope (velocities uniform within ± the limits): the condition number
then measures how well the data separate the coefficients and how much of each column's
range they fly, not the columns' units.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.simulation.design import (
    Design,
    DesignLimits,
    DesignProblem,
    FourierTrajectory,
    Kinematic,
    optimise,
)

FloatArray = NDArray[np.float64]

#: The FFS coordinates: the integrals of ν (m and rad).
COORDINATES = ("x", "y", "z", "roll", "pitch", "yaw")


def vehicle_limits(vehicle: Vehicle, velocity: FloatArray, max_angle: float,
                   depth_span: float = 2.0, thrust_share: float = 0.7) -> DesignLimits:
    """The limits of a vehicle's designed excitation.

    Parameters
    ----------
    vehicle : Vehicle
        With thrusters.
    velocity : ndarray, shape (6,)
        |ν| bound per DOF (m/s, rad/s).
    max_angle : float
        |roll|, |pitch| bound (rad).
    depth_span : float
        Depth excursion around the mean (m).
    thrust_share : float
        Share of each thruster's largest thrust the nominal model may use.

    Returns
    -------
    DesignLimits
        Effort channels: the thrusters (N).
    """
    thr = vehicle.need_thrusters("designing an excitation (the thrust limits)")
    bound = np.array([np.inf, np.inf, depth_span, max_angle, max_angle, np.inf])
    return DesignLimits(-bound, bound, np.asarray(velocity, dtype=float), np.full(6, np.inf),
                        np.full(thr.count, thrust_share * thr.gain * thr.n_max**2))


def nominal_wrench(vehicle: Vehicle) -> Kinematic:
    """τ(q, q̇, q̈) = M ν̇ + C(ν)ν + D(ν)ν + g(η) of the nominal model along FFS coordinates
    (ν = q̇, ν̇ = q̈, roll and pitch q₃, q₄; fluid-memory states at rest): what flying the
    references takes, for the thrust limits and as the protocol's feed-forward.

    Returns
    -------
    callable
        (q, q̇, q̈), each (N, 6) → τ (N, 6) (N, N·m).
    """
    body, damping = vehicle.body, vehicle.damping
    coriolis = _quadratic_form(body.coriolis_force)
    # g(η) is linear in the world's down axis in body axes (R's last row): g = G R[2, :]
    gravity = body.restoring(np.array([[[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
                                       [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]],
                                       np.eye(3)])).T
    rest = np.zeros((1, len(damping.memory_rates)))

    def wrench(q: FloatArray, qd: FloatArray, qdd: FloatArray) -> FloatArray:
        # R[2, :] = [−sin θ, cos θ sin φ, cos θ cos φ] (ZYX Euler angles, any yaw)
        down = np.column_stack([-np.sin(q[:, 4]), np.cos(q[:, 4]) * np.sin(q[:, 3]),
                                np.cos(q[:, 4]) * np.cos(q[:, 3])])
        # τ = M ν̇ + C(ν)ν + D(ν)ν + g(η)
        return np.asarray(qdd @ body.M_inertial.T + np.einsum("ijk,nj,nk->ni", coriolis, qd, qd)
                          + damping.force(qd, vehicle.theta, np.repeat(rest, len(qd), axis=0))
                          + down @ gravity.T, dtype=float)

    return wrench


def _problem(vehicle: Vehicle, limits: DesignLimits, template: FourierTrajectory,
             points: int, column_scale: FloatArray | None) -> DesignProblem:
    """The vehicle's design problem: the scaled damping regressor, the thrusts."""
    thr = vehicle.need_thrusters("designing an excitation (the thrust limits)")
    damping = vehicle.damping
    rows = 1.0 / vehicle.wrench_scale()
    t = np.linspace(0.0, template.period, points, endpoint=False)
    wrench = nominal_wrench(vehicle)

    def regressor(q: FloatArray, qd: FloatArray, qdd: FloatArray) -> FloatArray:
        del q, qdd
        states = damping.memory_states(t, qd) if len(damping.memory_rates) else None
        # Φ(ν) with each DOF's row per unit of its thrust range
        phi = damping.regressor(qd, states) * rows[None, :, None]
        scale = 1.0 if column_scale is None else column_scale
        return np.asarray(phi.reshape(-1, phi.shape[2]) / scale, dtype=float)

    def thrusts(q: FloatArray, qd: FloatArray, qdd: FloatArray) -> FloatArray:
        return np.asarray(thr.allocate(wrench(q, qd, qdd)), dtype=float)

    return DesignProblem(regressor, thrusts, limits, template, points)


def _quadratic_form(f: Callable[[FloatArray], FloatArray]) -> FloatArray:
    """H (6, 6, 6), symmetric in its last two indices, with f(ν) = Σ_jk H_ijk ν_j ν_k for a
    function quadratic in ν (C(ν)ν: C is linear in ν), from f at e_j and e_j + e_k."""
    eye = np.eye(6)
    pairs = (eye[:, None, :] + eye[None, :, :]).reshape(36, 6)
    single = f(eye)  # f(e_j) = H_jj
    both = f(pairs).reshape(6, 6, 6)  # f(e_j + e_k) = H_jj + H_kk + 2 H_jk (j ≠ k)
    H = 0.5 * (both - single[:, None, :] - single[None, :, :])
    H[np.arange(6), np.arange(6)] = single
    return np.ascontiguousarray(np.moveaxis(H, 2, 0))


def design_vehicle(vehicle: Vehicle, limits: DesignLimits, harmonics: int = 5,
                   base_frequency: float = 0.1, seed: int = 0, iterations: int = 30,
                   baseline: int = 8, points: int | None = None) -> Design:
    """FFS velocity, roll, pitch and depth references optimised for the condition number of
    the vehicle's (scaled) damping regressor within ``limits``.

    Parameters
    ----------
    vehicle : Vehicle
        The nominal vehicle (its terms, mass, restoring and thrusters).
    limits : DesignLimits
        :func:`vehicle_limits`.
    harmonics : int
        L.
    base_frequency : float
        f_f (Hz); the references repeat every 1 / f_f seconds.
    seed : int
        Seed of the random start and baseline.
    iterations : int
        L-BFGS-B iterations.
    baseline : int
        Random FFS (same limits) whose median condition number is the reference.
    points : int, optional
        Grid points per period (default 12 per harmonic).

    Returns
    -------
    Design
        Its condition numbers are those of the scaled damping regressor.
    """
    template = FourierTrajectory(np.zeros(6), np.zeros((6, harmonics)),
                                 np.zeros((6, harmonics)), float(base_frequency))
    points = points or 12 * harmonics
    # column units: the RMS of each column over the speed envelope (velocities uniform
    # within ± the limits, a 50 Hz sequence for the memory states), so that a coefficient
    # flown only at low speed shows as a weak column
    env = np.random.default_rng(0).uniform(-1.0, 1.0, (4096, 6)) * limits.velocity
    damping = vehicle.damping
    states = (damping.memory_states(np.arange(len(env)) / 50.0, env)
              if len(damping.memory_rates) else None)
    phi = damping.regressor(env, states) / vehicle.wrench_scale()[None, :, None]
    scale = np.sqrt(np.mean(phi.reshape(-1, phi.shape[2]) ** 2, axis=0))
    scale = np.where(scale > 1e-12 * scale.max(), scale, 1.0)
    problem = _problem(vehicle, limits, template, points, scale)
    return optimise(problem, COORDINATES, seed=seed, iterations=iterations, baseline=baseline,
                    effort_names=vehicle.need_thrusters("designing an excitation").names,
                    units=("m or rad", "m/s or rad/s", "m/s² or rad/s²", "N"))
