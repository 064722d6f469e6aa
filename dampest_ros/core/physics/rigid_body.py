"""Rigid-body and restoring parts of Fossen's equation: M, C(ν) and g(η).

All quantities are in Fossen's body frame (FRD) and world frame (NED); see
:mod:`dampest_ros.core.physics.frames` for the conversion to ROS frames.

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


def munk_moment(M_A: FloatArray, nu: FloatArray) -> FloatArray:
    """The Munk-moment part of C_A(ν)ν: [0, v × (M_A11 v)], shape (..., 6).

    The moment a body feels from its linear velocity alone through the translational added
    mass (Fossen 2011, §6.3.1): for a diagonal M_A, e.g. N = (Y_v̇ − X_u̇) u v.

    Parameters
    ----------
    M_A : ndarray, shape (6, 6)
    nu : ndarray, shape (..., 6)
    """
    nu = np.asarray(nu, dtype=float)
    out = np.zeros_like(nu)
    # v × (M_A11 v), on the moment rows only
    out[..., 3:] = np.cross(nu[..., :3], nu[..., :3] @ M_A[:3, :3].T)
    return out


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
class AddedMassTerms:
    """Which effects of the added mass M_A act on the vehicle (all by default).

    Real plants differ here: gz-sim has ``disable_added_mass`` and ``disable_coriolis``,
    MuJoCo's fluid model applies the velocity terms of added mass but not M_A ν̇, and many
    AUV models drop the Munk moments.

    Attributes
    ----------
    inertial : bool
        M_A ν̇ acts (the added mass resists acceleration).
    coriolis : bool
        C_A(ν)ν acts (Fossen 2011, eq. 6.49), Munk moments included unless ``munk`` is off.
    munk : bool
        The Munk-moment part of C_A(ν)ν, v × (M_A11 v), acts; needs ``coriolis``.
    """

    inertial: bool = True
    coriolis: bool = True
    munk: bool = True

    def __post_init__(self) -> None:
        if self.munk and not self.coriolis:
            raise ConfigError("added_mass_terms", "munk: true needs coriolis: true (the Munk "
                              "moments are entries of C_A); set munk: false")

    @classmethod
    def from_dict(cls, d: Any) -> AddedMassTerms:
        """From ``{inertial: true, coriolis: true, munk: true}`` (missing keys: true)."""
        if not isinstance(d, dict):
            raise ConfigError("added_mass_terms", f"must be a mapping, got {d!r}")
        unknown = set(d) - {"inertial", "coriolis", "munk"}
        if unknown:
            raise ConfigError("added_mass_terms", f"unknown key(s) {sorted(unknown)}; known: "
                              "inertial, coriolis, munk")
        for k, v in d.items():
            if not isinstance(v, bool):
                raise ConfigError(f"added_mass_terms.{k}", f"must be true or false, got {v!r}")
        return cls(**d)

    def as_dict(self) -> dict[str, bool]:
        """``{inertial, coriolis, munk}``."""
        return {"inertial": self.inertial, "coriolis": self.coriolis, "munk": self.munk}

    @property
    def all(self) -> bool:
        """Every effect acts (Fossen's full model)."""
        return self.inertial and self.coriolis and self.munk


def added_coriolis_force(M_A: FloatArray, terms: AddedMassTerms,
                         nu_r: FloatArray) -> FloatArray:
    """The acting part of C_A(ν_r)ν_r under the switches ``coriolis`` and ``munk``.

    Parameters
    ----------
    M_A : ndarray, shape (6, 6)
        Added mass (kg, kg·m, kg·m²).
    terms : AddedMassTerms
    nu_r : ndarray, shape (..., 6)
        Velocity relative to the water (m/s, rad/s).

    Returns
    -------
    ndarray, shape (..., 6)
        C_A(ν_r)ν_r, without its Munk moments when ``munk`` is off, zero when ``coriolis``
        is off (left-hand side, N and N·m).
    """
    if not terms.coriolis:
        return np.zeros(np.shape(nu_r))
    out = coriolis_force(M_A, nu_r)
    # without Munk moments: C_A(ν)ν − [0, v × (M_A11 v)]
    return out if terms.munk else out - munk_moment(M_A, nu_r)


def split_coriolis_force(M: FloatArray, M_A: FloatArray | None, terms: AddedMassTerms | None,
                         nu: FloatArray) -> FloatArray:
    """C_RB(ν)ν + the acting part of C_A(ν)ν from the total mass matrix and its added part.

    Parameters
    ----------
    M : ndarray, shape (6, 6)
        M_RB + M_A.
    M_A : ndarray, shape (6, 6), or None
        The added mass inside ``M``; needed only when ``terms`` turn an effect off.
    terms : AddedMassTerms or None
        None: all act (C(ν)ν of ``M`` as a whole).
    nu : ndarray, shape (..., 6)
        Body velocity, no current (m/s, rad/s).

    Returns
    -------
    ndarray, shape (..., 6)
    """
    if terms is None or terms.all:
        return coriolis_force(M, nu)
    if M_A is None:
        raise ConfigError("M_A", f"added-mass switches {terms.as_dict()} need M_A to split M")
    return coriolis_force(M - M_A, nu) + added_coriolis_force(M_A, terms, nu)


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
    added_mass_terms : AddedMassTerms
        Which effects of M_A act (inertial M_A ν̇, Coriolis C_A(ν)ν, Munk moments).
    """

    mass: float
    inertia: FloatArray
    r_g: FloatArray = field(default_factory=lambda: np.zeros(3))
    r_b: FloatArray = field(default_factory=lambda: np.zeros(3))
    volume: float = 0.0
    added_mass: FloatArray = field(default_factory=lambda: np.zeros((6, 6)))
    rho: float = 1025.0
    gravity: float = 9.81
    added_mass_terms: AddedMassTerms = field(default_factory=AddedMassTerms)

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
    def M_inertial(self) -> FloatArray:
        """The matrix that multiplies ν̇ in the plant: M_RB + M_A, or M_RB alone when the
        inertial added-mass effect is off, shape (6, 6)."""
        return self.M if self.added_mass_terms.inertial else self.M_RB

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
            return split_coriolis_force(self.M, self.added_mass, self.added_mass_terms, nu)
        return coriolis_force(self.M_RB, nu) + self.added_coriolis_force(nu_r)

    def added_coriolis_force(self, nu_r: FloatArray) -> FloatArray:
        """The acting part of C_A(ν_r)ν_r (switches ``coriolis`` and ``munk``), shape (..., 6).
        """
        return added_coriolis_force(self.added_mass, self.added_mass_terms, nu_r)

    def added_mass_force(self, nu: FloatArray, nu_dot: FloatArray) -> FloatArray:
        """Everything the added mass does to the vehicle, as it acts: M_A ν̇ (if inertial)
        plus the acting part of C_A(ν)ν, shape (..., 6) (left-hand side, N and N·m)."""
        out = self.added_coriolis_force(nu)
        if self.added_mass_terms.inertial:
            out = out + np.asarray(nu_dot, dtype=float) @ self.added_mass.T
        return out

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
        terms = AddedMassTerms.from_dict(d.get("added_mass_terms", {}))
        added = _diag_or_full("added_mass", d.get("added_mass", [0.0] * 6), 6)
        if "added_mass_terms" in d and not np.any(added):
            acting = [k for k, v in terms.as_dict().items() if v]
            if acting:
                raise ConfigError("added_mass_terms", f"{', '.join(acting)} set true but "
                                  "added_mass is zero or missing; give added_mass or set them "
                                  "false")
        return cls(
            mass=mass,
            inertia=inertia,
            r_g=np.asarray(d.get("r_g", [0.0, 0.0, 0.0]), dtype=float),
            r_b=np.asarray(d.get("r_b", [0.0, 0.0, 0.0]), dtype=float),
            volume=float(d.get("volume", mass / float(d.get("rho", 1025.0)))),
            added_mass=added,
            rho=float(d.get("rho", 1025.0)),
            gravity=float(d.get("gravity", 9.81)),
            added_mass_terms=terms,
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
