"""Drag of an element at a point of the body: the ``point`` damping term and its candidates
(the term also holds the lift and Magnus force of elements, :mod:`.point_lift`).

An appendage, a skid or a float off the body origin meets the water at its own velocity
v_p = v + ω × r_p (r_p its position, FRD, m), not at the body's. Its quadratic drag along one
direction e (a unit vector in the body frame: a body axis e_a, or an axis of an element the
vehicle file rotates) is a force at r_p,

    F_p = −c ‖v_p‖ v_p,e e         (``speed`` ``|U|``: drag on the element's speed)
    F_p = −c |v_p,e| v_p,e e       (``speed`` ``normal``: a strip's normal drag on its normal
                                    speed)
    F_p = −c |v_p,e| v_p           (``area``: a flat element's drag along its own velocity on
                                    the area it shows the flow, normal e)

with v_p,e = eᵀ v_p = wᵀν, w = [e; r_p × e] (6,), and it acts on the body as the wrench w
(force e at r_p: force along e, moment r_p × e): D(ν)ν = c α(ν) w wᵀ ν, α = ‖v_p‖ or |wᵀν|.
One coefficient c (N s²/m², positive when dissipative) enters the force along e and the two
moments its lever arm gives, consistently. Its power νᵀD(ν)ν = c α (wᵀν)² = c α v_p,e² is ≥ 0
for c ≥ 0: a non-negative coefficient is dissipative (its basis w wᵀ is positive
semi-definite, :meth:`DampingTerm.project` clips it at 0).

A flat element (a plate, a wing, a fin with normal e) shows a flow v_p the area A |cos β|,
β the angle between v_p and its normal: its pressure drag along v_p is c ‖v_p‖ v_p |cos β| =
c |v_p,e| v_p, on the body D(ν)ν = c |wᵀν| PᵀP ν (P = [I, −[r_p]×], v_p = P ν), power
c |v_p,e| ‖v_p‖² ≥ 0 for c ≥ 0 (PᵀP is positive semi-definite). Neither drag along a
direction has that form: it acts along v_p with a size set by the normal speed.

A direction (:mod:`.directions`) is a body axis 0, 1, 2 (u, v, w in the names) or any other
unit vector, named by its components, e.g. ``lift.e(0.8008,0.491,0.3429)@(0.44,0.21,-0.04)``.

The ``point`` term's elements (:class:`PointSpec`) are of four forces: ``drag`` and ``area``
(this module), ``lift`` and ``magnus`` (:mod:`.point_lift`: across v_p, doing no work).

Candidate points (:func:`candidate_points`): the positions of the vehicle file's geoms that are
off the origin (the shapes MuJoCo's fluid model applies its drag at), each with the geom's own
axes in the body frame (MuJoCo's forces on a geom act along its axes: the body axes unless the
file rotates it, ``rpy``); without a geometry, a small generic set along the body axes: ± half
the length L along x, ± L/4 along y and z (the ends and flanks of a body of about the usual
proportions).
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
from dampest_ros.core.physics.directions import (
    BODY_AXES,
    Axes,
    Direction,
    direction,
    geom_axes,
)
from dampest_ros.core.physics.geometry import Geometry
from dampest_ros.core.physics.point_lift import lift_basis, magnus_basis, transport
from dampest_ros.core.physics.rigid_body import DOF_NAMES, ConfigError

FloatArray = NDArray[np.float64]

#: The speeds an element's drag may go with: its speed ‖v_p‖ or its normal speed |v_p,a|.
SPEEDS = ("|U|", "normal")
#: The forces of an element: drag, a flat element's drag on its projected area, lift at an
#: angle of attack, Magnus force (:mod:`.point_lift`).
FORCES = ("drag", "area", "lift", "magnus")
def _name(axis: Direction) -> str:
    """A direction in a parameter name: ``u``, ``v``, ``w`` or ``e(e_x,e_y,e_z)``."""
    if isinstance(axis, int):
        return DOF_NAMES[axis]
    return "e(" + ",".join(f"{x:.12g}" for x in axis) + ")"


@dataclass(frozen=True)
class PointSpec:
    """One element force coefficient: where, which force, along which direction and on
    which speed.

    Attributes
    ----------
    position : tuple of 3 float
        r_p in the body frame (m, FRD).
    axis : int or tuple of 3 float
        The direction e (:data:`Direction`, from :func:`direction`): a drag's force, a flat
        element's normal (``area``), a lift's element axis; 0, 1, 2 a body axis x, y, z
        (velocity letters u, v, w); −1 for a Magnus force (it has none).
    speed : str
        A drag's ``|U|`` (‖v_p‖) or ``normal`` (|v_p,e|), :data:`SPEEDS`; ``|U|`` for the
        other forces.
    force : str
        ``drag``, ``area``, ``lift`` or ``magnus``, :data:`FORCES`.
    """

    position: tuple[float, float, float]
    axis: Direction
    speed: str = "|U|"
    force: str = "drag"

    @property
    def label(self) -> str:
        """The parameter name, e.g. ``drag.w|U|@(0.3,0,0.2)``: drag along w on the element's
        speed at the point (0.3, 0, 0.2) m (``drag.ww@…``: on its normal speed |w_p|);
        ``area.w@…``: the drag of a flat element with normal w on its projected area;
        ``lift.w@…``: the lift of an element along w; ``magnus@…``: the Magnus force. A
        direction off the body axes is ``e(e_x,e_y,e_z)``, its normal speed ``e``:
        ``drag.e(0.6,0.8,0)e@…``, ``lift.e(0.6,0.8,0)@…``."""
        where = ",".join(f"{x:.12g}" for x in self.position)
        if self.force == "magnus":
            return f"magnus@({where})"
        a = _name(self.axis)
        if self.force in ("area", "lift"):
            return f"{self.force}.{a}@({where})"
        normal = a if isinstance(self.axis, int) else "e"
        return f"drag.{a}{'|U|' if self.speed == '|U|' else normal}@({where})"

    @property
    def unit(self) -> FloatArray:
        """e, the unit vector of the direction in the body frame, shape (3,)."""
        if isinstance(self.axis, int):
            return np.eye(3)[self.axis]
        e = np.asarray(self.axis, dtype=float)
        return e / np.linalg.norm(e)

    @property
    def wrench(self) -> FloatArray:
        """w = [e; r_p × e], the body wrench of a unit force along e at r_p, shape (6,)."""
        e = self.unit
        return np.r_[e, np.cross(np.asarray(self.position, dtype=float), e)]

    @property
    def mirror(self) -> PointSpec:
        """The same force at the mirror image of the point across the body's xz plane
        (y → −y, and the direction's y component): its twin on the other side of a
        port–starboard symmetric vehicle."""
        x, y, z = self.position
        axis = self.axis
        if not isinstance(axis, int):
            # e_y → −e_y; then the sign that keeps the largest component positive (rounding
            # is odd, so this is the direction of the mirror image of the unrounded vector)
            ex, ey, ez = axis
            axis = direction((ex, -ey, ez))
        return PointSpec((x, -y + 0.0, z), axis, self.speed, self.force)

    def basis(self) -> Basis:
        """The parameter's basis: a drag's B = w wᵀ with α = ‖v_p‖ or |wᵀν|, a flat
        element's B = PᵀP with α = |wᵀν| (module docstring), a lift's or Magnus force's atoms
        (:mod:`.point_lift`)."""
        if self.force == "lift":
            return lift_basis(self.label, self.position, self.unit)
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
        force: magnus}``; an axis is u, v, w or a direction ``[e_x, e_y, e_z]`` (normalised,
        :func:`direction`)."""
        force = str(d.get("force", "drag")) if isinstance(d, dict) else ""
        if force not in FORCES or "position" not in d or ("axis" not in d
                                                          and force != "magnus"):
            raise ConfigError(where, "each element is {position: [x, y, z] (m), axis: u, v, "
                                     "w or [e_x, e_y, e_z], speed: '|U|' or normal} (a drag), "
                                     "{position, force: area or lift, axis} or {position, "
                                     "force: magnus}")
        pos = np.asarray(d["position"], dtype=float)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            raise ConfigError(f"{where}.position", f"three finite numbers (m), got {d['position']}")
        position = (float(pos[0]), float(pos[1]), float(pos[2]))
        if force == "magnus":
            return cls(position, -1, force=force)
        axis = _axis(d["axis"], f"{where}.axis", force)
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
        axis = DOF_NAMES[self.axis] if isinstance(self.axis, int) else list(self.axis)
        if self.force in ("area", "lift"):
            return {"position": list(self.position), "force": self.force, "axis": axis}
        return {"position": list(self.position), "axis": axis, "speed": self.speed}


def _axis(value: Any, where: str, force: str) -> Direction:
    """The direction of a vehicle or model file's ``axis:`` (u, v, w or [e_x, e_y, e_z])."""
    if not isinstance(value, (list, tuple)):
        axis = dof_index(value, where)
        if axis > 2:
            raise ConfigError(where, f"{value!r}: the {force} is along u, v, w or a direction "
                                     "[e_x, e_y, e_z]")
        return axis
    e = np.asarray(value, dtype=float) if all(
        isinstance(x, (int, float)) and not isinstance(x, bool) for x in value) else None
    if e is None or e.shape != (3,) or not np.all(np.isfinite(e)) or not np.any(e):
        raise ConfigError(where, f"{list(value)!r}: a direction is three finite numbers, not "
                                 "all zero, e.g. [0.6, 0.8, 0.0] (or u, v, w)")
    return direction(e)


def point_spec(basis: Basis) -> PointSpec:
    """The element force a basis of the ``point`` term stands for, read from its name."""
    found = _LABEL.fullmatch(basis.name)
    if found is None:
        raise ConfigError("point", f"{basis.name!r} is not an element force name "
                                   "(drag.<axis><speed>@(x,y,z), area.<axis>@(x,y,z), "
                                   "lift.<axis>@(x,y,z) or magnus@(x,y,z); an axis u, v, w "
                                   "or e(e_x,e_y,e_z))")
    axis, speed, force, normal, where = found.groups()
    x, y, z = _numbers(where)
    if force is not None:
        return PointSpec((x, y, z), _read(normal), force=force)
    if axis is None:
        return PointSpec((x, y, z), -1, force="magnus")
    return PointSpec((x, y, z), _read(axis), "|U|" if speed == "|U|" else "normal")


def _numbers(text: str) -> tuple[float, float, float]:
    """Three numbers ``x,y,z`` of a name."""
    x, y, z = (float(v) for v in text.split(","))
    return x, y, z


def _read(name: str) -> Direction:
    """The direction a name writes (:func:`_name`): a body axis letter or ``e(…)``."""
    return DOF_NAMES.index(name) if name in DOF_NAMES else direction(_numbers(name[2:-1]))


#: A direction in :attr:`PointSpec.label`: a body axis letter or e(e_x,e_y,e_z).
_DIRECTION = r"[uvw]|e\([^)]*\)"
#: The parameter names of :attr:`PointSpec.label`.
_LABEL = re.compile(rf"(?:drag\.({_DIRECTION})(\|U\||[uvwe])|(area|lift)\.({_DIRECTION})|magnus)"
                    r"@\(([^)]*)\)")


def point_term(specs: Sequence[PointSpec]) -> DampingTerm:
    """D_point: the drag, lift and Magnus force of elements at points of the body, one
    coefficient each."""
    return DampingTerm("point", "quadratic drag, lift or Magnus force of an element at a "
                                "point r of the body, on its own velocity v + ω × r (force "
                                "and moment r × F)",
                       [s.basis() for s in specs])


def candidate_points(geometry: Geometry | None, length: float
                     ) -> list[tuple[tuple[float, float, float], Axes]]:
    """Where elements may sit and their axes: the geoms off the origin with their own axes,
    else a generic set along the body axes (module docstring), each once, in file order.

    Parameters
    ----------
    geometry : Geometry or None
        The vehicle file's ``geometry:`` section.
    length : float
        The vehicle's reference length L (m).

    Returns
    -------
    list of (tuple of 3 float, tuple of 3 Direction)
        Positions (m, FRD) and the element's x, y, z axes in the body frame
        (:data:`BODY_AXES` for a geom the file does not rotate).
    """
    points: list[tuple[tuple[float, float, float], Axes]]
    if geometry is not None:
        points = [((float(g.position[0]), float(g.position[1]), float(g.position[2])),
                   geom_axes(g.rpy)) for g in geometry.geoms]
    else:
        half, quarter = 0.5 * length, 0.25 * length
        points = [((s * half, 0.0, 0.0), BODY_AXES) for s in (1.0, -1.0)]
        points += [((0.0, s * quarter, 0.0), BODY_AXES) for s in (1.0, -1.0)]
        points += [((0.0, 0.0, s * quarter), BODY_AXES) for s in (1.0, -1.0)]
    out: list[tuple[tuple[float, float, float], Axes]] = []
    for p in points:
        if np.linalg.norm(p[0]) > 0 and p not in out:
            out.append(p)
    return out


def mirror_pairs(specs: Sequence[PointSpec]) -> list[tuple[int, int]]:
    """The indices (i, j), i < j, of the drags in ``specs`` whose mirror images across the
    xz plane (:attr:`PointSpec.mirror`) are each other: elements off the centre line with a
    twin on the other side (pontoons, skids, floats at ± y), in the order of ``specs``."""
    index = {s: k for k, s in enumerate(specs)}
    return [(i, index[s.mirror]) for i, s in enumerate(specs)
            if s.position[1] != 0.0 and index.get(s.mirror, -1) > i]


def point_library(points: Sequence[tuple[Sequence[float], Axes]],
                  lifts: Sequence[tuple[tuple[float, float, float], Direction, bool]] = ()
                  ) -> list[PointSpec]:
    """The candidate element forces: per point of ``points`` (its position and the element's
    axes, :func:`candidate_points`), the drags along the element's three axes (u, v, w unless
    its geom is rotated) on its speed and then on its normal speed (6 per point); then the
    lifts ``lifts`` (position, element axis and whether the element is flat,
    :func:`~.point_lift.candidate_lifts`), each flat element's followed by its drag on its
    projected area."""
    where = [((float(p[0]), float(p[1]), float(p[2])), axes) for p, axes in points]
    return [*(PointSpec(p, a, s) for s in SPEEDS for p, axes in where for a in axes),
            *(PointSpec(p, a, force=f) for p, a, flat in lifts
              for f in (("lift", "area") if flat else ("lift",)))]
