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

from dampest_ros.core.physics.frames import cross

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
    out[..., 3:] = cross(nu[..., :3], nu[..., :3] @ M_A[:3, :3].T)
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
    out[..., :3] = cross(nu[..., 3:], a[..., :3])
    out[..., 3:] = cross(nu[..., :3], a[..., :3]) + cross(nu[..., 3:], a[..., 3:])
    return out


#: The entries (row, column) of Fossen's C_A(ν) (2011, eq. 6.49) that are not identically
#: zero: the off-diagonal entries of its blocks −S(a1) (rows X, Y, Z ← columns p, q, r and
#: rows K, M, N ← columns u, v, w) and −S(a2) (K, M, N ← p, q, r), a = M_A ν; 18 entries.
CA_ENTRIES: frozenset[tuple[int, int]] = frozenset(
    (i, j) for i in range(6) for j in range(6) if (i >= 3 or j >= 3) and i % 3 != j % 3)

#: The entries of C_A(ν) that carry the Munk moment: rows K, M, N ← columns u, v, w, i.e.
#: (K,v) (K,w) (M,u) (M,w) (N,u) (N,v) = (3,1) (3,2) (4,0) (4,2) (5,0) (5,1). Their force is
#: v × (A11 v + A12 ω): exactly the Munk moment v × (A11 v) when A12 = 0 (a body with three
#: planes of symmetry); with A12 ≠ 0 they carry v × (A12 ω) too.
MUNK_ENTRIES: frozenset[tuple[int, int]] = frozenset(
    (i, j) for (i, j) in CA_ENTRIES if i >= 3 and j < 3)


def entry_name(entry: tuple[int, int]) -> str:
    """``(0, 4)`` → ``"(X, q)"``: the force row and the velocity column of a C_A entry."""
    return f"({FORCE_NAMES[entry[0]]}, {DOF_NAMES[entry[1]]})"


