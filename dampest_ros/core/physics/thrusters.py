"""Thrusters: thrust curve T(n) = k_T ρ D⁴ n|n|, dead-zone, motor lag and allocation.

Positions and directions are in the FRD body frame. Rotor speed n is in rev/s internally;
ROS JointState carries it in rad/s (2πn).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.rigid_body import ConfigError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Thrusters:
    """A set of identical fixed thrusters.

    Parameters
    ----------
    names : tuple of str
        One name per thruster (JointState names).
    positions : ndarray, shape (n, 3)
        Thruster locations in the body frame (m).
    directions : ndarray, shape (n, 3)
        Unit thrust directions in the body frame for positive n.
    k_t : float
        Thrust coefficient k_T (dimensionless).
    diameter : float
        Propeller diameter D (m).
    rho : float
        Water density used by the thrust curve (kg/m³).
    n_max : float
        Saturation of rotor speed (rev/s).
    time_constant : float
        First-order motor lag (s); 0 means none.
    deadzone : float
        |n| below this gives no thrust (rev/s).
    """

    names: tuple[str, ...]
    positions: FloatArray
    directions: FloatArray
    k_t: float = 0.45
    diameter: float = 0.076
    rho: float = 1000.0
    n_max: float = 58.0
    time_constant: float = 0.05
    deadzone: float = 0.0

    def __post_init__(self) -> None:
        n = len(self.names)
        pos = np.asarray(self.positions, dtype=float)
        dirs = np.asarray(self.directions, dtype=float)
        if n == 0:
            raise ConfigError("thrusters", "at least one thruster is needed")
        if pos.shape != (n, 3) or not np.all(np.isfinite(pos)):
            raise ConfigError("thrusters.position", f"need {n} finite 3-vectors, got {pos.shape}")
        if dirs.shape != (n, 3) or np.any(np.linalg.norm(dirs, axis=1) < 1e-9):
            raise ConfigError("thrusters.direction", f"need {n} nonzero 3-vectors")
        for name in ("k_t", "diameter", "rho", "n_max"):
            v = getattr(self, name)
            if not np.isfinite(v) or v <= 0:
                raise ConfigError(f"thruster_model.{name}", f"must be > 0, got {v}")
        if self.time_constant < 0 or self.deadzone < 0:
            raise ConfigError("thruster_model", "time_constant and deadzone must be ≥ 0")
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "directions", dirs / np.linalg.norm(dirs, axis=1, keepdims=True))

    @property
    def count(self) -> int:
        """Number of thrusters."""
        return len(self.names)

    @cached_property
    def allocation(self) -> FloatArray:
        """Allocation matrix T_alloc (6×n): τ = T_alloc f for thrusts f (N)."""
        # column i: [d_i ; r_i × d_i]
        return np.vstack([self.directions.T, np.cross(self.positions, self.directions).T])

    @cached_property
    def allocation_pinv(self) -> FloatArray:
        """Moore–Penrose inverse T_alloc⁺ (n×6)."""
        return np.asarray(np.linalg.pinv(self.allocation), dtype=float)

    @property
    def gain(self) -> float:
        """k_T ρ D⁴ (N·s²)."""
        return self.k_t * self.rho * self.diameter**4

    def thrust(self, n: FloatArray, gain_error: float = 0.0,
               deadzone: float | None = None) -> FloatArray:
        """T(n) = (1 + gain_error) k_T ρ D⁴ n|n|, zero inside the dead-zone (N)."""
        dz = self.deadzone if deadzone is None else deadzone
        # T = k ρ D⁴ n|n|
        t = (1.0 + gain_error) * self.gain * n * np.abs(n)
        return np.where(np.abs(n) < dz, 0.0, t)

    def lag_step(self, n0: FloatArray, command: FloatArray, h: float
                 ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Rotor speeds over one step of length h with the command held (first-order lag).

        n(s) = c + (n₀ − c) e^{−s/T}, exact; without a lag (T = 0) the rotors turn at the
        command during the whole step.

        Parameters
        ----------
        n0, command : ndarray, shape (n,)
            Speeds at the start of the step and the command (rev/s).
        h : float
            Step length (s).

        Returns
        -------
        start, mid, end, mean : ndarray, shape (n,)
            n at s = 0, h/2 and h, and the mean of n over the step (rev/s).
        """
        tm = self.time_constant
        if tm <= 0:
            return command, command, command, command
        decay = np.exp(-h / tm)
        mid = lag_toward(n0, command, np.exp(-h / (2 * tm)))
        end = lag_toward(n0, command, decay)
        # mean of n over the step: c + (n₀ − c) (T/h)(1 − e^{−h/T})
        mean = command + (n0 - command) * (tm / h) * (1 - decay)
        return n0, mid, end, mean

    def step_thrust(self, start: FloatArray, mid: FloatArray, end: FloatArray,
                    gain_error: float = 0.0, deadzone: float | None = None) -> FloatArray:
        """Mean thrust over a step from the rotor speeds at its start, middle and end
        (:meth:`lag_step`), by Simpson's rule (N), shape (n,)."""
        def f(n: FloatArray) -> FloatArray:
            return self.thrust(n, gain_error, deadzone)

        # (T(n₀) + 4 T(n_mid) + T(n_end)) / 6
        return (f(start) + 4 * f(mid) + f(end)) / 6.0

    def step_means(self, n0: FloatArray, command: FloatArray, h: float
                   ) -> tuple[FloatArray, FloatArray]:
        """What a vehicle logs over steps of length h: the exact mean rotor speed (rev/s) and
        the mean nominal thrust (N, Simpson), from the speeds at the steps' starts and the
        commands held over them, shape (..., n) each (:meth:`lag_step`, :meth:`step_thrust`).
        """
        start, mid, end, mean = self.lag_step(n0, command, h)
        return mean, self.step_thrust(start, mid, end)

    def speed_for_thrust(self, thrust: FloatArray) -> FloatArray:
        """Inverse curve: n = sign(T) √(|T| / k_T ρ D⁴), saturated at ±n_max (rev/s)."""
        n = np.sign(thrust) * np.sqrt(np.abs(thrust) / self.gain)
        return np.clip(n, -self.n_max, self.n_max)

    def wrench(self, thrust: FloatArray) -> FloatArray:
        """τ = T_alloc f, shape (..., 6)."""
        return np.asarray(thrust) @ self.allocation.T

    def allocate(self, tau: FloatArray) -> FloatArray:
        """Least-norm thrusts that produce τ: f = T_alloc⁺ τ, shape (..., n)."""
        return np.asarray(tau) @ self.allocation_pinv.T

    @property
    def max_wrench(self) -> FloatArray:
        """Largest |τ_i| reachable in each DOF alone (N, N·m), shape (6,)."""
        f_max = self.gain * self.n_max**2
        return f_max * np.abs(self.allocation).sum(axis=1)

    @classmethod
    def from_dict(cls, d: dict[str, Any], rho: float) -> Thrusters:
        """From a preset: ``{model: {k_t, diameter, n_max, time_constant, deadzone},
        units: [{name, position, direction}, ...]}``."""
        units = d.get("units", [])
        model = d.get("model", {})
        try:
            return cls(
                names=tuple(str(u["name"]) for u in units),
                positions=np.array([u["position"] for u in units], dtype=float).reshape(-1, 3),
                directions=np.array([u["direction"] for u in units], dtype=float).reshape(-1, 3),
                rho=rho,
                **{k: float(v) for k, v in model.items()},
            )
        except KeyError as exc:
            raise ConfigError(f"thrusters.units.{exc.args[0]}", "missing") from None
        except TypeError as exc:
            raise ConfigError("thrusters.model", str(exc)) from None


def lag_toward(n0: FloatArray, command: FloatArray, decay: float) -> FloatArray:
    """c + (n₀ − c) e^{−s/T}: a first-order lag from n₀ toward the command c after a time s,
    given its decay e^{−s/T} (rev/s), the shape of n₀."""
    return command + (n0 - command) * decay
