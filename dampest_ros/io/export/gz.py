"""gz-sim Hydrodynamics plugin: export and import.

gz-sim ``Hydrodynamics`` system plugin (``gz-sim-hydrodynamics-system``). Tags
``<{x,y,z,k,m,n}{U,V,W,P,Q,R}>`` (linear), ``<xUabsU>``-style ``<iJabsK>`` (coefficient
of ν_j |ν_k|), ``<iJK>`` (of ν_j ν_k, no abs) and ``<iDotJ>`` (added mass), all 36 / 216
combinations, cross terms such as ``<yR>``, ``<nV>`` and ``<yVabsR>`` included.
``src/systems/hydrodynamics/HydrodynamicsUtils.hh`` (``buildDampingMatrix``) and
``Hydrodynamics.cc``: D(i,j) = −(<iJ> + Σ_k <iJabsK>|ν_k| + <iJK>ν_k) and the wrench
applied to the link is −D ν, so the applied force is +<xU> u + <xUabsU> u|u| …: SNAME
derivatives, **negative** when dissipative. Added mass: the applied force is
+<iDotJ> ν̇ (``kAmassVec = -Ma * stateDot``, wrench = −kTotalWrench), so <xDotU> is the
SNAME X_u̇ = −M_A (negative; since gz-sim 7, gz-sim PR #1617). Velocities are taken in
the frame of ``<link_name>``; Gazebo links follow REP-103, x forward, y left, z up (FLU)
— the Blue Robotics ``blue`` project states "Gazebo body frame (x-forward, y-left,
z-up)" next to its Hydrodynamics plugin. dampest works in FRD, so the export converts
with T = diag(1, −1, −1, 1, −1, −1): D_FLU = T D_FRD T, i.e. the coefficient of ν_j in
force i changes sign by t_i t_j (times t_k for a signed ν_k, never for |ν_k|); diagonal
terms are unchanged, couplings between {u, p} and {v, w, q, r} flip (X_w, Y_u, K_v, M_u,
N_p, …), couplings inside {v, w, q, r} do not (Y_r, N_v, Z_q, …). ``frame="frd"`` skips
the conversion for links built FRD.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np

from dampest_ros.core.identification.model import Model
from dampest_ros.core.identification.refold import all_entries
from dampest_ros.core.physics.damping import FloatArray
from dampest_ros.core.physics.frames import body_twist
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, AddedMassTerms, ConfigError
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.io.export import FRAMES
from dampest_ros.io.export.common import (
    Coefficient,
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
    xml_bool,
    xml_comment,
    xml_float,
)

_GZ_FORCE = "xyzkmn"
_GZ_VEL = "UVWPQR"
#: t with ν_FLU = t ⊙ ν_FRD (the same signs for wrenches).
_FLIP: FloatArray = body_twist(np.ones(6))
#: Tags of the gz plugin that carry no coefficient.
_GZ_OTHER = {"link_name", "water_density", "waterDensity", "namespace", "default_current",
             "disable_coriolis", "disable_added_mass", "lookup_current_x",
             "lookup_current_y", "lookup_current_z"}


def _gz_tag(c: Coefficient) -> str:
    base = f"{_GZ_FORCE[c.row]}{_GZ_VEL[c.col]}"
    if c.kind == "abs":
        return f"{base}abs{_GZ_VEL[c.k]}"
    if c.kind == "lin":
        return f"{base}{_GZ_VEL[c.k]}"
    return base


def _gz_sign(row: int, col: int, k: int, frame: str) -> float:
    """Sign of a coefficient in the link frame relative to FRD (k = −1: no signed ν_k)."""
    if frame == "frd":
        return 1.0
    s = _FLIP[row] * _FLIP[col]
    return float(s * _FLIP[k] if k >= 0 else s)


def _signed_k(c: Coefficient) -> int:
    """The velocity index whose sign enters α (ν_k of ``lin``), else −1."""
    return c.k if c.kind == "lin" else -1


def _check_frame(frame: str) -> str:
    if frame not in FRAMES:
        raise ValueError(f"unknown frame {frame!r}; use one of {FRAMES}")
    return frame


def _added_mass_in(frame: str, M_A: FloatArray) -> FloatArray:
    """An added-mass matrix, shape (6, 6) (kg, kg·m, kg·m²), converted between FRD and the
    link ``frame``: T M_A T with T = diag(``_FLIP``) for ``flu`` (its own inverse, so either
    way), unchanged for ``frd``."""
    T = np.diag(_FLIP) if frame == "flu" else np.eye(6)
    return np.asarray(T @ M_A @ T)


def export_gz(mf: Model, vehicle: Vehicle | None = None, *, link_name: str = "base_link",
              frame: str = "flu", source: str | None = None, force: bool = False,
              clamp: bool = False, refold: bool | None = None) -> Exported:
    """The gz-sim Hydrodynamics plugin element for a model.

    Parameters
    ----------
    mf : Model
    vehicle : Vehicle, optional
        Its rigid body gives the added mass M_A = M − M_RB; without it no ``<iDotJ>`` tags.
    link_name : str
        ``<link_name>`` of the plugin.
    frame : {'flu', 'frd'}
        Frame of that link: ``flu`` (Gazebo/REP-103; coefficients are converted) or ``frd``.
    source : str, optional
        Where the model came from, for the header comment.
    force, clamp : bool
        For coefficients that are not dissipative at every speed (gz-sim applies them at
        every speed): write them as they are (``force``) or the nearest dissipative set
        (``clamp``); the header says which.
    refold : bool, optional
        Write the static terms gz-sim has no tag for (element drags, products, speed
        norms) as the tags that reproduce their force best over the flown envelope
        (:func:`~dampest_ros.io.export.common.refolded`; the header gives the share);
        False: they are left out, listed. Default: refolded when the model file records
        its flown speeds (else left out); True: a file without them is refused.

    Returns
    -------
    Exported
        ``text`` is a ``<plugin>`` element (with a comment) to paste into the model's SDF
        (or into a URDF ``<gazebo>`` block).

    Raises
    ------
    NotDissipativeError
        The model generates energy and ``force`` is False.
    """
    frame = _check_frame(frame)
    model, theta, left_out = model_damping(mf)
    coefs, other = coefficients(model, theta) if model is not None else ([], [])
    left_out += other
    coefs, left_out, notes = refolded(mf, model, theta, coefs, left_out, all_entries(), "gz",
                                      refold)
    coefs, safety = made_safe(coefs, policy_of(force, clamp), "gz", source)
    damping = merge(((_gz_tag(c), c, -_gz_sign(c.row, c.col, _signed_k(c), frame) * c.value)
                      for c in coefs), notes)
    if any(c.kind == "lin" and c.row == c.col == c.k for c in coefs):
        notes.append("Signed diagonal products such as <xUU> mean X*u*u (no abs) in gz-sim; "
                     "gz warns that they may be unstable (gz-sim PR #1888).")
    M_A, mass_notes = export_added_mass(mf, vehicle)
    terms = added_mass_switches(mf, vehicle)
    switches = {"disable_added_mass": not terms.inertial, "disable_coriolis": not terms.coriolis}
    if terms.coriolis and terms.zeroed:
        left_out.append(f"added_mass_terms {terms.as_dict()}: gz-sim cannot zero entries of "
                        f"its C_A(nu) alone (here: {terms.off_text()}); written with the "
                        "Coriolis term on, all its entries included")
    if M_A is not None and terms.coriolis and np.any(M_A[~np.eye(6, dtype=bool)]):
        left_out.append("the off-diagonal M_A entries in C_A(nu)nu: gz-sim builds its Coriolis "
                        "term from the diagonal of M_A only (HydrodynamicsUtils.hh "
                        "buildCoriolisMatrix); they act in M_A nudot only")
    added: dict[str, float] = {}
    if M_A is not None:
        link = _added_mass_in(frame, M_A)
        for i in range(6):
            for j in range(6):
                if i == j or link[i, j] != 0.0:
                    added[f"{_GZ_FORCE[i]}Dot{_GZ_VEL[j]}"] = -float(link[i, j])
    frame_text = (
        ["Frame: coefficients are in the frame of link '" + link_name + "', taken as FLU "
         "(x forward, y left, z up: Gazebo/REP-103).",
         "dampest is FRD; FRD->FLU is T = diag(1,-1,-1,1,-1,-1), D_FLU = T D_FRD T: the",
         "coefficient of nu_j in force i is multiplied by t_i t_j (and t_k for a signed nu_k,",
         "never for |nu_k|). Diagonal terms keep their sign; couplings between {u,p} and",
         "{v,w,q,r} (e.g. xW, yU, kV, nP) flip, couplings inside {v,w,q,r} (yR, nV) do not."]
        if frame == "flu" else
        ["Frame: coefficients are in the frame of link '" + link_name + "', taken as FRD "
         "(x forward, y right, z down), as dampest: no conversion."])
    lines = [*header_lines(mf, source, coefs, safety),
             "Target: gz-sim Hydrodynamics system (gz-sim >= 7, e.g. Harmonic with ROS 2 Jazzy).",
             "Signs: gz applies F_i = sum_j (<iJ> + sum_k <iJabsK>|nu_k| + <iJK> nu_k) nu_j",
             "(HydrodynamicsUtils.hh buildDampingMatrix, wrench = -D nu): SNAME derivatives,",
             "negative when dissipative. Each tag = -(dampest coefficient), e.g. X_u = 13.7",
             "-> <xU>-13.7</xU>, X_uu = 141 -> <xUabsU>-141</xUabsU>.",
             *frame_text]
    if not terms.all:
        lines += [f"Added-mass switches {terms.as_dict()}: <disable_added_mass> drops "
                  "M_A nudot, <disable_coriolis> drops C_A(nu)nu."]
    if M_A is not None:
        lines += ["Added mass: <iDotJ> = -M_A (SNAME X_udot < 0; gz applies +<iDotJ> nudot).",
                  "With DART, <fluid_added_mass> in the link <inertial> (positive M_A) is the",
                  "stable alternative; then drop the <iDotJ> tags."]
    lines += mass_notes + notes
    if left_out:
        lines += ["LEFT OUT (no gz equivalent):", *(f"  {x}" for x in left_out)]
    plugin = ET.Element("plugin", {"filename": "gz-sim-hydrodynamics-system",
                                   "name": "gz::sim::systems::Hydrodynamics"})
    ET.SubElement(plugin, "link_name").text = link_name
    for tag, off in switches.items():
        if off:
            ET.SubElement(plugin, tag).text = "true"
    for tag, value in [*added.items(), *damping.items()]:
        ET.SubElement(plugin, tag).text = num(value)
    ET.indent(plugin, "  ")
    text = f"<!--{xml_comment(lines)}-->\n{ET.tostring(plugin, encoding='unicode')}\n"
    return exported_result("gz", text, left_out, mass_notes + notes, held_at_prior(mf),
                           safety)


def is_gz_plugin(el: ET.Element) -> bool:
    """Whether an element is a gz-sim Hydrodynamics ``<plugin>`` (by name or file name)."""
    return el.tag == "plugin" and (el.get("name", "").endswith("systems::Hydrodynamics")
                                   or "hydrodynamics-system" in el.get("filename", ""))


def _gz_plugin(root: ET.Element, label: str, link_name: str | None) -> ET.Element:
    """The one Hydrodynamics ``<plugin>`` under ``root`` (of link ``link_name`` when given).

    Raises
    ------
    ConfigError
        None, or several without ``link_name``.
    """
    plugins = [e for e in root.iter("plugin") if is_gz_plugin(e)]
    if link_name is not None:
        plugins = [p for p in plugins if (p.findtext("link_name") or "").strip() == link_name]
    if not plugins:
        raise ConfigError(label, "no gz-sim Hydrodynamics <plugin> "
                                 "(filename gz-sim-hydrodynamics-system)"
                                 + (f" for link {link_name!r}" if link_name else ""))
    if len(plugins) > 1:
        links = [(p.findtext("link_name") or "").strip() for p in plugins]
        raise ConfigError(label, f"{len(plugins)} Hydrodynamics plugins (links {links}); "
                                 f"choose one with link_name")
    return plugins[0]


def _read_gz_tags(plugin: ET.Element, frame: str) -> CoefficientTables:
    """The switches and coefficients of a plugin, converted from the link ``frame`` and the
    gz signs (SNAME, negative when dissipative) to FRD and dampest signs; other tags are noted
    as ignored (but those of :data:`_GZ_OTHER`).

    Raises
    ------
    ConfigError
        A non-numeric coefficient or a switch that is not a boolean.
    """
    tags = CoefficientTables()
    F, V = _GZ_FORCE, _GZ_VEL
    for el in plugin:
        if not isinstance(el.tag, str):
            continue
        tag = el.tag
        if tag in ("disable_added_mass", "disable_coriolis"):
            tags.disabled[tag] = xml_bool(el.text, f"<{tag}>")
            continue
        m = re.fullmatch(f"([{F}])(Dot)?([{V}])(?:(abs)?([{V}]))?", tag)
        if m is None:
            if tag not in _GZ_OTHER:
                tags.notes.append(f"<{tag}> ignored (not a Hydrodynamics coefficient).")
            continue
        i, j = F.index(m.group(1)), V.index(m.group(3))
        value = xml_float(el.text, f"<{tag}>")
        if m.group(2):
            if m.group(5):
                tags.notes.append(f"<{tag}> ignored (not a Hydrodynamics coefficient).")
                continue
            tags.link_mass[i, j] = neg(value)
            tags.has_added = True
            continue
        if m.group(5) is None:
            tags.lin[(i, j)] = neg(_gz_sign(i, j, -1, frame) * value)
            continue
        k = V.index(m.group(5))
        if m.group(4):
            coef = neg(_gz_sign(i, j, -1, frame) * value)
            if i == j == k:
                tags.quad[i] = coef
            else:
                tags.abs_cross[(i, j, k)] = coef
        else:
            tags.lin_cross[(i, j, k)] = neg(_gz_sign(i, j, k, frame) * value)
            if i == j == k:
                tags.notes.append(
                    f"<{tag}> read as {FORCE_NAMES[i]}*{DOF_NAMES[i]}*{DOF_NAMES[i]} (signed, "
                    f"gz-sim >= 7); files for older gz-sim meant {DOF_NAMES[i]}|{DOF_NAMES[i]}|: "
                    f"use <{tag[:2]}abs{tag[2]}>.")
    return tags


def _added_mass_terms(disabled: dict[str, bool]) -> AddedMassTerms:
    """The added-mass switches of a plugin. gz-sim's defaults (no tag): both effects act; its
    C_A(ν)ν holds the Munk moments."""
    coriolis = not disabled.get("disable_coriolis", False)
    return AddedMassTerms(inertial=not disabled.get("disable_added_mass", False),
                          coriolis=coriolis, munk=coriolis)


def import_gz(source: str | Path, *, frame: str = "flu",
              link_name: str | None = None) -> Imported:
    """Read the gz-sim Hydrodynamics plugin back into dampest conventions.

    Parameters
    ----------
    source : str or Path
        A file (SDF, URDF with ``<gazebo>`` blocks, or the bare ``<plugin>``) or XML text.
    frame : {'flu', 'frd'}
        Frame of the plugin's link (see :func:`export_gz`).
    link_name : str, optional
        Which plugin to read when the file has several.

    Returns
    -------
    Imported
        ``<iJ>`` become linear terms (diagonal ``X_u``, off-diagonal ``Y_r``), ``<iIabsI>``
        quadratic ``X_uu``, other ``<iJabsK>`` cross terms with α = |ν_k| (named ``Y_vr``),
        ``<iJK>`` cross terms with α = ν_k (``Y_vr``, or ``Y_vr_lin`` when that name is
        taken); ``<iDotJ>`` give ``added_mass``.

    Raises
    ------
    ConfigError
        No Hydrodynamics plugin, several without ``link_name``, or a non-numeric value.
    """
    frame = _check_frame(frame)
    root, label = parse_xml(source)
    plugin = _gz_plugin(root, label, link_name)
    tags = _read_gz_tags(plugin, frame)
    lin_spec, quad_spec, cross = damping_spec(tags)
    added = _added_mass_in(frame, tags.link_mass) if tags.has_added else None
    notes = [*tags.notes, f"Read from link '{(plugin.findtext('link_name') or '').strip()}' as "
                          f"{frame.upper()}."]
    return replace(build_imported("gz", lin_spec, quad_spec, cross, added, None, notes),
                   added_mass_terms=_added_mass_terms(tags.disabled))
