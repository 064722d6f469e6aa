"""Drag of an element at a point of the body: the ``point`` damping term and its candidates.

An appendage, a skid or a float off the body origin meets the water at its own velocity
v_p = v + ω × r_p (r_p its position, FRD, m), not at the body's. Its quadratic drag along one
body axis a (unit vector e_a) is a force at r_p,

    F_p = −c ‖v_p‖ v_p,a e_a       (``speed`` ``|U|``: drag on the element's speed)
    F_p = −c |v_p,a| v_p,a e_a     (``speed`` ``|a|``: a strip's normal drag on its normal speed)

with v_p,a = e_aᵀ v_p = wᵀν, w = [e_a; r_p × e_a] (6,), and it acts on the body as the wrench
w (force e_a at r_p: force along a, moment r_p × e_a): D(ν)ν = c α(ν) w wᵀ ν, α = ‖v_p‖ or
|wᵀν|. One coefficient c (N s²/m², positive when dissipative) enters the force along a and the
two moments its lever arm gives, consistently. Its power νᵀD(ν)ν = c α (wᵀν)² = c α v_p,a²
is ≥ 0 for c ≥ 0: a non-negative coefficient is dissipative (its basis w wᵀ is positive
semi-definite, :meth:`DampingTerm.project` clips it at 0).

Candidate points (:func:`candidate_points`): the positions of the vehicle file's geoms that are
off the origin (the shapes MuJoCo's fluid model applies its drag at); without a geometry, a small
generic set: ± half the length L along x, ± L/4 along y and z (the ends and flanks of a body
of about the usual proportions).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.alpha import Alpha, dof_index
from dampest_ros.core.physics.damping import Basis, DampingTerm
from dampest_ros.core.physics.geometry import Geometry
from dampest_ros.core.physics.rigid_body import DOF_NAMES, ConfigError

FloatArray = NDArray[np.float64]

#: The speeds an element's drag may go with: its speed ‖v_p‖ or its normal speed |v_p,a|.
SPEEDS = ("|U|", "normal")


@dataclass(frozen=True)
class PointSpec:
    """One element drag coefficient: where, along which axis and on which speed.

    Attributes
    ----------
    position : tuple of 3 float
        r_p in the body frame (m, FRD).
    axis : int
        0, 1, 2: the force along x, y or z (velocity letters u, v, w).
    speed : str
        ``|U|`` (‖v_p‖) or ``normal`` (|v_p,a|), :data:`SPEEDS`.
    """

    position: tuple[float, float, float]
    axis: int
    speed: str = "|U|"

    @property
    def label(self) -> str:
        """The parameter name, e.g. ``drag.w|U|@(0.3,0,0.2)``: drag along w on the element's
        speed at the point (0.3, 0, 0.2) m (``drag.ww@…``: on its normal speed |w_p|)."""
        a = DOF_NAMES[self.axis]
        where = ",".join(f"{x:.12g}" for x in self.position)
        return f"drag.{a}{'|U|' if self.speed == '|U|' else a}@({where})"

    @property
    def wrench(self) -> FloatArray:
        """w = [e_a; r_p × e_a], the body wrench of a unit force along a at r_p, shape (6,)."""
        e = np.eye(3)[self.axis]
        return np.r_[e, np.cross(np.asarray(self.position, dtype=float), e)]

    @property
    def mirror(self) -> PointSpec:
        """The same drag at the mirror image of the point across the body's xz plane
        (y → −y): its twin on the other side of a port–starboard symmetric vehicle."""
        x, y, z = self.position
        return PointSpec((x, -y + 0.0, z), self.axis, self.speed)

    def basis(self) -> Basis:
        """The parameter's basis: B = w wᵀ with α = ‖v_p‖ or |wᵀν| (module docstring)."""
        w = self.wrench
        alpha = (Alpha("pspeed", w=tuple(map(float, self.position))) if self.speed == "|U|"
                 else Alpha("absproj", w=tuple(map(float, w))))
        return Basis(self.label, np.outer(w, w), alpha)

    @classmethod
    def from_dict(cls, d: Any, where: str = "point") -> PointSpec:
        """From ``{position: [x, y, z], axis: w, speed: '|U|'}`` (speed optional)."""
        if not isinstance(d, dict) or "position" not in d or "axis" not in d:
            raise ConfigError(where, "each element is {position: [x, y, z] (m), axis: u, v "
                                     "or w, speed: '|U|' or normal}")
        pos = np.asarray(d["position"], dtype=float)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            raise ConfigError(f"{where}.position", f"three finite numbers (m), got {d['position']}")
        axis = dof_index(d["axis"], f"{where}.axis")
        if axis > 2:
            raise ConfigError(f"{where}.axis", f"{d['axis']!r}: the drag is along u, v or w")
        speed = str(d.get("speed", "|U|"))
        if speed not in SPEEDS:
            raise ConfigError(f"{where}.speed", f"{speed!r}; use one of {SPEEDS}")
        return cls((float(pos[0]), float(pos[1]), float(pos[2])), axis, speed)

    def to_dict(self) -> dict[str, Any]:
        """The mapping :meth:`from_dict` reads."""
        return {"position": list(self.position), "axis": DOF_NAMES[self.axis],
                "speed": self.speed}


