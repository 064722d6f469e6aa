"""Scalar functions α(ν) of the body velocity (FRD, relative to the water) that multiply a
damping parameter's basis matrix: :class:`Alpha` (one, parsed from its text, e.g. ``|r|``,
``k^2/|U|``) and :class:`AlphaBank` (many, evaluated together, vectorised over samples)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.frames import cross
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, ConfigError

FloatArray = NDArray[np.float64]


def dof_index(name: str | int, what: str = "dof") -> int:
    """Index 0..5 of a velocity letter (u..r), a force letter (X..N) or an int."""
    if isinstance(name, int) and 0 <= name < 6:
        return name
    if isinstance(name, str):
        if name in DOF_NAMES:
            return DOF_NAMES.index(name)
        if name in FORCE_NAMES:
            return FORCE_NAMES.index(name)
    raise ConfigError(what, f"unknown degree of freedom {name!r}; use one of {DOF_NAMES}")


@dataclass(frozen=True)
class Alpha:
    """A scalar function α(ν) of the body velocity, from a small library.

    kinds: ``one`` (1), ``abs`` (|ν_i|), ``lin`` (ν_i), ``norm`` (‖[u, v, w]‖, m/s),
    ``anorm`` (‖[p, q, r]‖, rad/s), ``pnorm`` (‖[ν_i, ν_j]‖, the cross-flow speed of a body
    slender along the third axis), ``area`` (ν_i² / ‖v‖ for a linear ν_i, ν_i² / ‖ω‖ for an
    angular one; with j ≥ 0 the pair (ν_i² + ν_j²) / ‖·‖, both linear or both angular, the
    cross-flow share of a body of revolution about the third axis; 0 at rest), ``prod``
    (ν_i ν_j), ``absprod`` (|ν_i ν_j|), ``absproj`` (|wᵀν| for a 6-vector w), ``pspeed``
    (‖v + ω × r‖, the speed through the water of the point r = ``w`` (3 floats, m, FRD) of the
    body: an element's local speed, m/s), ``pshare`` ((eᵀv_p)² / ‖v_p‖, v_p = v + ω × r at the
    point r = ``w[:3]``, e = ``w[3:]`` a unit direction in the body frame: the share of the
    element's speed along e, weighted by it, m/s; 0 at rest).
    """

    kind: str = "one"
    i: int = -1
    j: int = -1
    w: tuple[float, ...] = ()

    def __call__(self, nu: FloatArray) -> FloatArray:
        """Evaluate on samples ``nu`` of shape (N, 6); returns shape (N,)."""
        k = self.kind
        if k == "one":
            return np.ones(nu.shape[0])
        if k == "abs":
            return np.abs(nu[:, self.i])
        if k == "lin":
            return nu[:, self.i].copy()
        if k == "norm":
            return np.sqrt(np.einsum("ni,ni->n", nu[:, :3], nu[:, :3]))
        if k == "anorm":
            return np.sqrt(np.einsum("ni,ni->n", nu[:, 3:], nu[:, 3:]))
        if k == "pnorm":
            return np.hypot(nu[:, self.i], nu[:, self.j])
        if k == "area":
            return _area(nu, np.array([self.i]), np.array([self.j]))[:, 0]
        if k == "prod":
            return nu[:, self.i] * nu[:, self.j]
        if k == "absprod":
            return np.abs(nu[:, self.i] * nu[:, self.j])
        if k == "absproj":
            return np.abs(nu @ np.asarray(self.w))
        if k == "pspeed":
            return point_speeds(nu, np.array([self.w]))[:, 0]
        if k == "pshare":
            return point_shares(nu, np.array([self.w[:3]]), np.array([self.w[3:]]))[:, 0]
        raise ConfigError("alpha", f"unknown kind {k!r}")

    @property
    def reads(self) -> frozenset[int]:
        """The components of ν (0..5) α is a function of."""
        k = self.kind
        if k in ("abs", "lin"):
            return frozenset([self.i])
        if k in ("prod", "absprod", "pnorm"):
            return frozenset([self.i, self.j])
        if k == "area":
            # ν_i² (+ ν_j²) over the norm of ν_i's group
            return frozenset([*range(3 * (self.i >= 3), 3 * (self.i >= 3) + 3), self.i,
                              *([self.j] if 0 <= self.j < 6 else [])])
        if k == "norm":
            return frozenset(range(3))
        if k == "anorm":
            return frozenset(range(3, 6))
        if k == "absproj":
            return frozenset(int(i) for i in np.flatnonzero(np.asarray(self.w)))
        if k in ("pspeed", "pshare"):
            return frozenset(range(6))  # v + ω × r
        return frozenset()

    def scale(self, nu_scale: FloatArray) -> float:
        """Factor c with α(ν_s ⊙ ν') = c α(ν') for velocity scales ν_s, shape (6,).

        Exact for ``one, abs, lin, prod, absprod``; for ``norm`` and ``absproj`` exact when
        the velocities inside α share one scale (the largest is used).
        """
        s = np.asarray(nu_scale, dtype=float)
        k = self.kind
        if k == "one":
            return 1.0
        if k in ("abs", "lin"):
            return float(s[self.i])
        if k in ("prod", "absprod"):
            return float(s[self.i] * s[self.j])
        if k == "pnorm":
            return float(max(s[self.i], s[self.j]))
        if k == "area":
            top = max(s[self.i], s[self.j]) if self.j >= 0 else s[self.i]
            return float(top ** 2 / (s[:3].max() if self.i < 3 else s[3:].max()))
        if k == "norm":
            return float(s[:3].max())
        if k == "anorm":
            return float(s[3:].max())
        if k == "absproj":
            return float(s[np.abs(np.asarray(self.w)) > 0].max())
        if k in ("pspeed", "pshare"):
            return float(max(s[:3].max(), s[3:].max() * np.linalg.norm(self.w[:3])))
        raise ConfigError("alpha", f"unknown kind {k!r}")

    def label(self) -> str:
        """Short text form, e.g. ``|r|``, ``u``, ``|U|`` (‖v‖), ``|W|`` (‖ω‖)."""
        n = DOF_NAMES
        return {
            "one": "1",
            "abs": f"|{n[self.i]}|" if self.i >= 0 else "",
            "lin": n[self.i] if self.i >= 0 else "",
            "norm": "|U|",
            "anorm": "|W|",
            "pnorm": f"|{n[self.i]},{n[self.j]}|" if self.i >= 0 else "",
            "area": (f"|{n[self.i]},{n[self.j]}|" if self.j >= 0 else n[self.i]) +
                    f"^2/{'|U|' if self.i < 3 else '|W|'}" if self.i >= 0 else "",
            "prod": f"{n[self.i]}{n[self.j]}" if self.i >= 0 else "",
            "absprod": f"|{n[self.i]}{n[self.j]}|" if self.i >= 0 else "",
            "absproj": "|w'nu|",
            "pspeed": "|v+w x r|",
            "pshare": "e_p^2/|v+w x r|",
        }[self.kind]

    @classmethod
    def parse(cls, text: str) -> Alpha:
        """Parse ``1``, ``|r|``, ``u``, ``|U|`` (‖v‖), ``|W|`` (‖ω‖), ``|v,w|`` (‖(v, w)‖),
        ``v^2/|U|``, ``|v,w|^2/|U|`` ((v² + w²) / ‖v‖), ``uv``, ``|uv|``."""
        t = text.replace(" ", "")
        if t in ("1", "", "one"):
            return cls("one")
        if t in ("|U|", "norm"):
            return cls("norm")
        if t in ("|W|", "anorm"):
            return cls("anorm")
        if t.endswith(("^2/|U|", "^2/|W|")):
            idx = [dof_index(c, "alpha") for c in t[:-6].strip("|").split(",")]
            if len(idx) > 2 or any((i < 3) != t.endswith("|U|") for i in idx):
                raise ConfigError("alpha", f"{text!r}: a linear velocity goes over |U|, an "
                                  "angular one over |W|")
            return cls("area", idx[0], idx[1] if len(idx) == 2 else -1)
        if "," in t and t.startswith("|") and t.endswith("|"):
            pair = [dof_index(c, "alpha") for c in t.strip("|").split(",")]
            if len(pair) == 2:
                return cls("pnorm", pair[0], pair[1])
        bars = t.startswith("|") and t.endswith("|")
        core = t.strip("|")
        idx = [dof_index(c, "alpha") for c in core]
        if len(idx) == 1:
            return cls("abs" if bars else "lin", idx[0])
        if len(idx) == 2:
            return cls("absprod" if bars else "prod", idx[0], idx[1])
        raise ConfigError("alpha", f"cannot parse {text!r}")


class AlphaBank:
    """All α_j of a list of bases evaluated at once: a fixed number of array operations
    whatever p is, so the per-sample cost in the simulator and the RLS stays small.

    Parameters
    ----------
    alphas : sequence of Alpha
    """

    _ONE = 6  # index of the constant column appended to ν

    def __init__(self, alphas: Sequence[Alpha]) -> None:
        p = len(alphas)
        self.i = np.full(p, self._ONE)
        self.j = np.full(p, self._ONE)
        for k, a in enumerate(alphas):
            if a.kind in ("abs", "lin", "prod", "absprod", "pnorm", "area"):
                self.i[k] = a.i
            if a.kind in ("prod", "absprod", "pnorm") or (a.kind == "area" and a.j >= 0):
                self.j[k] = a.j

        def columns(*kinds: str) -> NDArray[np.int64]:
            return np.array([k for k, a in enumerate(alphas) if a.kind in kinds],
                            dtype=np.int64)

        # the columns of each kind that is not a product ν_i ν_j (with ν_6 ≡ 1)
        self.pnorm, self.area, self.proj = columns("pnorm"), columns("area"), columns("absproj")
        self.norm, self.anorm, self.pspeed = columns("norm"), columns("anorm"), columns("pspeed")
        self.pshare = columns("pshare")
        self.absolute = columns("abs", "absprod", "absproj")
        self.W = np.array([alphas[k].w for k in self.proj], dtype=float).reshape(-1, 6).T
        self.points = np.array([alphas[k].w for k in self.pspeed], dtype=float).reshape(-1, 3)
        shares = np.array([alphas[k].w for k in self.pshare], dtype=float).reshape(-1, 6)
        self.share_points, self.share_directions = shares[:, :3], shares[:, 3:]
        # the bank is a list of products (kinds one, lin, abs, prod, absprod) unless it holds
        # a norm, an area, a projection or a point's speed: then one sample goes through
        # __call__ as well
        special = (self.pnorm, self.area, self.proj, self.norm, self.anorm, self.pspeed,
                   self.pshare)
        self._products = None if any(len(k) for k in special) else list(
            zip(self.i.tolist(), self.j.tolist(),
                np.isin(np.arange(p), self.absolute).tolist(), strict=True))

    def __call__(self, nu: FloatArray) -> FloatArray:
        """α for samples ``nu`` (N, 6); returns (N, p)."""
        return np.ascontiguousarray(self.rows(nu).T)

    def rows(self, nu: FloatArray) -> FloatArray:
        """α for samples ``nu`` (N, 6) by function: shape (p, N), α_k(ν) in row k."""
        # ν by component (rows), ν_6 ≡ 1 appended: a column of α is a product of two rows, and
        # α is formed column by column (Fortran order), each kind writing its own columns
        aug = np.concatenate([nu.T, np.ones((1, nu.shape[0]))])
        # products ν_i ν_j cover the kinds one, lin and prod; the other kinds overwrite
        a = (aug[self.i] * aug[self.j]).T
        if len(k := self.pnorm):
            a[:, k] = np.hypot(aug[self.i[k]], aug[self.j[k]]).T
        if len(k := self.area):
            a[:, k] = _area(nu, self.i[k], self.j[k])
        if len(k := self.proj):
            a[:, k] = nu @ self.W
        if len(k := self.norm):
            a[:, k] = np.sqrt(np.einsum("ni,ni->n", nu[:, :3], nu[:, :3]))[:, None]
        if len(k := self.anorm):
            a[:, k] = np.sqrt(np.einsum("ni,ni->n", nu[:, 3:], nu[:, 3:]))[:, None]
        if len(k := self.pspeed):
            a[:, k] = point_speeds(nu, self.points)
        if len(k := self.pshare):
            a[:, k] = point_shares(nu, self.share_points, self.share_directions)
        if len(k := self.absolute):
            a[:, k] = np.abs(a[:, k])
        return np.asarray(a.T)

    def one(self, nu: list[float]) -> FloatArray:
        """α for one sample ``nu`` (6 floats); shape (p,), the same numbers as ``__call__``.

        A bank of products is evaluated on Python floats (a simulator calls this four times
        per step: numpy's per-call overhead would dominate).
        """
        if self._products is None:
            return self(np.array([nu]))[0]
        aug = [*nu, 1.0]  # ν_6 ≡ 1, as in __call__
        return np.array([abs(aug[i] * aug[j]) if a else aug[i] * aug[j]
                         for i, j, a in self._products])


def _area(nu: FloatArray, k: NDArray[np.int64], pair: NDArray[np.int64]) -> FloatArray:
    """ν_k² / ‖v‖ for linear k, ν_k² / ‖ω‖ for angular k, plus ν_l² / ‖·‖ where the
    ``pair`` index l is a velocity (0..5; none otherwise); 0 at rest, shape (N, len(k))."""
    square = nu[:, k] ** 2
    second = (pair >= 0) & (pair < 6)
    square[:, second] += nu[:, pair[second]] ** 2
    lin = np.sqrt(np.einsum("ni,ni->n", nu[:, :3], nu[:, :3]))
    ang = np.sqrt(np.einsum("ni,ni->n", nu[:, 3:], nu[:, 3:]))
    norm = np.where(k < 3, lin[:, None], ang[:, None])
    # ν_k² / ‖·‖ (≤ ‖·‖, so it goes to 0 with the speed)
    return np.divide(square, norm, out=np.zeros_like(norm), where=norm > 0)


def point_speeds(nu: FloatArray, points: FloatArray) -> FloatArray:
    """‖v + ω × r‖ of each point r of the body: its speed through the water.

    Parameters
    ----------
    nu : ndarray, shape (N, 6)
        Body velocity (m/s, rad/s), FRD.
    points : ndarray, shape (P, 3)
        Positions r in the body frame (m), FRD.

    Returns
    -------
    ndarray, shape (N, P)
        m/s.
    """
    return _speeds(point_velocities(nu, points))


def _speeds(vp: FloatArray) -> FloatArray:
    """‖v_p‖ of point velocities ``vp``, shape (N, P, 3) → (N, P)."""
    return np.sqrt(np.einsum("npi,npi->np", vp, vp))


def point_velocities(nu: FloatArray, points: FloatArray) -> FloatArray:
    """v_p = v + ω × r of each point r of the body, shape (N, P, 3) (m/s, FRD), for ``nu``
    (N, 6) and ``points`` (P, 3) as in :func:`point_speeds`."""
    # v_p = v + ω × r per sample and point
    return nu[:, None, :3] + cross(nu[:, None, 3:], points[None, :, :])


def point_shares(nu: FloatArray, points: FloatArray, directions: FloatArray) -> FloatArray:
    """(eᵀv_p)² / ‖v_p‖ of each point r of the body along its direction e: the part of the
    element's speed along e, weighted by it (0 at rest).

    Parameters
    ----------
    nu : ndarray, shape (N, 6)
        Body velocity (m/s, rad/s), FRD.
    points : ndarray, shape (P, 3)
        Positions r in the body frame (m), FRD.
    directions : ndarray, shape (P, 3)
        The unit direction e of each point in the body frame (a body axis or any other).

    Returns
    -------
    ndarray, shape (N, P)
        m/s.
    """
    vp = point_velocities(nu, points)
    speed = _speeds(vp)
    # eᵀv_p per sample and point (exactly v_p,a for a body axis e_a)
    along = np.einsum("npi,pi->np", vp, directions)
    # (eᵀv_p)² / ‖v_p‖ (≤ ‖v_p‖, so it goes to 0 with the speed)
    return np.divide(along ** 2, speed, out=np.zeros_like(speed), where=speed > 0)
