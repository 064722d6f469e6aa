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
from pathlib import Path

import numpy as np

from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.damping import FloatArray
from dampest_ros.core.physics.frames import body_vec
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.io.export.common import (
    CoefficientTables,
    Exported,
    Imported,
    added_mass_switches,
    build_imported,
    coefficients,
    damping_spec,
    export_added_mass,
    exported_result,
    header_lines,
    held_at_prior,
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

#: The plugin of uuv_gazebo_ros_plugins that holds the hydrodynamic models (ROS variant).
PLUGIN = {"name": "uuv_plugin", "filename": "libuuv_underwater_object_ros_plugin.so"}
#: The HMFossen matrices and how many numbers HydrodynamicModel.cc accepts for each (6: the
#: diagonal).
MATRICES = {"added_mass": (36,), "linear_damping": (6, 36),
            "linear_damping_forward_speed": (6, 36), "quadratic_damping": (6, 36)}


def to_hmfossen(value: float) -> float:
    """A dampest coefficient (dissipative > 0) as the HMFossen matrix entry (dissipative < 0),
    and back: −value, its own inverse (HMFossen's force is −D ν with D = −DLin − …)."""
    return neg(value)


def link_point(r: FloatArray) -> FloatArray:
    """A point of the body, shape (3,) (m), between dampest's FRD and the link's FLU frame:
    (x, −y, −z), its own inverse."""
    return body_vec(r)


def _numbers(values: FloatArray) -> str:
    """Whitespace-separated numbers, one row of a 6×6 matrix per line."""
    A = np.atleast_2d(np.asarray(values, dtype=float))
    rows = "\n".join("        " + " ".join(num(x) for x in row) for row in A)
    return "\n" + rows + "\n      "


def export_uuv(mf: Model, vehicle: Vehicle | None = None, *, link_name: str = "base_link",
               source: str | None = None, force: bool = False,
               clamp: bool = False, refold: bool | None = None) -> Exported:
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
    refold : bool, optional
        Write the static terms UUV Simulator cannot carry as the coefficients it can that reproduce
        their force best over the flown envelope
        (:func:`~dampest_ros.io.export.common.refolded`; the header gives the share);
        False: they are left out, listed. Default: refolded when the model file records
        its flown speeds (else left out); True: a file without them is refused.

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
    # its full linear matrix, its diagonal quadratic
    entries = [(i, j, -1) for i in range(6) for j in range(6)] + [(i, i, i) for i in range(6)]
    written, left_out, notes = refolded(mf, model, theta, written, left_out, entries, "uuv",
                                        refold)
    written, safety = made_safe(written, policy_of(force, clamp), "uuv", source)
    tags = {"const": "linear_damping", "abs": "quadratic_damping",
            "lin": "linear_damping_forward_speed"}
    mats = {key: np.zeros((6, 6)) for key in tags.values()}
    for kind, key in tags.items():
        items = [(f"{key}[{c.row},{c.col}]", c, to_hmfossen(c.value)) for c in written
                 if c.kind == kind]
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
        ET.SubElement(link, "center_of_buoyancy").text = " ".join(
            num(x) for x in link_point(vehicle.body.r_b))
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


def _uuv_link(root: ET.Element, label: str, link_name: str | None
              ) -> tuple[ET.Element, ET.Element, ET.Element]:
    """The plugin, the one ``<link>`` with a ``<hydrodynamic_model>`` under ``root`` (the
    link named ``link_name`` when given) and that model.

    Raises
    ------
    ConfigError
        None, or several without ``link_name``.
    """
    found = [(parent, link, hm) for parent in root.iter() for link in parent.findall("link")
             if (hm := link.find("hydrodynamic_model")) is not None]
    if link_name is not None:
        found = [x for x in found if x[1].get("name") == link_name]
    if not found:
        raise ConfigError(label, "no UUV Simulator <hydrodynamic_model> (in a <link> of the "
                                 "underwater-object <plugin>)"
                                 + (f" for link {link_name!r}" if link_name else ""))
    if len(found) > 1:
        names = [link.get("name") for _, link, _ in found]
        raise ConfigError(label, f"{len(found)} links with a <hydrodynamic_model> ({names}); "
                                 f"choose one with --link-name")
    return found[0]


def _matrix(hm: ET.Element, tag: str) -> FloatArray | None:
    """A HMFossen matrix, shape (6, 6), from its 36 numbers (rows first) or the 6 of its
    diagonal; None when the tag is absent.

    Raises
    ------
    ConfigError
        A value that is not a number, or a count HMFossen does not accept.
    """
    el = hm.find(tag)
    if el is None:
        return None
    values = [xml_float(x, f"<{tag}>") for x in (el.text or "").split()]
    if len(values) not in MATRICES[tag]:
        counts = " or ".join(str(n) for n in MATRICES[tag])
        raise ConfigError(f"<{tag}>", f"needs {counts} numbers (HMFossen), got {len(values)}")
    return np.diag(values) if len(values) == 6 else np.array(values).reshape(6, 6)


def _read_hmfossen(hm: ET.Element) -> CoefficientTables:
    """The matrices of a ``<hydrodynamic_model>`` of type fossen in dampest signs (FRD, as
    HMFossen): diagonal linear terms always, off-diagonal and forward-speed entries where not
    zero, the diagonal of the quadratic damping; other tags noted as ignored."""
    tables = CoefficientTables()
    DLin = _matrix(hm, "linear_damping")
    DFwd = _matrix(hm, "linear_damping_forward_speed")
    DNon = _matrix(hm, "quadratic_damping")
    M_A = _matrix(hm, "added_mass")
    for i in range(6):
        for j in range(6):
            if DLin is not None and (i == j or DLin[i, j] != 0):
                tables.lin[(i, j)] = to_hmfossen(DLin[i, j])
            if DFwd is not None and DFwd[i, j] != 0:
                tables.lin_cross[(i, j, 0)] = to_hmfossen(DFwd[i, j])
        if DNon is not None:
            tables.quad[i] = to_hmfossen(DNon[i, i])
    if DNon is not None and np.any(DNon[~np.eye(6, dtype=bool)]):
        tables.notes.append("off-diagonal <quadratic_damping> entries ignored (HMFossen uses "
                            "the diagonal only, |nu_i| nu_i).")
    if M_A is not None:
        tables.link_mass, tables.has_added = M_A, True
    tables.notes += [f"<{el.tag}> {(el.text or '').strip()} ignored (HMFossen reads type and "
                     f"the matrices from the SDF; its scaling and offset parameters are set "
                     f"at run time)."
                     for el in hm if el.tag != "type" and el.tag not in MATRICES]
    return tables


def _vehicle_notes(plugin: ET.Element, link: ET.Element) -> list[str]:
    """What the block says about the vehicle (volume, centre of buoyancy in FRD, density),
    which a model file does not hold."""
    out = []
    volume, cob = link.find("volume"), link.find("center_of_buoyancy")
    density = plugin.find("fluid_density")
    if volume is not None:
        out.append(f"volume {num(xml_float(volume.text, '<volume>'))} m^3")
    if cob is not None:
        r = [xml_float(x, "<center_of_buoyancy>") for x in (cob.text or "").split()]
        if len(r) != 3:
            raise ConfigError("<center_of_buoyancy>", f"needs 3 numbers (x y z in the link "
                                                      f"frame, m), got {len(r)}")
        r_b = ", ".join(num(x) for x in link_point(np.array(r)))
        out.append(f"centre of buoyancy r_b = [{r_b}] m (FRD)")
    if density is not None:
        out.append(f"fluid density {num(xml_float(density.text, '<fluid_density>'))} kg/m^3")
    if not out:
        return []
    return [f"{', '.join(out)}: the vehicle's, not part of a model file (set them in the "
            f"vehicle YAML)."]


def import_uuv(source: str | Path, *, link_name: str | None = None) -> Imported:
    """Read UUV Simulator's HMFossen model back into dampest conventions.

    Parameters
    ----------
    source : str or Path
        A file (SDF, URDF with ``<gazebo>`` blocks, or the bare ``<plugin>``) or XML text.
    link_name : str, optional
        Which ``<link name=…>`` to read when the file has several with a model.

    Returns
    -------
    Imported
        ``linear_damping`` gives linear terms (diagonal ``X_u``, off-diagonal ``Y_r``),
        the diagonal of ``quadratic_damping`` quadratic ``X_uu``,
        ``linear_damping_forward_speed`` cross terms with α = u (``Z_wu``; ``X_uu_lin`` when
        the name is taken), ``added_mass`` the added mass (FRD, positive).

    Raises
    ------
    ConfigError
        No ``<hydrodynamic_model>``, several without ``link_name``, a type other than
        ``fossen``, a value that is not a number or a count HMFossen does not accept.
    """
    root, label = parse_xml(source)
    plugin, link, hm = _uuv_link(root, label, link_name)
    kind = (hm.findtext("type") or "").strip()
    if kind != "fossen":
        raise ConfigError(f"{label}: <hydrodynamic_model> of link {link.get('name')!r}",
                          f"type {kind!r}: only type fossen holds coefficients (sphere, "
                          f"cylinder and spheroid are computed from the geometry)")
    tables = _read_hmfossen(hm)
    lin_spec, quad_spec, cross = damping_spec(tables)
    added = tables.link_mass if tables.has_added else None
    notes = [*tables.notes, *_vehicle_notes(plugin, link),
             f"Read from link '{link.get('name')}' (HMFossen, FRD)."]
    return build_imported("uuv", lin_spec, quad_spec, cross, added, None, notes)
