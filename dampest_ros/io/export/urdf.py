"""The URDF <hydrodynamics> block: export and import.

The ``<hydrodynamics>`` block read by the Robotic Decision Making Lab ``hydrodynamics``
library (used by ``auv_controllers`` and the ``blue`` BlueROV2 project), in its current nested
layout: ``<inertial>`` (``<mass value=/>``, ``<inertia ixx= iyy= izz=/>``,
``<center_of_gravity x= y= z=/>``, ``<added_mass Xdu= Ydv= … />``), ``<damping>``
(``<linear Xu= … />``, ``<quadratic Xuu= … />``) and ``<hydrostatics>`` (``<weight value=/>``,
``<buoyancy value=/>``, ``<center_of_buoyancy x= y= z=/>``). The flat layout of April 2025
(``<linear_damping>``, ``<quadratic_damping>``, ``<added_mass>``, ``<mass>`` … directly in
the block) is still read by the import. ``src/hydrodynamics.cpp``: M_A = −diag(Xdu …),
D(ν) = −diag(Xu …) − diag(Xuu … ⊙ |ν|) on the left-hand side, so all coefficients are SNAME
(negative); the restoring forces put the weight along +z, and ``auv_controllers`` works in
``base_link_fsd`` / ``odom_ned``: the block is FRD, as dampest. Diagonal terms only.
The import also reads whitespace-separated text (6 or 36 numbers).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from dampest_ros.core.identification.model import Model
from dampest_ros.core.identification.refold import diagonal_entries
from dampest_ros.core.physics.damping import FloatArray
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, ConfigError, rigid_body_mass
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.io.export.common import (
    Exported,
    Imported,
    added_mass_switches,
    build_imported,
    coefficients,
    export_added_mass,
    exported_result,
    header_lines,
    held_at_prior,
    linear_name,
    made_safe,
    merge,
    model_damping,
    neg,
    num,
    parse_xml,
    policy_of,
    refolded,
    switches_left_out,
    xml_comment,
    xml_float,
)

_URDF_ADDED = ("Xdu", "Ydv", "Zdw", "Kdp", "Mdq", "Ndr")
_URDF_LINEAR = ("Xu", "Yv", "Zw", "Kp", "Mq", "Nr")
_URDF_QUADRATIC = ("Xuu", "Yvv", "Zww", "Kpp", "Mqq", "Nrr")


def export_urdf(mf: Model, vehicle: Vehicle | None = None, *,
                source: str | None = None, force: bool = False,
                clamp: bool = False, refold: bool | None = None) -> Exported:
    """The ``<hydrodynamics>`` block (RDML ``hydrodynamics`` / ``auv_controllers`` / ``blue``).

    Parameters
    ----------
    mf : Model
    vehicle : Vehicle, optional
        Adds ``<mass>``, ``<inertia>``, ``<added_mass>`` (M_A = M − M_RB, diagonal),
        ``<weight>``, ``<buoyancy>`` and the centres of gravity and buoyancy.
    source : str, optional
        Where the model came from, for the header comment.
    force, clamp : bool
        For coefficients that are not dissipative at every speed: write them as they are
        (``force``) or the nearest dissipative set (``clamp``); the header says which.
    refold : bool, optional
        Write the static terms the block cannot carry as the coefficients it can that reproduce
        their force best over the flown envelope
        (:func:`~dampest_ros.io.export.common.refolded`; the header gives the share);
        False: they are left out, listed. Default: refolded when the model file records
        its flown speeds (else left out); True: a file without them is refused.

    Returns
    -------
    Exported
        ``text`` is the block (FRD, SNAME signs), to paste inside ``<robot>``.

    Raises
    ------
    NotDissipativeError
        The model generates energy and ``force`` is False.
    """
    model, theta, left_out = model_damping(mf)
    coefs, other = coefficients(model, theta) if model is not None else ([], [])
    left_out += other
    written = [c for c in coefs if c.row == c.col and (
        c.kind == "const" or (c.kind == "abs" and c.k == c.row))]
    left_out += [f"{c.name} = {num(c.value)} (off-diagonal or cross coupling: the block holds "
                 f"diagonal damping only)" for c in coefs if c not in written]
    written, left_out, notes = refolded(mf, model, theta, written, left_out,
                                        diagonal_entries(), "urdf", refold)
    written, safety = made_safe(written, policy_of(force, clamp), "urdf", source)
    lin = [(_URDF_LINEAR[c.row], c, -c.value) for c in written if c.kind == "const"]
    quad = [(_URDF_QUADRATIC[c.row], c, -c.value) for c in written if c.kind == "abs"]
    left_out += switches_left_out(added_mass_switches(mf, vehicle), "the block")
    lin_v, quad_v = merge(lin, notes), merge(quad, notes)
    for names, values, what in ((_URDF_LINEAR, lin_v, "linear"),
                                (_URDF_QUADRATIC, quad_v, "quadratic")):
        missing = [n for n in names if n not in values]
        if missing:
            notes.append(f"{', '.join(missing)}: no {what} term in the model, written as 0.")
    M_A, mass_notes = export_added_mass(mf, vehicle)
    block = ET.Element("hydrodynamics")
    if vehicle is not None and M_A is not None:
        left_out += _inertial(ET.SubElement(block, "inertial"), vehicle, M_A)
    elif M_A is not None:
        left_out.append("the added mass model.M_A (the block's <inertial> holds it beside the "
                        "vehicle's mass and inertia: pass the vehicle)")
    damping = ET.SubElement(block, "damping")
    ET.SubElement(damping, "linear", {n: num(lin_v.get(n, 0.0)) for n in _URDF_LINEAR})
    ET.SubElement(damping, "quadratic", {n: num(quad_v.get(n, 0.0)) for n in _URDF_QUADRATIC})
    if vehicle is not None:
        body = vehicle.body
        statics = ET.SubElement(block, "hydrostatics")
        ET.SubElement(statics, "weight", {"value": num(body.weight)})
        ET.SubElement(statics, "buoyancy", {"value": num(body.buoyancy)})
        ET.SubElement(statics, "center_of_buoyancy",
                      {a: num(x) for a, x in zip("xyz", body.r_b, strict=True)})
    lines = [*header_lines(mf, source, written, safety),
             "Target: <hydrodynamics> block of the Robotic Decision Making Lab 'hydrodynamics'",
             "library (auv_controllers, blue): Fossen FRD body frame (base_link_fsd), SNAME",
             "signs: D(nu) = -diag(linear_damping) - diag(quadratic_damping)|nu| and",
             "M_A = -diag(added_mass), so dissipative values are negative:",
             "X_u = 13.7 -> Xu=\"-13.7\", X_uu = 141 -> Xuu=\"-141\".",
             *mass_notes, *notes]
    if left_out:
        lines += ["LEFT OUT (the block has no place for them):", *(f"  {x}" for x in left_out)]
    ET.indent(block, "  ")
    text = f"<!--{xml_comment(lines)}-->\n{ET.tostring(block, encoding='unicode')}\n"
    return exported_result("urdf", text, left_out, mass_notes + notes, held_at_prior(mf),
                           safety)


def _inertial(el: ET.Element, vehicle: Vehicle, M_A: FloatArray) -> list[str]:
    """Fill ``<inertial>``: mass, inertia, centre of gravity and the diagonal added mass
    (SNAME, negative); returns the off-diagonal M_A entries it cannot hold (left-out lines)."""
    body = vehicle.body
    ET.SubElement(el, "mass", {"value": num(body.mass)})
    J = body.inertia
    inertia = {"ixx": J[0, 0], "iyy": J[1, 1], "izz": J[2, 2]}
    inertia.update({k: J[a, b] for k, (a, b) in
                    (("ixy", (0, 1)), ("ixz", (0, 2)), ("iyz", (1, 2))) if J[a, b] != 0})
    ET.SubElement(el, "inertia", {k: num(v) for k, v in inertia.items()})
    ET.SubElement(el, "center_of_gravity",
                  {a: num(x) for a, x in zip("xyz", body.r_g, strict=True)})
    ET.SubElement(el, "added_mass", {n: num(-M_A[i, i]) for i, n in enumerate(_URDF_ADDED)})
    return [f"M_A[{FORCE_NAMES[i]},{DOF_NAMES[j]}] = {M_A[i, j]:.6g} (off-diagonal added mass: "
            "the block holds the diagonal only)"
            for i in range(6) for j in range(6) if i != j and M_A[i, j] != 0]


def _numbers(el: ET.Element, what: str) -> list[float]:
    return [xml_float(x, what) for x in (el.text or "").split()]


def _diag_or_full(el: ET.Element, keys: Sequence[str], what: str,
                  notes: list[str]) -> FloatArray | None:
    """A 6×6 matrix from attributes (diagonal) or from 6 / 36 numbers of text."""
    attrs = {k: xml_float(el.get(k), f"<{what} {k}>") for k in keys if el.get(k) is not None}
    if attrs:
        unknown = sorted(set(el.attrib) - set(keys))
        if unknown:
            notes.append(f"<{el.tag}> attributes {unknown} ignored.")
        A = np.full((6, 6), np.nan)
        for n, k in enumerate(keys):
            if k in attrs:
                A[n, n] = attrs[k]
        return A
    nums = _numbers(el, f"<{what}>")
    if not nums:
        return None
    if len(nums) == 6:
        A = np.full((6, 6), np.nan)
        A[np.diag_indices(6)] = nums
        return A
    if len(nums) == 36:
        return np.array(nums).reshape(6, 6)
    raise ConfigError(f"<{what}>", f"needs 6 or 36 numbers or attributes {list(keys)}, "
                                   f"got {len(nums)} numbers")


def _first(block: ET.Element, *tags: str) -> ET.Element | None:
    for tag in tags:
        el = next(block.iter(tag), None)
        if el is not None:
            return el
    return None


def _scalar(el: ET.Element | None, what: str) -> float | None:
    if el is None:
        return None
    return xml_float(el.get("value") if el.get("value") is not None else el.text, what)


def import_urdf(source: str | Path) -> Imported:
    """Read a ``<hydrodynamics>`` block (RDML ``hydrodynamics`` / ``auv_controllers``).

    Parameters
    ----------
    source : str or Path
        A URDF (or any XML) file holding the block, or XML text.

    Returns
    -------
    Imported
        Diagonal linear ``X_u …`` and quadratic ``X_uu …`` (36-number linear text also gives
        off-diagonal ``Y_r …``); ``added_mass`` from ``<added_mass>``; ``rigid_body`` from
        ``<mass>`` + ``<inertia>`` (+ ``<center_of_gravity>``).

    Raises
    ------
    ConfigError
        No ``<hydrodynamics>`` element, or a non-numeric value.
    """
    root, label = parse_xml(source)
    block = root if root.tag == "hydrodynamics" else next(root.iter("hydrodynamics"), None)
    if block is None:
        raise ConfigError(label, "no <hydrodynamics> element")
    notes: list[str] = []
    lin_spec: dict[str, float] = {}
    quad_spec: dict[str, float] = {}
    lin_el = _first(block, "linear_damping", "linear")
    if lin_el is not None:
        A = _diag_or_full(lin_el, _URDF_LINEAR, lin_el.tag, notes)
        if A is not None:
            lin_spec = {linear_name(i, i): neg(float(A[i, i])) for i in range(6)
                        if not np.isnan(A[i, i])}
            lin_spec.update({linear_name(i, j): neg(float(A[i, j])) for i in range(6)
                             for j in range(6) if i != j and not np.isnan(A[i, j])
                             and A[i, j] != 0})
    quad_el = _first(block, "quadratic_damping", "quadratic")
    if quad_el is not None:
        A = _diag_or_full(quad_el, _URDF_QUADRATIC, quad_el.tag, notes)
        if A is not None:
            quad_spec = {f"{FORCE_NAMES[i]}_{DOF_NAMES[i]}{DOF_NAMES[i]}": neg(float(A[i, i]))
                         for i in range(6) if not np.isnan(A[i, i])}
            off = [(i, j) for i in range(6) for j in range(6)
                   if i != j and not np.isnan(A[i, j]) and A[i, j] != 0]
            if off:
                notes.append(f"off-diagonal quadratic damping at {off} ignored (the block's "
                             f"quadratic damping is diagonal, |nu_i| nu_i).")
    added = None
    am_el = _first(block, "added_mass")
    if am_el is not None:
        A = _diag_or_full(am_el, _URDF_ADDED, "added_mass", notes)
        if A is not None:
            added = 0.0 - np.nan_to_num(A, nan=0.0)
    rigid = None
    mass = _scalar(_first(block, "mass"), "<mass>")
    inertia_el = _first(block, "inertia")
    if mass is not None and inertia_el is not None:
        get = {k: xml_float(inertia_el.get(k, "0"), f"<inertia {k}>")
               for k in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")}
        inertia = np.array([[get["ixx"], get["ixy"], get["ixz"]],
                            [get["ixy"], get["iyy"], get["iyz"]],
                            [get["ixz"], get["iyz"], get["izz"]]])
        cg_el = _first(block, "center_of_gravity")
        r_g = np.array([xml_float(cg_el.get(a, "0"), f"<center_of_gravity {a}>") for a in "xyz"]
                       if cg_el is not None else [0.0, 0.0, 0.0])
        rigid = rigid_body_mass(mass, inertia, r_g)
    return build_imported("urdf", lin_spec, quad_spec, [], added, rigid, notes)
