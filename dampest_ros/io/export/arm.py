"""An identified arm as a simulator's model: MJCF (``<joint armature damping frictionloss>``
and the bodies' ``<inertial>``) and URDF (``<dynamics damping friction>`` and the links'
``<inertial>``), and the same files read back into an arm model file.

What is written, per quantity:

- A joint term (armature Ia, viscous Fv, Coulomb Fc) that is a base parameter on its own is
  the model file's estimate (``model.theta``), unless it is negative (not dissipative: the
  consistent fit's value then, and without one the export is refused). One that the data
  determine only in a combination (the armature of a joint whose rotor turns with the link's
  inertia about the same axis) is the consistent fit's split of it, or, for a file without
  one (the online node's), the arm's nominal value; the file says which in a comment.
- Link inertias are the physically consistent fit's (``model.consistent_full``, written by
  ``dampest arm identify --out``): one physical set that reproduces every base parameter.
  Each base parameter that combines several links' parameters is named in a comment (the data
  determine the sum, not the split). Without a consistent fit they are the URDF's nominal
  inertias, said so.
- URDF has no armature: the armature is a comment there. A URDF link that carries other
  links through fixed joints keeps its own inertial (the data determine the sum of them,
  which Pinocchio and the MJCF hold on one body), said so in a comment.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.arm.base import base_parameters
from dampest_ros.core.arm.model import (
    ArmModel,
    JointDynamics,
    arm_from_urdf,
    arm_model_identity,
    fixed_joints,
    joint_dynamics,
    mjcf,
    urdf_dynamics,
)
from dampest_ros.core.arm.online import ArmEstimate
from dampest_ros.core.arm.regressor import full_parameters, parameter_names
from dampest_ros.io.arm import ARM_MODEL_KIND, ArmDataError, ArmDescription
from dampest_ros.io.strict_yaml import InputError, load_yaml
from dampest_ros.io.yaml_io import model_section

FloatArray = NDArray[np.float64]

#: The joint terms exported, with the JointDynamics field each fills.
_TERMS = (("Ia", "armature"), ("Fv", "damping"), ("Fc", "frictionloss"))


@dataclass(frozen=True)
class ExportedArm:
    """The arm a model file describes, as exported.

    Attributes
    ----------
    arm : ArmModel
        The arm with the exported link inertias.
    dynamics : JointDynamics
        The exported joint terms.
    notes : list of str
        One line per quantity that is not the data's own value, and per base parameter that
        spans several links.
    """

    arm: ArmModel
    dynamics: JointDynamics
    notes: list[str]


def arm_of_model_file(path: str | Path) -> tuple[str, tuple[str, ...]] | None:
    """The arm (``model.arm``) of an arm model file and the joints it was identified with
    locked (``model.lock``, none if absent); None for any other file (a vehicle's model
    file, or one that does not read: its own reader says why)."""
    try:
        _, m = model_section(load_yaml(path))
    except (InputError, OSError):
        return None
    if m.get("kind") != ARM_MODEL_KIND:
        return None
    return str(m.get("arm")), tuple(str(j) for j in m.get("lock", []))


def consistent_full(path: str | Path, arm: ArmModel) -> FloatArray | None:
    """The consistent fit's full parameters of a model file (``model.consistent_full``), or
    None when the file has none (the online node's ~/save).

    Raises
    ------
    ArmDataError
        If its names are not this arm's full parameters.
    """
    try:
        _, m = model_section(load_yaml(path))
    except InputError as exc:
        raise ArmDataError(str(exc)) from None
    full = m.get("consistent_full")
    if not isinstance(full, dict):
        return None
    if list(full.get("names", [])) != parameter_names(arm):
        raise ArmDataError(f"{path}: model.consistent_full names the parameters of another "
                           "arm; export with the arm the file was identified on (--arm)")
    return np.asarray(full["values"], dtype=float)


def _terms(line: str) -> list[str]:
    """The full parameters a mapping line ``bk = a + c b - d e`` combines (the tokens whose
    part after the last dot is a parameter name, not a number's decimals)."""
    return [t for t in line.split(" = ", 1)[1].split() if t.rsplit(".", 1)[-1].isalpha()
            and "." in t]


#: A joint term less than this below 0 is a zero's rounding (from folding base parameters).
_ROUNDING = 1e-12


def _joint_term(name: str, estimate: float | None, split: float | None, nominal: float
                ) -> tuple[float, str | None]:
    """A joint term's exported value and why it is not the data's own (None: it is): the
    estimate when the data determine it alone and it is not negative; else the consistent
    fit's split; else (determined only in a combination) the nominal value.

    Raises
    ------
    ArmDataError
        If the estimate is negative (not dissipative) and there is no consistent fit.
    """
    if estimate is not None and estimate >= -_ROUNDING:
        return max(estimate, 0.0), None
    if estimate is not None and split is None:
        raise ArmDataError(f"{name} = {estimate:.6g} < 0 is not dissipative, and the model "
                           "file has no consistent fit to take instead; export the file "
                           "'dampest arm identify --out' writes")
    if split is not None:
        why = ("determined only in a combination" if estimate is None else
               f"the estimate {estimate:.6g} < 0 is not dissipative")
        return split, f"{name}: {why}; the consistent fit's value"
    return nominal, (f"{name}: determined only in a combination; the arm's nominal value "
                     "(the model file has no consistent fit)")


def exported_arm(desc: ArmDescription, est: ArmEstimate, full: FloatArray | None
                 ) -> ExportedArm:
    """The arm and joint terms to export from a model file's estimate (module docstring).

    Parameters
    ----------
    desc : ArmDescription
        The arm the model file belongs to.
    est : ArmEstimate
    full : ndarray, shape (14 n,), optional
        The consistent fit's full parameters (:func:`consistent_full`).

    Returns
    -------
    ExportedArm
    """
    arm = desc.model
    n = arm.n
    alone = {name: value for name, value, line in zip(est.parameter_names, est.theta,
                                                      est.mapping, strict=True)
             if _terms(line) == [name]}
    split = full[10 * n:].reshape(n, 4) if full is not None else None
    notes = []
    values: dict[str, list[float]] = {field: [] for _, field in _TERMS}
    for j, joint in enumerate(arm.names):
        for k, (term, field) in enumerate(_TERMS):
            name = f"{joint}.{term}"
            value, note = _joint_term(name, alone.get(name),
                                      None if split is None else float(split[j, k]),
                                      float(getattr(desc.dynamics, field)[j]))
            values[field].append(value)
            notes.extend([note] if note else [])
    dyn = JointDynamics(**{field: np.array(v) for field, v in values.items()})
    notes.append("torque offsets (off): the sensor's, not the arm's; not exported")
    if full is None:
        notes.append("link inertias: the URDF's nominal ones (the model file has no "
                     "consistent fit: write one with 'dampest arm identify --out')")
        inertial = arm.inertial
    else:
        inertial = full[:10 * n].reshape(n, 10)
    for line in est.mapping:
        links = {t.split(".")[0] for t in _terms(line)}
        if len(links) > 1:
            notes.append(f"{line.split(' = ')[0]} spans the links of {', '.join(sorted(links))}"
                         f": the data determine {line.split(' = ', 1)[1]}, not its split")
    return ExportedArm(replace(arm, inertial=np.array(inertial, dtype=float)), dyn, notes)


def _comment(text: str) -> str:
    """An XML comment of free text (``--`` is not allowed inside one)."""
    return f"<!-- {text.replace('--', '- -')} -->"


def export_mjcf(exp: ExportedArm, name: str, source: str) -> str:
    """The MJCF of an exported arm (:func:`~dampest_ros.core.arm.model.mjcf`) with a comment
    per note after the header line."""
    body = mjcf(exp.arm, exp.dynamics, name=name)
    head, rest = body.split("\n", 1)
    lines = [_comment(f"dampest export of {source}: joint terms and link inertias "
                      "identified (notes below)"), *(_comment(n) for n in exp.notes)]
    return head + "\n" + "\n".join(f"  {c}" for c in lines) + "\n" + rest


def _inertial_element(pi: FloatArray) -> ET.Element:
    """A URDF <inertial> of ten inertial parameters about the link origin."""
    m = float(pi[0])
    c = pi[1:4] / m
    Io = np.array([[pi[4], pi[5], pi[7]], [pi[5], pi[6], pi[8]], [pi[7], pi[8], pi[9]]])
    Ic = Io - m * (math.fsum(c * c) * np.eye(3) - np.outer(c, c))
    el = ET.Element("inertial")
    ET.SubElement(el, "origin", xyz=" ".join(repr(float(x)) for x in c), rpy="0 0 0")
    ET.SubElement(el, "mass", value=repr(m))
    ET.SubElement(el, "inertia", ixx=repr(float(Ic[0, 0])), ixy=repr(float(Ic[0, 1])),
                  ixz=repr(float(Ic[0, 2])), iyy=repr(float(Ic[1, 1])),
                  iyz=repr(float(Ic[1, 2])), izz=repr(float(Ic[2, 2])))
    return el


def _fixed_with_mass(root: ET.Element, link: str) -> list[str]:
    """Links hanging from ``link`` through fixed joints that have an <inertial>."""
    links = {str(el.get("name")): el for el in root.findall("link")}
    out, todo = [], [link]
    while todo:
        parent = todo.pop()
        for j in root.findall("joint"):
            p, c = j.find("parent"), j.find("child")
            if (j.get("type") == "fixed" and p is not None and c is not None
                    and p.get("link") == parent):
                child = str(c.get("link"))
                todo.append(child)
                if child in links and links[child].find("inertial") is not None:
                    out.append(child)
    return out


def export_urdf(exp: ExportedArm, urdf: str, source: str) -> str:
    """The arm's URDF with the exported <dynamics damping friction> of every joint and the
    exported <inertial> of every link that alone makes up its joint's body (module
    docstring); notes and the armature as comments."""
    root = ET.fromstring(urdf)
    joints = {str(j.get("name")): j for j in root.findall("joint")}
    links = {str(el.get("name")): el for el in root.findall("link")}
    notes = list(exp.notes)
    for j, name in enumerate(exp.arm.names):
        joint = joints[name]
        for old in joint.findall("dynamics"):
            joint.remove(old)
        ET.SubElement(joint, "dynamics", damping=repr(float(exp.dynamics.damping[j])),
                      friction=repr(float(exp.dynamics.frictionloss[j])))
        notes.append(f"{name}: armature {float(exp.dynamics.armature[j])!r} kg m^2 (URDF has "
                     "no element for it)")
        child = joint.find("child")
        link = str(child.get("link")) if child is not None else ""
        rigid = _fixed_with_mass(root, link)
        if rigid:
            notes.append(f"link {link}: inertial left as is; the data determine its sum with "
                         f"{', '.join(rigid)} (fixed to it)")
            continue
        for old in links[link].findall("inertial"):
            links[link].remove(old)
        links[link].insert(0, _inertial_element(exp.arm.inertial[j]))
    root.insert(0, ET.Comment(f" dampest export of {source}: joint dynamics and link "
                              "inertias identified (notes below) ".replace("--", "- -")))
    for k, note in enumerate(notes):
        root.insert(k + 1, ET.Comment(f" {note} ".replace("--", "- -")))
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n"


def import_arm(path: str | Path, fmt: str, desc: ArmDescription
               ) -> tuple[ArmModel, JointDynamics]:
    """Read an arm's joint terms and link inertias back from an MJCF or URDF (its joints
    named as ``desc``'s; a URDF's other joints, a gripper's, held fixed at 0).

    Raises
    ------
    ArmDataError
        If the file does not load or lacks one of the arm's joints.
    """
    import mujoco

    from dampest_ros.core.arm.mjinverse import body_parameters, joint_bodies

    text = Path(path).read_text(encoding="utf-8")
    try:
        if fmt == "mjcf":
            mj = mujoco.MjModel.from_xml_string(text)
            bodies, _ = joint_bodies(mj, desc.model.names)
            inertial = np.array([body_parameters(mj, b) for b in bodies])
            return (replace(desc.model, inertial=inertial),
                    joint_dynamics(mj, desc.model.names))
        moving = [str(j.get("name")) for j in ET.fromstring(text).findall("joint")
                  if j.get("type") not in ("fixed", "floating", "planar")]
        arm = arm_from_urdf(fixed_joints(text, tuple(
            name for name in moving if name not in desc.model.names)))
    except (ValueError, ET.ParseError) as exc:
        raise ArmDataError(f"{path}: {exc}") from None
    if arm.names != desc.model.names:
        raise ArmDataError(f"{path}: joints {list(arm.names)}, not the arm's "
                           f"{list(desc.model.names)}; import with the arm it describes")
    return arm, urdf_dynamics(arm)


def imported_estimate(arm: ArmModel, dyn: JointDynamics, like: ArmDescription,
                      ) -> ArmEstimate:
    """The base parameters of an imported arm as a model file's estimate (σ 0, nothing
    identified: a description, not a measurement)."""
    base = base_parameters(like.model)
    theta = base.of(full_parameters(arm, dyn))
    kept = [base.names[i] for i in base.independent]
    return ArmEstimate(tuple(arm.names), kept, theta, np.zeros(len(kept)),
                       np.zeros(len(kept), dtype=bool), base.mapping(),
                       identity=arm_model_identity(like.source, like.model, kept))
