"""A simple per-DOF velocity PI controller with optional model feed-forward.

τ = m_ii (k_p e + k_i ∫e) + τ_ff,   e = ν_ref − ν,

with m_ii the diagonal of M so that the gains are bandwidths (1/s, 1/s²) in every DOF. The
integral is clamped (anti-windup) and the output saturated to what the thrusters can give.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.vehicle import Vehicle

FloatArray = NDArray[np.float64]

#: Closed-loop bandwidth (rad/s) of the example controller (controller_node, demo).
DEFAULT_BANDWIDTH = 1.5


class VelocityPI:
    """Per-DOF PI velocity controller.

    Parameters
    ----------
    mass_diag : ndarray, shape (6,)
        Diagonal of M (kg, kg·m²): scales the gains into forces.
    tau_max : ndarray, shape (6,)
        Output saturation per DOF (N, N·m).
    bandwidth : float or ndarray, shape (6,)
        Closed-loop bandwidth ω (rad/s); k_p = 2ω, k_i = ω².
    feedforward : callable, optional
        ν ↦ τ_ff (6,), e.g. the model's D(ν)ν + C(ν)ν.
    """

    def __init__(self, mass_diag: FloatArray, tau_max: FloatArray,
                 bandwidth: float | FloatArray = 2.0,
                 feedforward: Callable[[FloatArray], FloatArray] | None = None) -> None:
        self.m = np.asarray(mass_diag, dtype=float)
        self.tau_max = np.asarray(tau_max, dtype=float)
        w = np.broadcast_to(np.asarray(bandwidth, dtype=float), (6,))
        self.kp = 2.0 * w
        self.ki = w * w
        self.feedforward = feedforward
        self.integral = np.zeros(6)

    @classmethod
    def for_vehicle(cls, vehicle: Vehicle, bandwidth: float | FloatArray = DEFAULT_BANDWIDTH,
                    feedforward: Callable[[FloatArray], FloatArray] | None = None
                    ) -> VelocityPI:
        """The PI of a vehicle: gains scaled by the diagonal of its M, output limited to 90 %
        of what its thrusters can give in each DOF."""
        thrusters = vehicle.need_thrusters("the velocity controller (its output limits)")
        return cls(np.diag(vehicle.body.M), 0.9 * thrusters.max_wrench, bandwidth, feedforward)

    def reset(self) -> None:
        """Clear the integral state."""
        self.integral[:] = 0.0

    def __call__(self, nu_ref: FloatArray, nu: FloatArray, dt: float) -> FloatArray:
        """Control wrench τ (6,) for reference and measured velocity over step dt (s)."""
        e = np.asarray(nu_ref) - np.asarray(nu)
        # ∫e with anti-windup: the integral alone never asks for more than tau_max
        limit = self.tau_max / np.maximum(self.m * self.ki, 1e-12)
        self.integral = np.clip(self.integral + e * dt, -limit, limit)
        tau = self.m * (self.kp * e + self.ki * self.integral)
        if self.feedforward is not None:
            tau = tau + self.feedforward(np.asarray(nu_ref))
        return np.asarray(np.clip(tau, -self.tau_max, self.tau_max), dtype=float)


def tracking_rms(nu_ref: FloatArray, nu: FloatArray, dofs: Sequence[int],
                 skip: int = 0) -> float:
    """RMS of the velocity error ν_ref − ν over the given DOFs after the first ``skip`` steps.

    Parameters
    ----------
    nu_ref, nu : ndarray, shape (N, 6)
    dofs : sequence of int
        Columns (0..5 = u..r) to include.
    skip : int
        Steps left out at the start (the transient).

    Returns
    -------
    float
        m/s and rad/s mixed, as the DOFs are.
    """
    e = np.asarray(nu_ref)[skip:, list(dofs)] - np.asarray(nu)[skip:, list(dofs)]
    return float(np.sqrt(np.mean(e * e)))
