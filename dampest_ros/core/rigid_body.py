"""Rigid-body and restoring parts of Fossen's equation: M, C(ν) and g(η).

All quantities are in Fossen's body frame (FRD) and world frame (NED); see
:mod:`dampest_ros.core.frames` for the conversion to ROS frames.

Functions are vectorised over leading sample axes.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

DOF_NAMES = ("u", "v", "w", "p", "q", "r")
FORCE_NAMES = ("X", "Y", "Z", "K", "M", "N")


class ConfigError(ValueError):
    """A vehicle or model configuration value is invalid; the message names the field."""

    def __init__(self, field_name: str, reason: str) -> None:
        super().__init__(f"{field_name}: {reason}")
        self.field = field_name
        self.reason = reason


def skew(a: FloatArray) -> FloatArray:
    """Skew-symmetric cross-product matrices S(a) with S(a) b = a × b.

    Parameters
    ----------
    a : ndarray, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    a = np.asarray(a, dtype=float)
    S = np.zeros((*a.shape[:-1], 3, 3))
    S[..., 0, 1], S[..., 0, 2] = -a[..., 2], a[..., 1]
    S[..., 1, 0], S[..., 1, 2] = a[..., 2], -a[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -a[..., 1], a[..., 0]
    return S


def rigid_body_mass(mass: float, inertia: FloatArray, r_g: FloatArray) -> FloatArray:
    """Rigid-body mass matrix M_RB about the body origin (Fossen 2011, eq. 3.44).

    Parameters
    ----------
    mass : float
        Vehicle mass m (kg).
    inertia : ndarray, shape (3, 3)
        Inertia tensor about the centre of gravity I_g (kg·m²).
    r_g : ndarray, shape (3,)
        Centre of gravity in the body frame (m).

    Returns
    -------
    ndarray, shape (6, 6)
    """
    S = skew(np.asarray(r_g, dtype=float))
    M = np.zeros((6, 6))
    M[:3, :3] = mass * np.eye(3)
    M[:3, 3:] = -mass * S
    M[3:, :3] = mass * S
    # I_o = I_g - m S(r_g)² (parallel-axis theorem)
    M[3:, 3:] = np.asarray(inertia, dtype=float) - mass * S @ S
    return M


def coriolis_matrix(M: FloatArray, nu: FloatArray) -> FloatArray:
    """Skew-symmetric Coriolis–centripetal matrix C(ν) built from a mass matrix.

    Uses C(ν) = [[0, -S(M11 ν1 + M12 ν2)], [-S(M11 ν1 + M12 ν2), -S(M21 ν1 + M22 ν2)]]
    (Fossen 2011, eq. 6.43 for M_RB and eq. 6.49 for M_A), valid for any symmetric M.

    Parameters
    ----------
    M : ndarray, shape (6, 6)
    nu : ndarray, shape (..., 6)
        Body velocity [u, v, w, p, q, r] (m/s, rad/s).

    Returns
    -------
    ndarray, shape (..., 6, 6)
    """
    a = np.asarray(nu, dtype=float) @ M.T
    C = np.zeros((*a.shape[:-1], 6, 6))
    S1 = skew(a[..., :3])
    C[..., :3, 3:] = -S1
    C[..., 3:, :3] = -S1
    C[..., 3:, 3:] = -skew(a[..., 3:])
    return C


def coriolis_force(M: FloatArray, nu: FloatArray) -> FloatArray:
    """C(ν)ν without forming C: [ν2 × a1, ν1 × a1 + ν2 × a2] with a = M ν.

    Parameters
    ----------
    M : ndarray, shape (6, 6)
    nu : ndarray, shape (..., 6)

    Returns
    -------
    ndarray, shape (..., 6)
    """
    nu = np.asarray(nu, dtype=float)
    a = nu @ M.T
    out = np.empty_like(a)
    out[..., :3] = np.cross(nu[..., 3:], a[..., :3])
    out[..., 3:] = np.cross(nu[..., :3], a[..., :3]) + np.cross(nu[..., 3:], a[..., 3:])
    return out


@dataclass(frozen=True)
class RigidBody:
    """Mass, inertia, added mass and restoring data of a vehicle (FRD body frame, SI units).

    Parameters
    ----------
    mass : float
        m (kg), > 0.
    inertia : ndarray, shape (3, 3)
        Inertia tensor about the CG (kg·m²), symmetric positive definite.
    r_g, r_b : ndarray, shape (3,)
        Centres of gravity and buoyancy in the body frame (m).
    volume : float
        Displaced volume ∇ (m³), ≥ 0.
    added_mass : ndarray, shape (6, 6)
        M_A, symmetric positive semi-definite (kg, kg·m, kg·m²).
    rho : float
        Water density (kg/m³).
    gravity : float
        g (m/s²).
    """

    mass: float
    inertia: FloatArray
    r_g: FloatArray = field(default_factory=lambda: np.zeros(3))
    r_b: FloatArray = field(default_factory=lambda: np.zeros(3))
    volume: float = 0.0
    added_mass: FloatArray = field(default_factory=lambda: np.zeros((6, 6)))
    rho: float = 1025.0
    gravity: float = 9.81

    def __post_init__(self) -> None:
        for name in ("mass", "rho", "gravity"):
            object.__setattr__(self, name, _check_positive(name, getattr(self, name)))
        if not np.isfinite(self.volume) or self.volume < 0:
            raise ConfigError("volume", f"must be a finite number ≥ 0, got {self.volume}")
        object.__setattr__(self, "inertia", _matrix("inertia", self.inertia, 3))
        object.__setattr__(self, "r_g", _vector("r_g", self.r_g, 3))
        object.__setattr__(self, "r_b", _vector("r_b", self.r_b, 3))
        object.__setattr__(self, "added_mass", _matrix("added_mass", self.added_mass, 6))
        _check_spd("inertia", self.inertia, strict=True)
        _check_spd("added_mass", self.added_mass, strict=False)
        _check_spd("mass matrix M_RB + M_A", self.M, strict=True)

    @property
    def M_RB(self) -> FloatArray:
        """Rigid-body mass matrix, shape (6, 6)."""
        return rigid_body_mass(self.mass, self.inertia, self.r_g)

    @property
    def M(self) -> FloatArray:
        """Total mass matrix M = M_RB + M_A, shape (6, 6)."""
        return self.M_RB + self.added_mass

    @property
    def weight(self) -> float:
        """W = m g (N)."""
        return self.mass * self.gravity

    @property
    def buoyancy(self) -> float:
        """B = ρ g ∇ (N)."""
        return self.rho * self.gravity * self.volume

    def coriolis_force(self, nu: FloatArray, nu_r: FloatArray | None = None) -> FloatArray:
        """C_RB(ν)ν + C_A(ν_r)ν_r, shape (..., 6).

        Parameters
        ----------
        nu : ndarray, shape (..., 6)
            Body velocity over ground.
        nu_r : ndarray, shape (..., 6), optional
            Velocity relative to the water (defaults to ``nu``: no current).
        """
        if nu_r is None:
            return coriolis_force(self.M, nu)
        return coriolis_force(self.M_RB, nu) + coriolis_force(self.added_mass, nu_r)

    def restoring(self, R: FloatArray) -> FloatArray:
        """Restoring forces g(η) from body-to-NED rotation matrices (Fossen 2011, eq. 4.6).

        Parameters
        ----------
        R : ndarray, shape (..., 3, 3)
            Body (FRD) to world (NED) rotation.

        Returns
        -------
        ndarray, shape (..., 6)
            g(η) as it appears on the left-hand side of M ν̇ + … + g(η) = τ.
        """
        R = np.asarray(R, dtype=float)
        down = R[..., 2, :]  # world z axis expressed in the body frame, R^T e_z
        f_g = self.weight * down  # weight, body frame
        f_b = -self.buoyancy * down  # buoyancy, body frame
        g = np.empty((*down.shape[:-1], 6))
        # g(η) = -[f_g + f_b ; r_g × f_g + r_b × f_b]
        g[..., :3] = -(f_g + f_b)
        g[..., 3:] = -(np.cross(self.r_g, f_g) + np.cross(self.r_b, f_b))
        return g

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RigidBody:
        """Build from a preset's ``vehicle`` mapping (inertia, added_mass: diagonal or full)."""
        try:
            mass = float(d["mass"])
            inertia = _diag_or_full("inertia", d["inertia"], 3)
        except KeyError as exc:
            raise ConfigError(str(exc.args[0]), "missing") from None
        return cls(
            mass=mass,
            inertia=inertia,
            r_g=np.asarray(d.get("r_g", [0.0, 0.0, 0.0]), dtype=float),
            r_b=np.asarray(d.get("r_b", [0.0, 0.0, 0.0]), dtype=float),
            volume=float(d.get("volume", mass / float(d.get("rho", 1025.0)))),
            added_mass=_diag_or_full("added_mass", d.get("added_mass", [0.0] * 6), 6),
            rho=float(d.get("rho", 1025.0)),
            gravity=float(d.get("gravity", 9.81)),
        )


def _check_positive(name: str, value: object) -> float:
    """``value`` as a float if it is a finite real number > 0 (numpy scalars included)."""
    # numbers.Real covers int, float, np.integer and np.floating; bool is rejected explicitly
    if (not isinstance(value, numbers.Real) or isinstance(value, bool)
            or not np.isfinite(float(value)) or value <= 0):
        raise ConfigError(name, f"must be a finite number > 0, got {value!r}")
    return float(value)


def _vector(name: str, v: Any, n: int) -> FloatArray:
    a = np.asarray(v, dtype=float)
    if a.shape != (n,):
        raise ConfigError(name, f"must have {n} numbers, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ConfigError(name, "contains NaN or Inf")
    return a


def _matrix(name: str, v: Any, n: int) -> FloatArray:
    a = np.asarray(v, dtype=float)
    if a.shape != (n, n):
        raise ConfigError(name, f"must be {n}x{n}, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ConfigError(name, "contains NaN or Inf")
    return a


def _diag_or_full(name: str, v: Any, n: int) -> FloatArray:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(name, f"must be numbers, got {v!r}") from None
    if a.shape == (n,):
        return np.diag(a)
    if a.shape == (n * n,):
        return a.reshape(n, n)
    return _matrix(name, a, n)


def _check_spd(name: str, A: FloatArray, strict: bool) -> None:
    if not np.allclose(A, A.T, rtol=1e-9, atol=1e-9):
        raise ConfigError(name, "must be symmetric")
    eig = np.linalg.eigvalsh(A)
    if (strict and eig.min() <= 0) or eig.min() < -1e-9 * max(1.0, float(eig.max())):
        kind = "positive definite" if strict else "positive semi-definite"
        raise ConfigError(name, f"must be {kind}; smallest eigenvalue {eig.min():.3g}")