@dataclass(frozen=True)
class AddedMassTerms:
    """Which effects of the added mass M_A act on the vehicle (all by default).

    Real plants differ here: gz-sim has ``disable_added_mass`` and ``disable_coriolis``,
    MuJoCo's fluid model applies the velocity terms of added mass but not M_A ν̇, many AUV
    models drop the Munk moments and some zero single entries of C_A(ν).

    The Coriolis part is one representation, the set of zeroed entries of the 6×6 C_A(ν)
    (:attr:`zeroed`, :data:`CA_ENTRIES`); ``coriolis`` and ``munk`` are shorthands for all of
    them and for :data:`MUNK_ENTRIES`. The fields are kept canonical: ``coriolis_zero`` holds
    only the zeroed entries the shorthands do not say, so equal masks compare equal.

    Attributes
    ----------
    inertial : bool
        M_A ν̇ acts (the added mass resists acceleration).
    coriolis : bool
        C_A(ν)ν acts (Fossen 2011, eq. 6.49), in the entries not zeroed otherwise.
    munk : bool
        The Munk entries of C_A(ν) (:data:`MUNK_ENTRIES`) act; needs ``coriolis``.
    coriolis_zero : tuple of (int, int)
        Further zeroed entries (row = force index 0–5 X…N, column = velocity index 0–5
        u…r), each one of :data:`CA_ENTRIES`.
    """

    inertial: bool = True
    coriolis: bool = True
    munk: bool = True
    coriolis_zero: tuple[tuple[int, int], ...] = ()

    def __post_init__(self) -> None:
        if self.munk and not self.coriolis:
            raise ConfigError("added_mass_terms", "munk: true needs coriolis: true (the Munk "
                              "moments are entries of C_A); set munk: false")
        listed = frozenset((int(i), int(j)) for i, j in self.coriolis_zero)
        if listed and not self.coriolis:
            raise ConfigError("added_mass_terms.coriolis_zero", "coriolis: false already "
                              "zeroes every entry of C_A; drop coriolis_zero or coriolis")
        if listed - CA_ENTRIES:
            e = min(listed - CA_ENTRIES)
            raise ConfigError("added_mass_terms.coriolis_zero",
                              f"entry {entry_name(e)} = {list(e)} is zero in C_A(ν) whatever "
                              f"M_A; nonzero entries of row {FORCE_NAMES[e[0]]}: "
                              + ", ".join(DOF_NAMES[j] for i, j in sorted(CA_ENTRIES)
                                          if i == e[0]))
        zeroed = listed | (frozenset() if self.munk else MUNK_ENTRIES)
        zeroed |= frozenset() if self.coriolis else CA_ENTRIES
        munk = not MUNK_ENTRIES <= zeroed
        coriolis = zeroed != CA_ENTRIES
        object.__setattr__(self, "coriolis", coriolis)
        object.__setattr__(self, "munk", munk)
        extra = zeroed - (frozenset() if munk else MUNK_ENTRIES) if coriolis else frozenset()
        object.__setattr__(self, "coriolis_zero", tuple(sorted(extra)))

    @property
    def zeroed(self) -> frozenset[tuple[int, int]]:
        """Every zeroed entry of C_A(ν), shorthands included (the one representation)."""
        if not self.coriolis:
            return CA_ENTRIES
        return frozenset(self.coriolis_zero) | (frozenset() if self.munk else MUNK_ENTRIES)

    @property
    def mask(self) -> FloatArray:
        """C_A(ν)'s acting entries, shape (6, 6): 0 where zeroed, 1 elsewhere (the plant
        applies mask ⊙ C_A(ν))."""
        out = np.ones((6, 6))
        for e in self.zeroed:
            out[e] = 0.0
        return out

    @classmethod
    def from_dict(cls, d: Any) -> AddedMassTerms:
        """From ``{inertial, coriolis, munk: bool, coriolis_zero: [[X, q], …],
        coriolis_mask: [36 × 0/1]}`` (missing switches: true; see :func:`_parse_entries`)."""
        if not isinstance(d, dict):
            raise ConfigError("added_mass_terms", f"must be a mapping, got {d!r}")
        unknown = set(d) - {"inertial", "coriolis", "munk", "coriolis_zero", "coriolis_mask"}
        if unknown:
            raise ConfigError("added_mass_terms", f"unknown key(s) {sorted(unknown)}; known: "
                              "inertial, coriolis, munk, coriolis_zero, coriolis_mask")
        switches = {k: v for k, v in d.items() if k in ("inertial", "coriolis", "munk")}
        for k, v in switches.items():
            if not isinstance(v, bool):
                raise ConfigError(f"added_mass_terms.{k}", f"must be true or false, got {v!r}")
        zero = _parse_entries(d.get("coriolis_zero", []))
        if "coriolis_mask" in d:
            zero |= _parse_mask(d["coriolis_mask"])
        return cls(**switches, coriolis_zero=tuple(sorted(zero)))

    def as_dict(self) -> dict[str, Any]:
        """``{inertial, coriolis, munk}``, with ``coriolis_zero: [[X, q], …]`` (names) when
        entries beyond the shorthands are zeroed."""
        out: dict[str, Any] = {"inertial": self.inertial, "coriolis": self.coriolis,
                               "munk": self.munk}
        if self.coriolis_zero:
            out["coriolis_zero"] = [[FORCE_NAMES[i], DOF_NAMES[j]]
                                    for i, j in self.coriolis_zero]
        return out

    def as_parameters(self) -> dict[str, Any]:
        """The model file's form (ROS parameter values): :meth:`as_dict` with
        ``coriolis_zero`` replaced by ``coriolis_mask``, 36 ints row-major, 1 = the entry of
        C_A(ν) acts (a controller applies mask ⊙ C_A(ν))."""
        out = self.as_dict()
        if out.pop("coriolis_zero", None) is not None:
            out["coriolis_mask"] = self.mask.astype(int).reshape(36).tolist()
        return out

    @property
    def all(self) -> bool:
        """Every effect acts (Fossen's full model)."""
        return self.inertial and not self.zeroed

    def off_text(self) -> str:
        """What does not act, for messages: e.g. ``"munk, C_A entries (X, q) (Z, q)"``."""
        off = [k for k in ("inertial", "coriolis", "munk") if not getattr(self, k)]
        if self.coriolis_zero:
            off.append("C_A entries " + " ".join(entry_name(e) for e in self.coriolis_zero))
        return ", ".join(off)


