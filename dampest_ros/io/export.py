"""Export a model to simulator and controller formats, and import it back.

Targets (docs/architecture.md §5), with the conventions read from each project's source:

``gz``
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
``urdf``
    The ``<hydrodynamics>`` block read by the Robotic Decision Making Lab ``hydrodynamics``
    library (used by ``auv_controllers`` and the ``blue`` BlueROV2 project),
    ``examples/description/bluerov2.model.urdf``: attributes ``<added_mass Xdu= Ydv= … />``,
    ``<linear_damping Xu= … />``, ``<quadratic_damping Xuu= … />`` plus ``<mass>``,
    ``<inertia ixx= iyy= izz= />``, ``<weight>``, ``<buoyancy>``, ``<center_of_gravity>``,
    ``<center_of_buoyancy>``. ``src/hydrodynamics.cpp``: M_A = −diag(Xdu …), D(ν) = −diag(Xu …)
    − diag(Xuu … ⊙ |ν|) on the left-hand side, so all coefficients are SNAME (negative);
    the restoring forces put the weight along +z, and ``auv_controllers`` works in
    ``base_link_fsd`` / ``odom_ned``: the block is FRD, as dampest. Diagonal terms only.
    The import also reads the nested layout of ``auv_controllers``' demos
    (``<inertial><added_mass/></inertial><damping><linear/><quadratic/></damping>``) and
    whitespace-separated text (6 or 36 numbers).
``uuv``
    UUV Simulator ``HMFossen`` (``uuv_gazebo_plugins/src/HydrodynamicModel.cc``):
    ``added_mass`` (36, M_A, positive), ``linear_damping`` (6 or 36),
    ``quadratic_damping`` (6 or 36, only the diagonal is used) and
    ``linear_damping_forward_speed`` (36): D = −DLin − u·DLinForwardSpeed,
    D_ii += −DNonLin_ii |ν_i|, wrench = −D ν, computed on velocities converted to FRD
    (``ToNEDConvention`` negates y and z): matrices in FRD, damping **negative** when
    dissipative. Written as YAML (``hydrodynamic_model: {type: fossen, …}``).

dampest stores D(ν)ν on the left-hand side with dissipative coefficients positive, in FRD.
Added mass is the model file's ``model.M_A`` when it has one, else M_A = M − M_RB with the
vehicle's rigid body; with neither only the damping is exported (and the output says so).
The added-mass switches (``model.added_mass_terms``, else the vehicle's) become gz-sim's
``<disable_added_mass>`` (``inertial: false``) and ``<disable_coriolis>`` (``coriolis:
false``); gz-sim has no switch for the Munk moments alone (its C_A(ν)ν always holds them), and
the URDF block and UUV Simulator have no switches at all: such a combination is listed as
left out, as are off-diagonal M_A entries in gz-sim's C_A(ν)ν (built from the diagonal of M_A
only; they act in its M_A ν̇). Terms a format cannot express (fluid memory, residual modes,
|U| or product α) are listed in the output and raised as :class:`ExportWarning`; nothing is
dropped silently.

Two things are never exported silently. Coefficients the data did not determine
(``model.identified`` false, :attr:`~dampest_ros.io.yaml_io.ModelFile.held`) are written with
the value the model holds (their prior) and listed as such in the file's header, with an
:class:`ExportWarning`. A model that generates energy somewhere on a grid over its flown
speeds (``model.flown_speeds``, else a default box; see
:func:`~dampest_ros.core.identified.non_dissipative`) is refused with
:class:`NotDissipativeError`, which names the coefficient and the velocity; with
``force=True`` it is exported and the header says that it is not dissipative.
"""

from __future__ import annotations

import math
import re
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from dampest_ros.core.damping import DampingModel, FloatArray
from dampest_ros.core.frames import body_twist
from dampest_ros.core.identified import non_dissipative
from dampest_ros.core.rigid_body import (
    DOF_NAMES,
    FORCE_NAMES,
    AddedMassTerms,
    ConfigError,
    rigid_body_mass,
)
from dampest_ros.core.vehicle import Vehicle, damping_from_spec
from dampest_ros.io.yaml_io import ModelFile

#: Export targets.
FORMATS = ("gz", "urdf", "uuv")
#: Formats :func:`import_model` reads.
IMPORT_FORMATS = ("gz", "urdf")
#: Body frames of a gz link: ``flu`` (REP-103, Gazebo's default) or ``frd``.
FRAMES = ("flu", "frd")

_GZ_FORCE = "xyzkmn"
_GZ_VEL = "UVWPQR"
#: t with ν_FLU = t ⊙ ν_FRD (the same signs for wrenches).
_FLIP: FloatArray = body_twist(np.ones(6))
#: Tags of the gz plugin that carry no coefficient.
_GZ_OTHER = {"link_name", "water_density", "waterDensity", "namespace", "default_current",
             "disable_coriolis", "disable_added_mass", "lookup_current_x",
             "lookup_current_y", "lookup_current_z"}
_URDF_ADDED = ("Xdu", "Ydv", "Zdw", "Kdp", "Mdq", "Ndr")
_URDF_LINEAR = ("Xu", "Yv", "Zw", "Kp", "Mq", "Nr")
_URDF_QUADRATIC = ("Xuu", "Yvv", "Zww", "Kpp", "Mqq", "Nrr")


