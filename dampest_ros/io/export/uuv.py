"""UUV Simulator: the underwater-object plugin block with its HMFossen hydrodynamic model (SDF).

``uuv_gazebo_plugins`` (``UnderwaterObjectPlugin.cc``) reads, for every ``<link name=…>``
inside its ``<plugin>``, a ``<hydrodynamic_model>``; ``<type>fossen</type>`` selects HMFossen
(``HydrodynamicModel.cc``), which takes whitespace-separated numbers, rows first:
``<added_mass>`` (36: M_A itself, positive), ``<linear_damping>`` (6 for the diagonal, or
36), ``<linear_damping_forward_speed>`` (6 or 36) and ``<quadratic_damping>`` (6 or 36, of
which only the diagonal is used). On the link velocity converted to FRD (``ToNEDConvention``
negates y and z of Gazebo's FLU) it builds D = −DLin − u·DLinForwardSpeed,
D_ii += −DNonLin_ii |ν_i| and applies −D ν (converted back to FLU): the matrices are FRD, as
dampest, and dissipative entries are negative (X_u = 13.7 → −13.7). Beside the model the link
takes ``<volume>`` (m³) and ``<center_of_buoyancy>`` (m, in the link frame, FLU), the plugin
``<fluid_density>`` (kg/m³); they are written when a vehicle is given (r_b converted from FRD).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.damping import FloatArray
from dampest_ros.core.physics.frames import body_twist
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.io.export.common import (
    Exported,
    added_mass_switches,
    coefficients,
    export_added_mass,
    exported_result,
    header_lines,
    held_at_prior,
    made_safe,
    merge,
    model_damping,
    num,
    policy_of,
    switches_left_out,
    xml_comment,
)

#: The plugin of uuv_gazebo_ros_plugins that holds the hydrodynamic models (ROS variant).
PLUGIN = {"name": "uuv_plugin", "filename": "libuuv_underwater_object_ros_plugin.so"}


def _numbers(values: FloatArray) -> str:
    """Whitespace-separated numbers, one row of a 6×6 matrix per line."""
    A = np.atleast_2d(np.asarray(values, dtype=float))
    rows = "\n".join("        " + " ".join(num(x) for x in row) for row in A)
    return "\n" + rows + "\n      "


def export_uuv(mf: Model, vehicle: Vehicle | None = None, *, link_name: str = "base_link",
               source: str | None = None, force: bool = False,
               clamp: bool = False) -> Exported:
    """The UUV Simulator ``<plugin>`` block with the model as its HMFossen matrices (FRD).

    Parameters
    ----------
    mf : Model
    vehicle : Vehicle, optional
        Gives ``<added_mass>`` (M_A = M − M_RB, positive, when the model file has no
        ``model.M_A``), ``<volume>``, ``<center_of_buoyancy>`` and ``<fluid_density>``.
    link_name : str
        ``name`` of the plugin's ``<link>`` (the vehicle's base link in its SDF/URDF).
    source : str, optional
        Where the model came from, for the header comment.
    force, clamp : bool
        For coefficients that are not dissipative at every speed: write them as they are
        (``force``) or the nearest dissipative set (``clamp``); the header says which.

    Returns
    -------
    Exported
        ``text``: a header comment, then the ``<plugin>`` element to paste into the vehicle's
        SDF (or a URDF ``<gazebo>`` block). ``<linear_damping>`` and
        ``<linear_damping_forward_speed>`` are 36 numbers, ``<quadratic_damping>`` the 6 of
        its diagonal, ``<added_mass>`` 36.

    Raises
    ------
    NotDissipativeError
        The model generates energy and ``force`` is False.
    """
    model, theta, left_out = model_damping(mf)
    coefs, other = coefficients(model, theta) if model is not None else ([], [])
    left_out += other
    written = [c for c in coefs if c.kind == "const" or (c.kind == "lin" and c.k == 0)
               or (c.kind == "abs" and c.row == c.col == c.k)]
    left_out += [f"{c.name} = {num(c.value)} (UUV Simulator has quadratic damping on the "
                 f"diagonal only (|nu_i| nu_i) and products with u only)"
                 for c in coefs if c not in written]
    written, safety = made_safe(written, policy_of(force, clamp), "uuv", source)
    notes: list[str] = []
    # HMFossen's force is −D ν with D = −DLin − …: each entry is −(dampest coefficient)
    tags = {"const": "linear_damping", "abs": "quadratic_damping",
            "lin": "linear_damping_forward_speed"}
    mats = {key: np.zeros((6, 6)) for key in tags.values()}
    for kind, key in tags.items():
        items = [(f"{key}[{c.row},{c.col}]", c, -c.value) for c in written if c.kind == kind]
        for k, v in merge(items, notes).items():
            i, j = (int(x) for x in k[len(key) + 1:-1].split(","))
            mats[key][i, j] = v
    fwd = any(c.kind == "lin" for c in written)
    left_out += switches_left_out(added_mass_switches(mf, vehicle), "UUV Simulator")
    M_A, mass_notes = export_added_mass(mf, vehicle)
    lines = [*header_lines(mf, source, written, safety),
             "Target: UUV Simulator underwater-object plugin (uuv_gazebo_ros_plugins), model",
             "HMFossen (uuv_gazebo_plugins HydrodynamicModel.cc). Matrices in the FRD body",
             "frame (the plugin converts Gazebo's FLU with ToNEDConvention), rows first:",
             "D = -linear_damping - u*linear_damping_forward_speed,",
             "D_ii += -quadratic_damping_ii |nu_i|, force -D nu: dissipative entries are",
             "negative, e.g. X_u = 13.7 -> -13.7.",
             "added_mass is M_A itself (positive)." if M_A is not None else "",
             *mass_notes, *notes]
    if left_out:
        lines += ["LEFT OUT (no UUV Simulator equivalent):", *(f"  {x}" for x in left_out)]
    plugin = ET.Element("plugin", PLUGIN)
    if vehicle is not None:
        ET.SubElement(plugin, "fluid_density").text = num(vehicle.body.rho)
    link = ET.SubElement(plugin, "link", {"name": link_name})
    if vehicle is not None:
        ET.SubElement(link, "volume").text = num(vehicle.body.volume)
        # r_b FRD → the link's FLU frame: (x, −y, −z)
        r_b = body_twist(np.r_[vehicle.body.r_b, np.zeros(3)])[:3]
        ET.SubElement(link, "center_of_buoyancy").text = " ".join(num(x) for x in r_b)
    hm = ET.SubElement(link, "hydrodynamic_model")
    ET.SubElement(hm, "type").text = "fossen"
    if M_A is not None:
        ET.SubElement(hm, "added_mass").text = _numbers(M_A)
    ET.SubElement(hm, "linear_damping").text = _numbers(mats["linear_damping"])
    if fwd:
        ET.SubElement(hm, "linear_damping_forward_speed").text = _numbers(
            mats["linear_damping_forward_speed"])
    ET.SubElement(hm, "quadratic_damping").text = _numbers(
        np.diag(mats["quadratic_damping"]))
    ET.indent(plugin, "  ")
    text = (f"<!--{xml_comment([x for x in lines if x])}-->\n"
            f"{ET.tostring(plugin, encoding='unicode')}\n")
    return exported_result("uuv", text, left_out, mass_notes + notes, held_at_prior(mf),
                           safety)
