"""Lift and Magnus force of an element at a point of the body: forces across its own flow.

An element at r_p (FRD, m) meets the water at v_p = v + ω × r_p = P ν, P = [I, −[r_p]×]
(3×6), and a force F at r_p acts on the body as the wrench Pᵀ F = [F; r_p × F]. Beside its
drag (:mod:`.point_drag`, along v_p or its body axis), a body in a flow feels forces across
v_p, from the circulation the flow takes around it (Kutta–Joukowski: force ρ Γ × v per unit
length):

* lift of an element at an angle of attack. A slender element along a direction e (a float's
  long axis, a strut), or a plate with normal e, turns the flow that meets it obliquely; the
  force is the cross-flow part of its normal force,

      F_L = c (e·v_p) (‖v_p‖² e − (e·v_p) v_p) / ‖v_p‖ = c (e·v_p) ((v_p × e) × v_p) / ‖v_p‖,

  of size (c/2) ‖v_p‖² sin 2β (β the angle between v_p and e: none along the axis nor across
  it, most at 45°), quadratic-homogeneous in v_p, c (N s²/m²) of either sign.
  As a parameter: Pᵀ F_L = c (‖v_p‖ w wᵀ − (v_p,a² / ‖v_p‖) PᵀP) ν with w = Pᵀe, two atoms
  (α ``pspeed`` and ``pshare``, :mod:`.alpha`); the first is the element's drag on its speed,
  the second takes back its part along v_p.
* Magnus force of a rotating element: the body's rotation carries a circulation round the
  element, and the flow past it a force F_M = c ω × v_p at r_p (c in kg, of either sign).
  Its part c ω × v at the origin is the Coriolis force of a translational added mass −c
  (m_u = m_v = m_w, the ``coriolis`` term), which the vehicle's ``coriolis`` term already
  carries for all elements together; the parameter is the rest, what moving the element off
  the origin adds: the force c ω × (ω × r_p) and the moments r_p × F_M,

      Pᵀ F_M − [c ω × v; 0] = c Σ_k ω_k (Pᵀ [e_k]× P − E [e_k]× Eᵀ) ν,  E = [I; 0] (6×3),

  three atoms with α = p, q, r (the whole Magnus force as one parameter would repeat the
  ``coriolis`` term's columns and hide its own lever arm among their collinear directions).

Power: both forces are perpendicular to v_p, so νᵀ Pᵀ F = v_pᵀ F = 0 whatever c (and the
Magnus part left at the origin, vᵀ (c ω × v), is 0 too): they move energy between the DOFs and
take none out (their D(ν) is not positive semi-definite; the lift's atoms are, one PSD and one
NSD, and sum to a power of zero, the Magnus ones are skew).
:meth:`~dampest_ros.core.physics.damping.DampingTerm.project` leaves their coefficients as
they are, and the dissipativity constraint (:mod:`dampest_ros.core.identification.dissipative`)
sees zero power rows for them: neither can make a model generate energy.

Candidates (:func:`candidate_lifts`): the elements of the geometry lift about their own axis,
turned into the body frame by the geom's orientation (a body axis unless the file rotates the
geom, :mod:`.directions`; MuJoCo's forces on a geom act along its own axes): a slender
element (a float, a strut, a bottle: semi-axes a ≤ b ≤ c with c/b > b/a) about its
long axis, a flat one (a wing, a fin, a plate: b/a ≥ c/b) about its normal (the plate's
circulation is across the flow and its normal, so its lift has the same form with e its
normal: MuJoCo's Kutta lift of a thin ellipsoid, semi-axes r_1, r_2 in its plane, is this force
with c = C_K ρ π r_1 r_2, up to the flow within a few degrees of its plane). A flat element
also drags on the area it shows the flow (``area``, :mod:`.point_drag`). A sphere turns no
flow. Without a geometry no lift is offered: lift needs a shape.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.alpha import Alpha
from dampest_ros.core.physics.damping import Basis
from dampest_ros.core.physics.directions import Direction, geom_axes
from dampest_ros.core.physics.geometry import Geometry

FloatArray = NDArray[np.float64]


def transport(position: tuple[float, float, float]) -> FloatArray:
    """P = [I, −[r]×], shape (3, 6): v_p = P ν for the point r = ``position`` (m, FRD); Pᵀ
    maps a force at r to its body wrench [F; r × F]."""
    r = np.asarray(position, dtype=float)
    # [r]× a = r × a, column by column
    cross = np.cross(r, np.eye(3), axisa=0, axisb=0, axisc=0)
    return np.hstack([np.eye(3), -cross])


def lift_basis(name: str, position: tuple[float, float, float], e: FloatArray) -> Basis:
    """The lift of an element along the unit direction ``e`` (shape (3,), body frame) at
    ``position`` (module docstring): atoms (‖v_p‖, w wᵀ) and ((eᵀv_p)² / ‖v_p‖, −PᵀP),
    w = Pᵀ e."""
    P = transport(position)
    # w = Pᵀ e = [e; r × e], the wrench of a unit force along e at r
    w = P.T @ e
    where = tuple(map(float, position))
    return Basis(name, np.outer(w, w), Alpha("pspeed", w=where),
                 ((-P.T @ P, Alpha("pshare", w=(*where, *map(float, e)))),))


def magnus_basis(name: str, position: tuple[float, float, float]) -> Basis:
    """The Magnus force of an element at ``position`` less its part at the origin (module
    docstring): atoms (ω_k, Pᵀ [e_k]× P − E [e_k]× Eᵀ), k = x, y, z."""
    P, E = transport(position), transport((0.0, 0.0, 0.0))
    e = np.eye(3)
    # [e_k]× as matrices, shape (3, 3, 3)
    skew = np.cross(e[:, None, :], e[None, :, :]).transpose(0, 2, 1)
    atoms = [(P.T @ skew[k] @ P - E.T @ skew[k] @ E, Alpha("lin", 3 + k)) for k in range(3)]
    return Basis(name, atoms[0][0], atoms[0][1], tuple(atoms[1:]))


def candidate_lifts(geometry: Geometry | None
                    ) -> list[tuple[tuple[float, float, float], Direction, bool]]:
    """The lifts the elements of the vehicle's geometry may have (module docstring): per
    geom off the origin but a sphere, its position, its long axis (a slender geom) or its
    normal (a flat one) in the body frame and whether it is flat, in file order.

    Parameters
    ----------
    geometry : Geometry or None
        The vehicle file's ``geometry:`` section.

    Returns
    -------
    list of (tuple of 3 float, Direction, bool)
        Position (m, FRD), axis (:data:`~.directions.Direction`: 0, 1, 2 for u, v, w when
        the geom is not rotated) and flat.
    """
    out: list[tuple[tuple[float, float, float], Direction, bool]] = []
    for g in geometry.geoms if geometry is not None else ():
        a, b, c = sorted(g.size)
        where = (float(g.position[0]), float(g.position[1]), float(g.position[2]))
        if not np.linalg.norm(where) > 0 or a == c:
            continue
        # slender (c/b > b/a): its long axis; flat: its normal, the shortest; in the body
        # frame: the geom's rotation of its own axis
        flat = not c * a > b * b
        own = geom_axes(g.rpy)[int(np.argmin(g.size) if flat else np.argmax(g.size))]
        lift = (where, own, flat)
        if lift not in out:
            out.append(lift)
    return out