class ExportWarning(UserWarning):
    """Part of a model could not be written in the target format, or holds values the data did
    not determine (listed in the message)."""


class NotDissipativeError(ValueError):
    """The model generates energy (νᵀD(ν)ν < 0) somewhere in its speed envelope: a simulator
    built from it gains energy and can diverge. The message names the coefficient and ν."""


@dataclass(frozen=True)
class Coefficient:
    """One damping coefficient in a target-independent form.

    The left-hand-side force (FRD, dissipative positive) on ``row`` gains
    ``value · α(ν) · ν_col`` with α = 1 (``kind="const"``), |ν_k| (``"abs"``) or ν_k
    (``"lin"``).

    Parameters
    ----------
    row, col : int
        Force X..N and velocity u..r indices, 0..5.
    kind : str
        ``const``, ``abs`` or ``lin``.
    k : int
        Index of the velocity inside α (−1 for ``const``).
    value : float
    name : str
        The dampest parameter it comes from.
    """

    row: int
    col: int
    kind: str
    k: int
    value: float
    name: str


@dataclass(frozen=True)
class Exported:
    """An exported model.

    Parameters
    ----------
    format : str
        One of :data:`FORMATS`.
    text : str
        The file content (XML or YAML), with a header comment on conventions.
    left_out : tuple of str
        Parameters (or added-mass entries) the format cannot hold, with the reason.
    notes : tuple of str
        Other remarks written in the header (frame, added mass, merged tags, …).
    held : tuple of str
        ``"name = value (reason)"`` of the coefficients the data did not determine, written
        with the model's value (the prior) and listed in the header.
    non_dissipative : tuple of str
        Where the model generates energy (only with ``force=True``; stated in the header).
    """

    format: str
    text: str
    left_out: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    held: tuple[str, ...] = ()
    non_dissipative: tuple[str, ...] = ()


@dataclass(frozen=True)
class Imported:
    """A model read from a simulator file, in dampest conventions (FRD, dissipative > 0).

    Parameters
    ----------
    format : str
        One of :data:`IMPORT_FORMATS`.
    names : list of str
        Parameter names in θ order, as :func:`damping_from_spec` builds them from ``spec``.
    theta : ndarray, shape (p,)
    spec : dict
        A ``damping`` mapping (sections ``linear``, ``quadratic``, ``cross``).
    added_mass : ndarray, shape (6, 6), or None
        M_A in FRD (positive), when the file has added-mass entries.
    rigid_body : ndarray, shape (6, 6), or None
        M_RB, when the file has mass and inertia (``urdf`` only).
    notes : tuple of str
        What was ignored or interpreted.
    added_mass_terms : AddedMassTerms or None
        The added-mass switches (``gz``: from ``<disable_added_mass>`` and
        ``<disable_coriolis>``, all on without them; None for ``urdf``, which has none).
    """

    format: str
    names: list[str]
    theta: FloatArray
    spec: dict[str, Any]
    added_mass: FloatArray | None = None
    rigid_body: FloatArray | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)
    added_mass_terms: AddedMassTerms | None = None

    def damping(self) -> DampingModel:
        """The damping model of ``spec`` (parameter names are ``names``)."""
        return damping_from_spec(self.spec)[0]


# --- the model as coefficients ---------------------------------------------------------------


