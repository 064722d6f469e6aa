"""Drag of an element at a point of the body: the ``point`` damping term and its candidates
(the term also holds the lift and Magnus force of elements, :mod:`.point_lift`).

An appendage, a skid or a float off the body origin meets the water at its own velocity
v_p = v + ω × r_p (r_p its position, FRD, m), not at the body's. Its quadratic drag along one
body axis a (unit vector e_a) is a force at r_p,

    F_p = −c ‖v_p‖ v_p,a e_a       (``speed`` ``|U|``: drag on the element's speed)
    F_p = −c |v_p,a| v_p,a e_a     (``speed`` ``|a|``: a strip's normal drag on its normal speed)
    F_p = −c |v_p,a| v_p           (``area``: a flat element's drag along its own velocity on
                                    the area it shows the flow, normal e_a)

with v_p,a = e_aᵀ v_p = wᵀν, w = [e_a; r_p × e_a] (6,), and it acts on the body as the wrench
w (force e_a at r_p: force along a, moment r_p × e_a): D(ν)ν = c α(ν) w wᵀ ν, α = ‖v_p‖ or
|wᵀν|. One coefficient c (N s²/m², positive when dissipative) enters the force along a and the
two moments its lever arm gives, consistently. Its power νᵀD(ν)ν = c α (wᵀν)² = c α v_p,a²
is ≥ 0 for c ≥ 0: a non-negative coefficient is dissipative (its basis w wᵀ is positive
semi-definite, :meth:`DampingTerm.project` clips it at 0).

A flat element (a plate, a wing, a fin with normal e_a) shows a flow v_p the area A |cos β|,
β the angle between v_p and its normal: its pressure drag along v_p is c ‖v_p‖ v_p |cos β| =
c |v_p,a| v_p, on the body D(ν)ν = c |wᵀν| PᵀP ν (P = [I, −[r_p]×], v_p = P ν), power
c |v_p,a| ‖v_p‖² ≥ 0 for c ≥ 0 (PᵀP is positive semi-definite). Neither drag along a body
axis has that form: it acts along v_p with a size set by the normal speed.

The ``point`` term's elements (:class:`PointSpec`) are of four forces: ``drag`` and ``area``
(this module), ``lift`` and ``magnus`` (:mod:`.point_lift`: across v_p, doing no work).

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
from dampest_ros.core.physics.point_lift import lift_basis, magnus_basis, transport
from dampest_ros.core.physics.rigid_body import DOF_NAMES, ConfigError

FloatArray = NDArray[np.float64]

#: The speeds an element's drag may go with: its speed ‖v_p‖ or its normal speed |v_p,a|.
SPEEDS = ("|U|", "normal")
#: The forces of an element: drag, a flat element's drag on its projected area, lift at an
#: angle of attack, Magnus force (:mod:`.point_lift`).
FORCES = ("drag", "area", "lift", "magnus")


@dataclass(frozen=True)
class PointSpec:
    """One element force coefficient: where, which force, along which axis and on which
    speed.

    Attributes
    ----------
    position : tuple of 3 float
        r_p in the body frame (m, FRD).
    axis : int
        0, 1, 2: a drag's force along x, y or z (velocity letters u, v, w), a flat element's
        normal (``area``), a lift's element axis e; −1 for a Magnus force (it has none).
    speed : str
        A drag's ``|U|`` (‖v_p‖) or ``normal`` (|v_p,a|), :data:`SPEEDS`; ``|U|`` for the
        other forces.
    force : str
        ``drag``, ``area``, ``lift`` or ``magnus``, :data:`FORCES`.
    """

    position: tuple[float, float, float]
    axis: int
    speed: str = "|U|"
    force: str = "drag"

    @property
    def label(self) -> str:
        """The parameter name, e.g. ``drag.w|U|@(0.3,0,0.2)``: drag along w on the element's
        speed at the point (0.3, 0, 0.2) m (``drag.ww@…``: on its normal speed |w_p|);
        ``area.w@…``: the drag of a flat element with normal w on its projected area;
        ``lift.w@…``: the lift of an element along w; ``magnus@…``: the Magnus force."""
        where = ",".join(f"{x:.12g}" for x in self.position)
        if self.force == "magnus":
            return f"magnus@({where})"
        a = DOF_NAMES[self.axis]
        if self.force in ("area", "lift"):
            return f"{self.force}.{a}@({where})"
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
        return PointSpec((x, -y + 0.0, z), self.axis, self.speed, self.force)

    def basis(self) -> Basis:
        """The parameter's basis: a drag's B = w wᵀ with α = ‖v_p‖ or |wᵀν|, a flat
        element's B = PᵀP with α = |wᵀν| (module docstring), a lift's or Magnus force's atoms
        (:mod:`.point_lift`)."""
        if self.force == "lift":
            return lift_basis(self.label, self.position, self.axis)
        if self.force == "magnus":
            return magnus_basis(self.label, self.position)
        w = self.wrench
        if self.force == "area":
            P = transport(self.position)
            return Basis(self.label, P.T @ P, Alpha("absproj", w=tuple(map(float, w))))
        alpha = (Alpha("pspeed", w=tuple(map(float, self.position))) if self.speed == "|U|"
                 else Alpha("absproj", w=tuple(map(float, w))))
        return Basis(self.label, np.outer(w, w), alpha)

    @classmethod
    def from_dict(cls, d: Any, where: str = "point") -> PointSpec:
        """From ``{position: [x, y, z], axis: w, speed: '|U|'}`` (a drag, speed optional),
        ``{position: [x, y, z], force: area (or lift), axis: w}`` or ``{position: [x, y, z],
        force: magnus}``."""
        force = str(d.get("force", "drag")) if isinstance(d, dict) else ""
        if force not in FORCES or "position" not in d or ("axis" not in d
                                                          and force != "magnus"):
            raise ConfigError(where, "each element is {position: [x, y, z] (m), axis: u, v "
                                     "or w, speed: '|U|' or normal} (a drag), {position, "
                                     "force: area or lift, axis} or {position, force: "
                                     "magnus}")
        pos = np.asarray(d["position"], dtype=float)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            raise ConfigError(f"{where}.position", f"three finite numbers (m), got {d['position']}")
        position = (float(pos[0]), float(pos[1]), float(pos[2]))
        if force == "magnus":
            return cls(position, -1, force=force)
        axis = dof_index(d["axis"], f"{where}.axis")
        if axis > 2:
            raise ConfigError(f"{where}.axis", f"{d['axis']!r}: the {force} is along u, v or w")
        if force in ("area", "lift"):
            return cls(position, axis, force=force)
        speed = str(d.get("speed", "|U|"))
        if speed not in SPEEDS:
            raise ConfigError(f"{where}.speed", f"{speed!r}; use one of {SPEEDS}")
        return cls(position, axis, speed)

    def to_dict(self) -> dict[str, Any]:
        """The mapping :meth:`from_dict` reads."""
        if self.force == "magnus":
            return {"position": list(self.position), "force": self.force}
        if self.force in ("area", "lift"):
            return {"position": list(self.position), "force": self.force,
                    "axis": DOF_NAMES[self.axis]}
        return {"position": list(self.position), "axis": DOF_NAMES[self.axis],
                "speed": self.speed}


def point_spec(basis: Basis) -> PointSpec:
    """The element force a basis of the ``point`` term stands for, read from its name."""
    found = _LABEL.fullmatch(basis.name)
    if found is None:
        raise ConfigError("point", f"{basis.name!r} is not an element force name "
                                   "(drag.<axis><speed>@(x,y,z), area.<axis>@(x,y,z), "
                                   "lift.<axis>@(x,y,z) or magnus@(x,y,z))")
    axis, speed, force, normal, where = found.groups()
    x, y, z = (float(v) for v in where.split(","))
    if force is not None:
        return PointSpec((x, y, z), DOF_NAMES.index(normal), force=force)
    if axis is None:
        return PointSpec((x, y, z), -1, force="magnus")
    return PointSpec((x, y, z), DOF_NAMES.index(axis), "|U|" if speed == "|U|" else "normal")


#: The parameter names of :attr:`PointSpec.label`.
_LABEL = re.compile(
    r"(?:drag\.([uvw])(\|U\||[uvw])|(area|lift)\.([uvw])|magnus)@\(([^)]*)\)")


def point_term(specs: Sequence[PointSpec]) -> DampingTerm:
    """D_point: the drag, lift and Magnus force of elements at points of the body, one
    coefficient each."""
    return DampingTerm("point", "quadratic drag, lift or Magnus force of an element at a "
                                "point r of the body, on its own velocity v + ω × r (force "
                                "and moment r × F)",
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


def point_library(points: Sequence[Sequence[float]],
                  lifts: Sequence[tuple[tuple[float, float, float], int, bool]] = ()
                  ) -> list[PointSpec]:
    """The candidate element forces: per point of ``points``, the drags along u, v, w on the
    element's speed and then on its normal speed (6 per point); then the lifts ``lifts``
    (position, element axis and whether the element is flat,
    :func:`~.point_lift.candidate_lifts`), each flat element's followed by its drag on its
    projected area."""
    where = [(float(p[0]), float(p[1]), float(p[2])) for p in points]
    return [*(PointSpec(p, a, s) for s in SPEEDS for p in where for a in range(3)),
            *(PointSpec(p, a, force=f) for p, a, flat in lifts
              for f in (("lift", "area") if flat else ("lift",)))]