def _parse_entries(v: Any) -> set[tuple[int, int]]:
    """``coriolis_zero``: a list of [row, column] pairs; a row is a force name X Y Z K M N or
    its index 0–5, a column a velocity name u v w p q r or its index 0–5."""
    key = "added_mass_terms.coriolis_zero"
    if not isinstance(v, list):
        raise ConfigError(key, f"must be a list of [row, column] pairs like [[X, q], [Z, q]], "
                               f"got {v!r}")
    out: set[tuple[int, int]] = set()
    for k, pair in enumerate(v):
        if not (isinstance(pair, list) and len(pair) == 2):
            raise ConfigError(f"{key}[{k}]", f"must be a [row, column] pair like [X, q] or "
                                              f"[0, 4], got {pair!r}")
        entry = (_axis(f"{key}[{k}]", pair[0], FORCE_NAMES, "row"),
                 _axis(f"{key}[{k}]", pair[1], DOF_NAMES, "column"))
        if entry in out:
            raise ConfigError(f"{key}[{k}]", f"{entry_name(entry)} is listed twice")
        out.add(entry)
    return out


def _axis(key: str, v: Any, names: tuple[str, ...], what: str) -> int:
    """A row or column of C_A given as a name of ``names`` or its index 0–5."""
    if isinstance(v, str) and v in names:
        return names.index(v)
    if isinstance(v, int) and not isinstance(v, bool) and 0 <= v < 6:
        return v
    raise ConfigError(key, f"{what} {v!r} is neither one of {' '.join(names)} nor an index "
                           "0-5")


def _parse_mask(v: Any) -> set[tuple[int, int]]:
    """``coriolis_mask``: 36 numbers 0 or 1, row-major; the zeroed entries of C_A it names."""
    key = "added_mass_terms.coriolis_mask"
    ok = isinstance(v, list) and len(v) == 36 and all(
        not isinstance(x, bool) and isinstance(x, int) and x in (0, 1) for x in v)
    if not ok:
        got = f"{len(v)} items" if isinstance(v, list) and len(v) != 36 else repr(v)
        raise ConfigError(key, "must be 36 integers 0 or 1, row-major (1: the entry of "
                               f"C_A(ν) acts), got {got}")
    return {e for e in CA_ENTRIES if v[6 * e[0] + e[1]] == 0}


def added_coriolis_force(M_A: FloatArray, terms: AddedMassTerms,
                         nu_r: FloatArray) -> FloatArray:
    """The acting part of C_A(ν_r)ν_r: the entries of C_A not in ``terms.zeroed``.

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
        (mask ⊙ C_A(ν_r)) ν_r (left-hand side, N and N·m): zero when ``coriolis`` is off.
    """
    if not terms.coriolis:
        return np.zeros(np.shape(nu_r))
    if not terms.coriolis_zero and (terms.munk or not np.any(M_A[:3, 3:])):
        out = coriolis_force(M_A, nu_r)
        # A12 = 0: the Munk entries' force is exactly v × (A11 v)
        return out if terms.munk else out - munk_moment(M_A, nu_r)
    nu_r = np.asarray(nu_r, dtype=float)
    C = coriolis_matrix(M_A, nu_r) * terms.mask
    return np.asarray(np.einsum("...ij,...j->...i", C, nu_r))


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
            acting = [k for k in ("inertial", "coriolis", "munk") if getattr(terms, k)]
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
