"""What the export formats share: the model as single coefficients, the added mass and its
switches, the file header (origin, held-at-prior list, dissipativity), the refusal of a
non-dissipative model, XML reading, and the mass matrix of an import.
"""

from __future__ import annotations

import math
import re
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dampest_ros.core.identification.identified import non_dissipative
from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.damping import DampingModel, FloatArray
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, AddedMassTerms, ConfigError
from dampest_ros.core.physics.vehicle import Vehicle, damping_from_spec
from dampest_ros.io.yaml_io import SIGN_CONVENTION


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
        One of :data:`~dampest_ros.io.export.FORMATS`.
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
        One of :data:`~dampest_ros.io.export.IMPORT_FORMATS`.
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


def num(x: float) -> str:
    """Shortest text that reads back as the same float; ``0`` for ±0."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot export the non-finite value {x}")
    return "0" if x == 0.0 else repr(x)


def model_damping(mf: Model) -> tuple[DampingModel | None, FloatArray, list[str]]:
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
            unknown.append(f"{name} = {num(value)} (the model file has no model.terms, so "
                           f"its structure is unknown)")
        elif m.group(3):
            if FORCE_NAMES.index(m.group(1)) != DOF_NAMES.index(m.group(2)):
                unknown.append(f"{name} = {num(value)} (not a diagonal quadratic term and "
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
                other.append(f"{name} = {num(c)} (fluid memory with rate {num(lam)} 1/s: "
                             f"the format has no memory states)")
            continue
        for b, v in zip(term.bases, th, strict=True):
            nz = np.argwhere(b.B != 0)
            a = b.alpha
            if b.more:
                other.append(f"{b.name} = {num(v)} (an added-mass correction acting through "
                             "the Coriolis force and Munk moment only, not inertially: the "
                             "format's added mass acts both ways)")
            elif len(nz) == 1 and a.kind in ("one", "abs", "lin"):
                i, j = (int(x) for x in nz[0])
                kind = {"one": "const", "abs": "abs", "lin": "lin"}[a.kind]
                out.append(Coefficient(i, j, kind, a.i if kind != "const" else -1,
                                       float(v) * float(b.B[i, j]), b.name))
            elif a.kind == "absproj":
                w = ", ".join(f"{x:.3g}" for x in a.w)
                other.append(f"{b.name} = {num(v)} (quadratic drag along the mode "
                             f"w = [{w}], force = s |w'nu| w w'nu: not a single coefficient)")
            else:
                other.append(f"{b.name} = {num(v)} (alpha = {a.label() or a.kind}: no such "
                             f"velocity dependence in the format)")
    return out, other


def export_added_mass(mf: Model, vehicle: Vehicle | None
                      ) -> tuple[FloatArray | None, list[str]]:
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


def added_mass_switches(mf: Model, vehicle: Vehicle | None) -> AddedMassTerms:
    """The added-mass switches of the model file, else of the vehicle, else all on."""
    if mf.added_mass_terms is not None:
        return mf.added_mass_terms
    return vehicle.body.added_mass_terms if vehicle is not None else AddedMassTerms()


def switches_left_out(terms: AddedMassTerms, fmt: str) -> list[str]:
    """The left-out line for switches a format without any cannot hold ([] when all on)."""
    if terms.all:
        return []
    off = ", ".join(k for k, v in terms.as_dict().items() if not v)
    return [f"added_mass_terms {terms.as_dict()} (the plant applies no {off} effect of the "
            f"added mass; {fmt} has no switches and applies M_A nudot and C_A(nu)nu whole)"]


def merge(items: Iterable[tuple[str, Coefficient, float]],
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


def checked(mf: Model, force: bool, source: str | None) -> tuple[list[str], list[str]]:
    """The held-at-prior coefficients (``"name = value (reason)"``) and where the model
    generates energy (:func:`~dampest_ros.core.identification.identified.non_dissipative` over
    :attr:`Model.flown <dampest_ros.core.identification.model.Model.flown>`).

    Raises
    ------
    NotDissipativeError
        When the model generates energy and ``force`` is False.
    """
    held = [f"{n} = {num(mf.theta[mf.parameter_names.index(n)])} ({why})"
            for n, why in mf.held.items()]
    model, theta, _ = model_damping(mf)
    unsafe = non_dissipative(model, theta, mf.flown) if model is not None else []
    if unsafe and not force:
        raise NotDissipativeError(f"{source or 'the model'} is not dissipative: "
                                  f"{'; '.join(unsafe)}; a simulator built from it gains "
                                  "energy and can diverge (fix the model, e.g. identify "
                                  "with --select, or export anyway with --force)")
    return held, unsafe


def exported_result(fmt: str, text: str, left_out: Sequence[str], notes: Sequence[str],
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


def xml_comment(lines: Sequence[str]) -> str:
    """Comment text for XML (no ``--`` inside, which XML forbids)."""
    text = "\n".join(f"  {line}" if line else "" for line in lines)
    return "\n" + text.replace("--", "- -") + "\n"


def header_lines(mf: Model, source: str | None, held: Sequence[str],
            unsafe: Sequence[str]) -> list[str]:
    """The first lines of every export: origin, what is not an estimate, and dissipativity."""
    where = f" from {source}" if source else ""
    lines = [f"Exported by dampest_ros{where} (model version {mf.version}, "
             f"dampest convention {SIGN_CONVENTION}: +D(nu)nu on the left-hand side, FRD)."]
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


def neg(x: float) -> float:
    """−x without producing −0.0."""
    return 0.0 - x



# --- reading XML -------------------------------------------------------------------------------


def parse_xml(source: str | Path) -> tuple[ET.Element, str]:
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


def xml_float(text: str | None, what: str) -> float:
    try:
        value = float((text or "").strip())
    except ValueError:
        raise ConfigError(what, f"not a number: {text!r} (expand xacro expressions first, "
                                f"e.g. 'xacro model.urdf.xacro > model.urdf')") from None
    if not math.isfinite(value):
        raise ConfigError(what, f"is {value}")
    return value


def build_imported(fmt: str, lin: dict[str, float], quad: dict[str, float],
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


def linear_name(i: int, j: int) -> str:
    return f"{FORCE_NAMES[i]}_{DOF_NAMES[j]}"


def xml_bool(text: str | None, what: str) -> bool:
    """An SDF boolean (true/false/1/0, any case)."""
    value = (text or "").strip().lower()
    if value not in ("true", "false", "1", "0"):
        raise ConfigError(what, f"must be true or false, got {text!r}")
    return value in ("true", "1")



# --- the mass matrix of an import ---------------------------------------------------------------


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