def point_spec(basis: Basis) -> PointSpec:
    """The element drag a basis of the ``point`` term stands for, read from its name."""
    found = _LABEL.fullmatch(basis.name)
    if found is None:
        raise ConfigError("point", f"{basis.name!r} is not an element drag name "
                                   "(drag.<axis><speed>@(x,y,z))")
    axis, speed, where = found.groups()
    x, y, z = (float(v) for v in where.split(","))
    return PointSpec((x, y, z), DOF_NAMES.index(axis), "|U|" if speed == "|U|" else "normal")


#: The parameter names of :attr:`PointSpec.label`.
_LABEL = re.compile(r"drag\.([uvw])(\|U\||[uvw])@\(([^)]*)\)")


def point_term(specs: Sequence[PointSpec]) -> DampingTerm:
    """D_point: the drag of elements at points of the body, one coefficient each."""
    return DampingTerm("point", "quadratic drag of an element at a point r of the body, on "
                                "its own velocity v + ω × r (force and moment r × F)",
                       [s.basis() for s in specs])


def candidate_points(geometry: Geometry | None, length: float) -> list[tuple[float, ...]]:
    """Where elements may sit: the geoms off the origin, else a generic set (module
    docstring), each once, in file order.

    Parameters
    ----------
    geometry : Geometry or None
        The vehicle file's ``geometry:`` section.
    length : float
        The vehicle's reference length L (m).

    Returns
    -------
    list of tuple of 3 float
        Positions (m, FRD).
    """
    points: list[tuple[float, ...]]
    if geometry is not None:
        points = [tuple(map(float, g.position)) for g in geometry.geoms]
    else:
        half, quarter = 0.5 * length, 0.25 * length
        points = [(s * half, 0.0, 0.0) for s in (1.0, -1.0)]
        points += [(0.0, s * quarter, 0.0) for s in (1.0, -1.0)]
        points += [(0.0, 0.0, s * quarter) for s in (1.0, -1.0)]
    out: list[tuple[float, ...]] = []
    for p in points:
        if np.linalg.norm(p) > 0 and p not in out:
            out.append(p)
    return out


def mirror_pairs(specs: Sequence[PointSpec]) -> list[tuple[int, int]]:
    """The indices (i, j), i < j, of the drags in ``specs`` whose mirror images across the
    xz plane (:attr:`PointSpec.mirror`) are each other: elements off the centre line with a
    twin on the other side (pontoons, skids, floats at ± y), in the order of ``specs``."""
    index = {s: k for k, s in enumerate(specs)}
    return [(i, index[s.mirror]) for i, s in enumerate(specs)
            if s.position[1] != 0.0 and index.get(s.mirror, -1) > i]


def point_library(points: Sequence[Sequence[float]]) -> list[PointSpec]:
    """The candidate element drags at ``points``: per point, along u, v, w, on the element's
    speed and then on its normal speed (6 per point)."""
    return [PointSpec((float(p[0]), float(p[1]), float(p[2])), a, s)
            for s in SPEEDS for p in points for a in range(3)]