def _num(x: float) -> str:
    """Shortest text that reads back as the same float; ``0`` for ±0."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot export the non-finite value {x}")
    return "0" if x == 0.0 else repr(x)


def _model_damping(mf: ModelFile) -> tuple[DampingModel | None, FloatArray, list[str]]:
    """The damping model of a model file, its θ, and the parameters it cannot place.

    Files written with ``damping=`` carry ``model.terms``; for older files the structure is
    read from the names (``X_u``/``Y_r`` linear, ``X_uu`` quadratic); other names are
    returned as unplaceable.
    """
    theta = np.asarray(mf.theta, dtype=float)
    if mf.damping is not None:
        return mf.damping, theta, []
    spec: dict[str, dict[str, float]] = {"linear": {}, "quadratic": {}}
    unknown = []
    for name, value in zip(mf.parameter_names, theta, strict=True):
        m = re.fullmatch(r"([XYZKMN])_([uvwpqr])(\2)?", name)
        if m is None:
            unknown.append(f"{name} = {_num(value)} (the model file has no model.terms, so "
                           f"its structure is unknown)")
        elif m.group(3):
            if FORCE_NAMES.index(m.group(1)) != DOF_NAMES.index(m.group(2)):
                unknown.append(f"{name} = {_num(value)} (not a diagonal quadratic term and "
                               f"no model.terms in the file)")
            else:
                spec["quadratic"][name] = float(value)
        else:
            spec["linear"][name] = float(value)
    spec = {k: v for k, v in spec.items() if v}
    if not spec:
        return None, np.zeros(0), unknown
    model, th = damping_from_spec(spec)
    return model, th, unknown


def coefficients(model: DampingModel, theta: FloatArray) -> tuple[list[Coefficient], list[str]]:
    """Split a damping model into single-entry coefficients and what has no such form.

    Parameters
    ----------
    model : DampingModel
    theta : ndarray, shape (p,)

    Returns
    -------
    coefficients : list of Coefficient
        Every static basis with one non-zero entry and α ∈ {1, |ν_k|, ν_k}.
    other : list of str
        ``"name = value (reason)"`` for the rest: memory states, residual modes, α = ‖v‖,
        products.
    """
    theta = np.asarray(theta, dtype=float)
    out: list[Coefficient] = []
    other: list[str] = []
    for term in model.terms:
        th = theta[model.slice(term.kind)]
        if term.kind == "freq":
            for name, c, lam in zip(term.parameter_names, th, term.rates, strict=True):
                other.append(f"{name} = {_num(c)} (fluid memory with rate {_num(lam)} 1/s: "
                             f"the format has no memory states)")
            continue
        for b, v in zip(term.bases, th, strict=True):
            nz = np.argwhere(b.B != 0)
            a = b.alpha
            if len(nz) == 1 and a.kind in ("one", "abs", "lin"):
                i, j = (int(x) for x in nz[0])
                kind = {"one": "const", "abs": "abs", "lin": "lin"}[a.kind]
                out.append(Coefficient(i, j, kind, a.i if kind != "const" else -1,
                                       float(v) * float(b.B[i, j]), b.name))
            elif a.kind == "absproj":
                w = ", ".join(f"{x:.3g}" for x in a.w)
                other.append(f"{b.name} = {_num(v)} (quadratic drag along the mode "
                             f"w = [{w}], force = s |w'nu| w w'nu: not a single coefficient)")
            else:
                other.append(f"{b.name} = {_num(v)} (alpha = {a.label() or a.kind}: no such "
                             f"velocity dependence in the format)")
    return out, other


def _added_mass(mf: ModelFile, vehicle: Vehicle | None) -> tuple[FloatArray | None, list[str]]:
    """M_A (FRD): the file's ``model.M_A``, else M − M_RB of the vehicle, cleaned of
    round-off, and notes; None with neither."""
    if mf.M_A is not None:
        return np.asarray(mf.M_A, dtype=float).reshape(6, 6), [
            "Added mass M_A from the model file (model.M_A)."]
    if vehicle is None:
        return None, ["Added mass not exported: M_A = M - M_RB needs the vehicle's rigid "
                      "body (pass a vehicle); the simulator's default (zero) applies."]
    M = np.asarray(mf.M, dtype=float).reshape(6, 6)
    M_A = M - vehicle.body.M_RB
    scale = float(np.abs(M).max())
    # M and M_RB are sums of decimal inputs: keep 12 significant digits, zero the round-off
    M_A = np.where(np.abs(M_A) <= 1e-12 * scale, 0.0,
                   np.array([[float(f"{x:.12g}") for x in row] for row in M_A]))
    notes = [f"Added mass M_A = M - M_RB with the rigid body of vehicle {vehicle.name!r}."]
    if not np.allclose(M_A, M_A.T, atol=1e-9 * scale):
        notes.append("M - M_RB is not symmetric; its entries are written as they are.")
    neg = [f"{FORCE_NAMES[i]}: {M_A[i, i]:.6g}" for i in range(6) if M_A[i, i] < 0]
    if neg:
        msg = (f"M - M_RB has negative diagonal entries ({', '.join(neg)}): is "
               f"{vehicle.name!r} the vehicle of this model?")
        warnings.warn(msg, ExportWarning, stacklevel=3)
        notes.append(msg)
    return M_A, notes


def _switches(mf: ModelFile, vehicle: Vehicle | None) -> AddedMassTerms:
    """The added-mass switches of the model file, else of the vehicle, else all on."""
    if mf.added_mass_terms is not None:
        return mf.added_mass_terms
    return vehicle.body.added_mass_terms if vehicle is not None else AddedMassTerms()


def _switches_left_out(terms: AddedMassTerms, fmt: str) -> list[str]:
    """The left-out line for switches a format without any cannot hold ([] when all on)."""
    if terms.all:
        return []
    off = ", ".join(k for k, v in terms.as_dict().items() if not v)
    return [f"added_mass_terms {terms.as_dict()} (the plant applies no {off} effect of the "
            f"added mass; {fmt} has no switches and applies M_A nudot and C_A(nu)nu whole)"]


def _merge(items: Iterable[tuple[str, Coefficient, float]],
           notes: list[str]) -> dict[str, float]:
    """Sum target values that share a key; note the merges. Keeps first-seen order."""
    values: dict[str, float] = {}
    names: dict[str, list[str]] = {}
    for key, c, v in items:
        values[key] = values.get(key, 0.0) + v
        names.setdefault(key, []).append(c.name)
    for key, ns in names.items():
        if len(ns) > 1:
            notes.append(f"{' + '.join(ns)} share {key}: written as their sum.")
    return values


def _checked(mf: ModelFile, force: bool, source: str | None) -> tuple[list[str], list[str]]:
    """The held-at-prior coefficients (``"name = value (reason)"``) and where the model
    generates energy (:func:`~dampest_ros.core.identified.non_dissipative` over
    :attr:`ModelFile.flown <dampest_ros.io.yaml_io.ModelFile.flown>`).

    Raises
    ------
    NotDissipativeError
        When the model generates energy and ``force`` is False.
    """
    held = [f"{n} = {_num(mf.theta[mf.parameter_names.index(n)])} ({why})"
            for n, why in mf.held.items()]
    model, theta, _ = _model_damping(mf)
    unsafe = non_dissipative(model, theta, mf.flown) if model is not None else []
    if unsafe and not force:
        raise NotDissipativeError(f"{source or 'the model'} is not dissipative: "
                                  f"{'; '.join(unsafe)}; a simulator built from it gains "
                                  "energy and can diverge (fix the model, e.g. identify "
                                  "with --select, or export anyway with --force)")
    return held, unsafe


def _exported(fmt: str, text: str, left_out: Sequence[str], notes: Sequence[str],
              held: Sequence[str], unsafe: Sequence[str]) -> Exported:
    """The result, with an :class:`ExportWarning` for what was left out or held."""
    if left_out:
        warnings.warn(f"{fmt} export left out {len(left_out)} parameter(s): "
                      + "; ".join(left_out), ExportWarning, stacklevel=3)
    if held:
        warnings.warn(f"{fmt} export holds {len(held)} coefficient(s) the data did not "
                      "determine, at their prior: " + "; ".join(held), ExportWarning,
                      stacklevel=3)
    return Exported(fmt, text, tuple(left_out), tuple(notes), tuple(held), tuple(unsafe))


def _comment(lines: Sequence[str]) -> str:
    """Comment text for XML (no ``--`` inside, which XML forbids)."""
    text = "\n".join(f"  {line}" if line else "" for line in lines)
    return "\n" + text.replace("--", "- -") + "\n"


def _header(mf: ModelFile, source: str | None, held: Sequence[str],
            unsafe: Sequence[str]) -> list[str]:
    """The first lines of every export: origin, what is not an estimate, and dissipativity."""
    where = f" from {source}" if source else ""
    lines = [f"Exported by dampest_ros{where} (model version {mf.version}, "
             f"dampest convention {mf.sign_convention}: +D(nu)nu on the left-hand side, FRD)."]
    if unsafe:
        lines += ["NON-DISSIPATIVE, exported on request (force): the model generates energy,",
                  "a simulator built from it can diverge:", *(f"  {x}" for x in unsafe)]
    else:
        lines.append("Dissipative: nu'D(nu)nu >= 0 on a grid over the "
                     + ("flown speeds." if mf.flown is not None else
                        "default speed box (the model file has no flown speeds)."))
    if held:
        lines += ["HELD AT PRIOR (not identified: the data did not determine them; the value",
                  "written is the prior, not an estimate):", *(f"  {x}" for x in held)]
    return lines


# --- gz-sim Hydrodynamics ----------------------------------------------------------------------


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


def _neg(x: float) -> float:
    """−x without producing −0.0."""
    return 0.0 - x


def _check_frame(frame: str) -> str:
    if frame not in FRAMES:
        raise ValueError(f"unknown frame {frame!r}; use one of {FRAMES}")
    return frame


def export_gz(mf: ModelFile, vehicle: Vehicle | None = None, *, link_name: str = "base_link",
              frame: str = "flu", source: str | None = None, force: bool = False) -> Exported:
    """The gz-sim Hydrodynamics plugin element for a model.

    Parameters
    ----------
    mf : ModelFile
    vehicle : Vehicle, optional
        Its rigid body gives the added mass M_A = M − M_RB; without it no ``<iDotJ>`` tags.
    link_name : str
        ``<link_name>`` of the plugin.
    frame : {'flu', 'frd'}
        Frame of that link: ``flu`` (Gazebo/REP-103; coefficients are converted) or ``frd``.
    source : str, optional
        Where the model came from, for the header comment.
    force : bool
        Export a model that is not dissipative (the header says so).

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
    held, unsafe = _checked(mf, force, source)
    model, theta, left_out = _model_damping(mf)
    coefs, other = coefficients(model, theta) if model is not None else ([], [])
    left_out += other
    notes: list[str] = []
    damping = _merge(((_gz_tag(c), c, -_gz_sign(c.row, c.col, _signed_k(c), frame) * c.value)
                      for c in coefs), notes)
    if any(c.kind == "lin" and c.row == c.col == c.k for c in coefs):
        notes.append("Signed diagonal products such as <xUU> mean X*u*u (no abs) in gz-sim; "
                     "gz warns that they may be unstable (gz-sim PR #1888).")
    M_A, mass_notes = _added_mass(mf, vehicle)
    terms = _switches(mf, vehicle)
    switches = {"disable_added_mass": not terms.inertial, "disable_coriolis": not terms.coriolis}
    if terms.coriolis and not terms.munk:
        left_out.append(f"added_mass_terms {terms.as_dict()}: gz-sim cannot drop the Munk "
                        "moments alone (its C_A(nu)nu holds them); written with the Coriolis "
                        "term on, Munk moments included")
    if M_A is not None and terms.coriolis and np.any(M_A[~np.eye(6, dtype=bool)]):
        left_out.append("the off-diagonal M_A entries in C_A(nu)nu: gz-sim builds its Coriolis "
                        "term from the diagonal of M_A only (HydrodynamicsUtils.hh "
                        "buildCoriolisMatrix); they act in M_A nudot only")
    added: dict[str, float] = {}
    if M_A is not None:
        T = np.diag(_FLIP) if frame == "flu" else np.eye(6)
        link = T @ M_A @ T
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
    lines = [*_header(mf, source, held, unsafe),
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
        ET.SubElement(plugin, tag).text = _num(value)
    ET.indent(plugin, "  ")
    text = f"<!--{_comment(lines)}-->\n{ET.tostring(plugin, encoding='unicode')}\n"
    return _exported("gz", text, left_out, mass_notes + notes, held, unsafe)


# --- URDF <hydrodynamics> block ----------------------------------------------------------------


def export_urdf(mf: ModelFile, vehicle: Vehicle | None = None, *,
                source: str | None = None, force: bool = False) -> Exported:
    """The ``<hydrodynamics>`` block (RDML ``hydrodynamics`` / ``auv_controllers`` / ``blue``).

    Parameters
    ----------
    mf : ModelFile
    vehicle : Vehicle, optional
        Adds ``<mass>``, ``<inertia>``, ``<added_mass>`` (M_A = M − M_RB, diagonal),
        ``<weight>``, ``<buoyancy>`` and the centres of gravity and buoyancy.
    source : str, optional
        Where the model came from, for the header comment.
    force : bool
        Export a model that is not dissipative (the header says so).

    Returns
    -------
    Exported
        ``text`` is the block (FRD, SNAME signs), to paste inside ``<robot>``.

    Raises
    ------
    NotDissipativeError
        The model generates energy and ``force`` is False.
    """
    held, unsafe = _checked(mf, force, source)
    model, theta, left_out = _model_damping(mf)
    coefs, other = coefficients(model, theta) if model is not None else ([], [])
    left_out += other
    notes: list[str] = []
    lin: list[tuple[str, Coefficient, float]] = []
    quad: list[tuple[str, Coefficient, float]] = []
    for c in coefs:
        if c.kind == "const" and c.row == c.col:
            lin.append((_URDF_LINEAR[c.row], c, -c.value))
        elif c.kind == "abs" and c.row == c.col == c.k:
            quad.append((_URDF_QUADRATIC[c.row], c, -c.value))
        else:
            left_out.append(f"{c.name} = {_num(c.value)} (off-diagonal or cross coupling: "
                            f"the block holds diagonal damping only)")
    left_out += _switches_left_out(_switches(mf, vehicle), "the block")
    lin_v, quad_v = _merge(lin, notes), _merge(quad, notes)
    for names, values, what in ((_URDF_LINEAR, lin_v, "linear"),
                                (_URDF_QUADRATIC, quad_v, "quadratic")):
        missing = [n for n in names if n not in values]
        if missing:
            notes.append(f"{', '.join(missing)}: no {what} term in the model, written as 0.")
    M_A, mass_notes = _added_mass(mf, vehicle)
    block = ET.Element("hydrodynamics")
    if vehicle is not None and M_A is not None:
        body = vehicle.body
        ET.SubElement(block, "mass").text = _num(body.mass)
        J = body.inertia
        inertia = {"ixx": J[0, 0], "iyy": J[1, 1], "izz": J[2, 2]}
        inertia.update({k: J[a, b] for k, (a, b) in
                        (("ixy", (0, 1)), ("ixz", (0, 2)), ("iyz", (1, 2))) if J[a, b] != 0})
        ET.SubElement(block, "inertia", {k: _num(v) for k, v in inertia.items()})
        ET.SubElement(block, "added_mass",
                      {n: _num(-M_A[i, i]) for i, n in enumerate(_URDF_ADDED)})
        off = [f"M_A[{FORCE_NAMES[i]},{DOF_NAMES[j]}] = {M_A[i, j]:.6g}"
               for i in range(6) for j in range(6) if i != j and M_A[i, j] != 0]
        left_out += [f"{x} (off-diagonal added mass: the block holds the diagonal only)"
                     for x in off]
    ET.SubElement(block, "linear_damping", {n: _num(lin_v.get(n, 0.0)) for n in _URDF_LINEAR})
    ET.SubElement(block, "quadratic_damping",
                  {n: _num(quad_v.get(n, 0.0)) for n in _URDF_QUADRATIC})
    if vehicle is not None:
        body = vehicle.body
        ET.SubElement(block, "weight").text = _num(body.weight)
        ET.SubElement(block, "buoyancy").text = _num(body.buoyancy)
        for tag, r in (("center_of_gravity", body.r_g), ("center_of_buoyancy", body.r_b)):
            ET.SubElement(block, tag, {a: _num(x) for a, x in zip("xyz", r, strict=True)})
    lines = [*_header(mf, source, held, unsafe),
             "Target: <hydrodynamics> block of the Robotic Decision Making Lab 'hydrodynamics'",
             "library (auv_controllers, blue): Fossen FRD body frame (base_link_fsd), SNAME",
             "signs: D(nu) = -diag(linear_damping) - diag(quadratic_damping)|nu| and",
             "M_A = -diag(added_mass), so dissipative values are negative:",
             "X_u = 13.7 -> Xu=\"-13.7\", X_uu = 141 -> Xuu=\"-141\".",
             *mass_notes, *notes]
    if left_out:
        lines += ["LEFT OUT (the block has no place for them):", *(f"  {x}" for x in left_out)]
    ET.indent(block, "  ")
    text = f"<!--{_comment(lines)}-->\n{ET.tostring(block, encoding='unicode')}\n"
    return _exported("urdf", text, left_out, mass_notes + notes, held, unsafe)


# --- UUV Simulator -----------------------------------------------------------------------------


def _yaml_matrix(key: str, A: FloatArray) -> list[str]:
    rows = [", ".join(_num(x) for x in row) for row in np.asarray(A).reshape(6, 6)]
    return [f"  {key}: [", *(f"    {r}{',' if k < 5 else ']'}" for k, r in enumerate(rows))]


def export_uuv(mf: ModelFile, vehicle: Vehicle | None = None, *,
               source: str | None = None, force: bool = False) -> Exported:
    """UUV Simulator ``fossen`` hydrodynamic model as YAML (6×6 row-major matrices, FRD).

    Parameters
    ----------
    mf : ModelFile
    vehicle : Vehicle, optional
        Gives ``added_mass`` (M_A = M − M_RB, positive); without it the key is omitted.
    source : str, optional
        Where the model came from, for the header comment.
    force : bool
        Export a model that is not dissipative (the header says so).

    Returns
    -------
    Exported
        ``text`` is YAML with ``hydrodynamic_model: {type: fossen, …}``.

    Raises
    ------
    NotDissipativeError
        The model generates energy and ``force`` is False.
    """
    held, unsafe = _checked(mf, force, source)
    model, theta, left_out = _model_damping(mf)
    coefs, other = coefficients(model, theta) if model is not None else ([], [])
    left_out += other
    notes: list[str] = []
    lin: list[tuple[str, Coefficient, float]] = []
    quad: list[tuple[str, Coefficient, float]] = []
    fwd: list[tuple[str, Coefficient, float]] = []
    for c in coefs:
        key = f"[{c.row},{c.col}]"
        if c.kind == "const":
            lin.append((f"linear_damping{key}", c, -c.value))
        elif c.kind == "abs" and c.row == c.col == c.k:
            quad.append((f"quadratic_damping{key}", c, -c.value))
        elif c.kind == "lin" and c.k == 0:
            fwd.append((f"linear_damping_forward_speed{key}", c, -c.value))
        else:
            left_out.append(f"{c.name} = {_num(c.value)} (UUV Simulator has quadratic damping "
                            f"on the diagonal only (|nu_i| nu_i) and products with u only)")
    left_out += _switches_left_out(_switches(mf, vehicle), "UUV Simulator")
    mats = {}
    for key, items in (("linear_damping", lin), ("quadratic_damping", quad),
                       ("linear_damping_forward_speed", fwd)):
        A = np.zeros((6, 6))
        for k, v in _merge(items, notes).items():
            i, j = (int(x) for x in k[len(key) + 1:-1].split(","))
            A[i, j] = v
        mats[key] = A
    M_A, mass_notes = _added_mass(mf, vehicle)
    lines = [*_header(mf, source, held, unsafe),
             "Target: UUV Simulator HMFossen (HydrodynamicModel.cc). FRD body frame (the",
             "plugin converts Gazebo's FLU with ToNEDConvention). D = -linear_damping",
             "- u*linear_damping_forward_speed, D_ii += -quadratic_damping_ii |nu_i|, force",
             "-D nu: dissipative entries are negative, e.g. X_u = 13.7 -> -13.7.",
             "added_mass is M_A itself (positive)." if M_A is not None else "",
             *mass_notes, *notes]
    if left_out:
        lines += ["LEFT OUT (no UUV Simulator equivalent):", *(f"  {x}" for x in left_out)]
    out = [f"# {x}".rstrip() for x in lines if x] + ["hydrodynamic_model:", "  type: fossen"]
    if M_A is not None:
        out += _yaml_matrix("added_mass", M_A)
    out += _yaml_matrix("linear_damping", mats["linear_damping"])
    out += _yaml_matrix("quadratic_damping", mats["quadratic_damping"])
    if fwd:
        out += _yaml_matrix("linear_damping_forward_speed", mats["linear_damping_forward_speed"])
    return _exported("uuv", "\n".join(out) + "\n", left_out, mass_notes + notes, held, unsafe)


def export_model(mf: ModelFile, fmt: str, vehicle: Vehicle | None = None, *,
                 link_name: str = "base_link", frame: str = "flu",
                 source: str | None = None, force: bool = False) -> Exported:
    """Export a model in one of :data:`FORMATS`.

    Parameters
    ----------
    mf : ModelFile
    fmt : {'gz', 'urdf', 'uuv'}
    vehicle : Vehicle, optional
        For the added mass M_A = M − M_RB (and, for ``urdf``, the rigid-body entries).
    link_name, frame : str
        ``gz`` only; see :func:`export_gz`.
    source : str, optional
        Where the model came from, for the header comment.
    force : bool
        Export a model that is not dissipative (the header says so).

    Returns
    -------
    Exported

    Raises
    ------
    ValueError
        Unknown format or frame.
    NotDissipativeError
        The model generates energy and ``force`` is False.
    """
    if fmt == "gz":
        return export_gz(mf, vehicle, link_name=link_name, frame=frame, source=source,
                         force=force)
    if fmt == "urdf":
        return export_urdf(mf, vehicle, source=source, force=force)
    if fmt == "uuv":
        return export_uuv(mf, vehicle, source=source, force=force)
    raise ValueError(f"unknown export format {fmt!r}; use one of {FORMATS}")


# --- import ------------------------------------------------------------------------------------


def _parse_xml(source: str | Path) -> tuple[ET.Element, str]:
    """The root element of an XML file or text, and a label for messages."""
    if isinstance(source, Path) or not str(source).lstrip().startswith("<"):
        path = Path(source)
        if not path.is_file():
            raise FileNotFoundError(f"no file {path}")
        text, label = path.read_text(), str(path)
    else:
        text, label = str(source), "XML text"
    try:
        return ET.fromstring(text), label
    except ET.ParseError as exc:
        raise ConfigError(label, f"not valid XML: {exc}") from None


def _float(text: str | None, what: str) -> float:
    try:
        value = float((text or "").strip())
    except ValueError:
        raise ConfigError(what, f"not a number: {text!r} (expand xacro expressions first, "
                                f"e.g. 'xacro model.urdf.xacro > model.urdf')") from None
    if not math.isfinite(value):
        raise ConfigError(what, f"is {value}")
    return value


def _build(fmt: str, lin: dict[str, float], quad: dict[str, float],
           cross: list[dict[str, Any]], added: FloatArray | None, rigid: FloatArray | None,
           notes: list[str]) -> Imported:
    spec: dict[str, Any] = {}
    if lin:
        spec["linear"] = lin
    if quad:
        spec["quadratic"] = quad
    if cross:
        spec["cross"] = cross
    if not spec:
        raise ConfigError(fmt, "no damping coefficient found")
    model, theta = damping_from_spec(spec)
    return Imported(fmt, model.parameter_names, theta, spec, added, rigid, tuple(notes))


def _linear_name(i: int, j: int) -> str:
    return f"{FORCE_NAMES[i]}_{DOF_NAMES[j]}"


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
    root, label = _parse_xml(source)
    plugins = [e for e in root.iter("plugin")
               if e.get("name", "").endswith("systems::Hydrodynamics")
               or "hydrodynamics-system" in e.get("filename", "")]
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
    plugin = plugins[0]
    notes: list[str] = []
    lin: dict[tuple[int, int], float] = {}
    quad: dict[int, float] = {}
    abs_cross: dict[tuple[int, int, int], float] = {}
    lin_cross: dict[tuple[int, int, int], float] = {}
    link_mass = np.zeros((6, 6))
    has_added = False
    F, V = _GZ_FORCE, _GZ_VEL
    disabled: dict[str, bool] = {}
    for el in plugin:
        if not isinstance(el.tag, str):
            continue
        tag = el.tag
        if tag in ("disable_added_mass", "disable_coriolis"):
            disabled[tag] = _bool(el.text, f"<{tag}>")
            continue
        m = re.fullmatch(f"([{F}])(Dot)?([{V}])(?:(abs)?([{V}]))?", tag)
        if m is None:
            if tag not in _GZ_OTHER:
                notes.append(f"<{tag}> ignored (not a Hydrodynamics coefficient).")
            continue
        i, j = F.index(m.group(1)), V.index(m.group(3))
        value = _float(el.text, f"<{tag}>")
        if m.group(2):
            if m.group(5):
                notes.append(f"<{tag}> ignored (not a Hydrodynamics coefficient).")
                continue
            link_mass[i, j] = _neg(value)
            has_added = True
            continue
        if m.group(5) is None:
            lin[(i, j)] = _neg(_gz_sign(i, j, -1, frame) * value)
            continue
        k = V.index(m.group(5))
        if m.group(4):
            coef = _neg(_gz_sign(i, j, -1, frame) * value)
            if i == j == k:
                quad[i] = coef
            else:
                abs_cross[(i, j, k)] = coef
        else:
            lin_cross[(i, j, k)] = _neg(_gz_sign(i, j, k, frame) * value)
            if i == j == k:
                notes.append(f"<{tag}> read as {FORCE_NAMES[i]}*{DOF_NAMES[i]}*{DOF_NAMES[i]}"
                             f" (signed, gz-sim >= 7); files for older gz-sim meant "
                             f"{DOF_NAMES[i]}|{DOF_NAMES[i]}|: use <{tag[:2]}abs{tag[2]}>.")
    lin_spec = {_linear_name(i, i): lin[(i, i)] for i in range(6) if (i, i) in lin}
    lin_spec.update({_linear_name(i, j): v for (i, j), v in sorted(lin.items()) if i != j})
    quad_spec = {f"{FORCE_NAMES[i]}_{DOF_NAMES[i]}{DOF_NAMES[i]}": quad[i]
                 for i in range(6) if i in quad}
    taken = set(lin_spec) | set(quad_spec)
    cross: list[dict[str, Any]] = []
    for (i, j, k), v in sorted(abs_cross.items()):
        name = f"{FORCE_NAMES[i]}_{DOF_NAMES[j]}{DOF_NAMES[k]}"
        taken.add(name)
        cross.append({"row": FORCE_NAMES[i], "col": DOF_NAMES[j],
                      "alpha": f"|{DOF_NAMES[k]}|", "name": name, "value": v})
    for (i, j, k), v in sorted(lin_cross.items()):
        name = f"{FORCE_NAMES[i]}_{DOF_NAMES[j]}{DOF_NAMES[k]}"
        name = f"{name}_lin" if name in taken else name
        cross.append({"row": FORCE_NAMES[i], "col": DOF_NAMES[j], "alpha": DOF_NAMES[k],
                      "name": name, "value": v})
    added = None
    if has_added:
        T = np.diag(_FLIP) if frame == "flu" else np.eye(6)
        added = T @ link_mass @ T
    notes.append(f"Read from link '{(plugin.findtext('link_name') or '').strip()}' as "
                 f"{frame.upper()}.")
    # gz-sim's defaults (no tag): both effects act; its C_A(ν)ν holds the Munk moments
    coriolis = not disabled.get("disable_coriolis", False)
    terms = AddedMassTerms(inertial=not disabled.get("disable_added_mass", False),
                           coriolis=coriolis, munk=coriolis)
    return replace(_build("gz", lin_spec, quad_spec, cross, added, None, notes),
                   added_mass_terms=terms)


def _bool(text: str | None, what: str) -> bool:
    """An SDF boolean (true/false/1/0, any case)."""
    value = (text or "").strip().lower()
    if value not in ("true", "false", "1", "0"):
        raise ConfigError(what, f"must be true or false, got {text!r}")
    return value in ("true", "1")


def _numbers(el: ET.Element, what: str) -> list[float]:
    return [_float(x, what) for x in (el.text or "").split()]


def _diag_or_full(el: ET.Element, keys: Sequence[str], what: str,
                  notes: list[str]) -> FloatArray | None:
    """A 6×6 matrix from attributes (diagonal) or from 6 / 36 numbers of text."""
    attrs = {k: _float(el.get(k), f"<{what} {k}>") for k in keys if el.get(k) is not None}
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
    return _float(el.get("value") if el.get("value") is not None else el.text, what)


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
    root, label = _parse_xml(source)
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
            lin_spec = {_linear_name(i, i): _neg(float(A[i, i])) for i in range(6)
                        if not np.isnan(A[i, i])}
            lin_spec.update({_linear_name(i, j): _neg(float(A[i, j])) for i in range(6)
                             for j in range(6) if i != j and not np.isnan(A[i, j])
                             and A[i, j] != 0})
    quad_el = _first(block, "quadratic_damping", "quadratic")
    if quad_el is not None:
        A = _diag_or_full(quad_el, _URDF_QUADRATIC, quad_el.tag, notes)
        if A is not None:
            quad_spec = {f"{FORCE_NAMES[i]}_{DOF_NAMES[i]}{DOF_NAMES[i]}": _neg(float(A[i, i]))
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
        get = {k: _float(inertia_el.get(k, "0"), f"<inertia {k}>")
               for k in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")}
        inertia = np.array([[get["ixx"], get["ixy"], get["ixz"]],
                            [get["ixy"], get["iyy"], get["iyz"]],
                            [get["ixz"], get["iyz"], get["izz"]]])
        cg_el = _first(block, "center_of_gravity")
        r_g = np.array([_float(cg_el.get(a, "0"), f"<center_of_gravity {a}>") for a in "xyz"]
                       if cg_el is not None else [0.0, 0.0, 0.0])
        rigid = rigid_body_mass(mass, inertia, r_g)
    return _build("urdf", lin_spec, quad_spec, [], added, rigid, notes)


def import_model(source: str | Path, fmt: str, *, frame: str = "flu",
                 link_name: str | None = None) -> Imported:
    """Import a model from one of :data:`IMPORT_FORMATS`.

    Parameters
    ----------
    source : str or Path
        File or XML text.
    fmt : {'gz', 'urdf'}
    frame, link_name
        ``gz`` only; see :func:`import_gz`.

    Returns
    -------
    Imported

    Raises
    ------
    ValueError
        Unknown format.
    """
    if fmt == "gz":
        return import_gz(source, frame=frame, link_name=link_name)
    if fmt == "urdf":
        return import_urdf(source)
    raise ValueError(f"unknown import format {fmt!r}; use one of {IMPORT_FORMATS}")


def imported_mass(imp: Imported, vehicle: Vehicle | None) -> tuple[FloatArray, list[str]]:
    """The mass matrix M = M_RB + M_A of an imported model, and notes on where it came from
    (:func:`imported_mass_parts`)."""
    M_RB, M_A, notes = imported_mass_parts(imp, vehicle)
    return np.asarray(M_RB + M_A, dtype=float), notes


def imported_mass_parts(imp: Imported, vehicle: Vehicle | None
                        ) -> tuple[FloatArray, FloatArray, list[str]]:
    """M_RB and M_A (each (6, 6), FRD) of an imported model, and notes on where they came
    from.

    M_RB comes from ``vehicle`` when given, else from the file; M_A from the file when it has
    added-mass entries, else from ``vehicle``.

    Raises
    ------
    ConfigError
        Neither the file nor a vehicle gives the rigid body.
    """
    notes = []
    if vehicle is not None:
        M_RB = vehicle.body.M_RB
        notes.append(f"M_RB from vehicle {vehicle.name!r}")
    elif imp.rigid_body is not None:
        M_RB = imp.rigid_body
        notes.append("M_RB from the file's mass and inertia")
    else:
        raise ConfigError("vehicle", f"the {imp.format} file has no rigid-body data: give the "
                                     f"vehicle (preset name or YAML) to complete M = M_RB + M_A")
    if imp.added_mass is not None:
        M_A = imp.added_mass
        notes.append("M_A from the file")
    elif vehicle is not None:
        M_A = vehicle.body.added_mass
        notes.append(f"M_A from vehicle {vehicle.name!r} (none in the file)")
    else:
        M_A = np.zeros((6, 6))
        notes.append("M_A = 0 (none in the file)")
    return np.asarray(M_RB, dtype=float), np.asarray(M_A, dtype=float), notes
