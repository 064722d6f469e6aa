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
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from dampest_ros.core.identification.model import Model
from dampest_ros.core.identification.refold import Entry
from dampest_ros.core.identification.refold import refold as refit_onto
from dampest_ros.core.physics.damping import DampingModel, FloatArray
from dampest_ros.core.physics.point_drag import point_spec
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, AddedMassTerms, ConfigError
from dampest_ros.core.physics.vehicle import Vehicle, damping_from_spec
from dampest_ros.io.yaml_io import SIGN_CONVENTION


class ExportWarning(UserWarning):
    """Part of a model could not be written in the target format, or holds values the data did
    not determine (listed in the message)."""


class NotDissipativeError(ValueError):
    """The coefficients a format would write generate energy (νᵀD(ν)ν < 0) at some speed: a
    simulator built from them gains energy there. The message names the coefficient, the
    speed and the choices (clamp, force)."""


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
        Where the written damping turns non-dissipative (only with ``force``; stated in
        the header).
    constrained : dict of str to float
        With ``clamp``: the coefficients set to 0, with the value they had.
    """

    format: str
    text: str
    left_out: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    held: tuple[str, ...] = ()
    non_dissipative: tuple[str, ...] = ()
    constrained: dict[str, float] = field(default_factory=dict)


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
        ``"name = value (reason)"`` for the rest: memory states, residual modes, element
        drags, α = ‖v‖, products.
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
            if term.kind == "point":
                other.append(f"{b.name} = {num(v)} (the {point_spec(b).force} of an element "
                             "at a point of the body on its own velocity v + ω × r, one "
                             "coefficient in a force and its moments: the format has no such "
                             "term)")
            elif b.more:
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
    return [f"added_mass_terms {terms.as_dict()} (the plant applies no {terms.off_text()} "
            f"effect of the added mass; {fmt} has no switches and applies M_A nudot and "
            "C_A(nu)nu whole)"]


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


#: What an export does with a coefficient set that is not dissipative everywhere.
POLICIES = ("refuse", "clamp", "force")


@dataclass(frozen=True)
class Safety:
    """The dissipativity of what an export writes.

    Attributes
    ----------
    policy : str
        One of :data:`POLICIES`.
    turns : list of Turn
        Where the coefficients as estimated turn non-dissipative ([]: they never do).
    changed : dict of str to float
        With ``clamp``: name → the value the clamp replaced by 0.
    """

    policy: str
    turns: list[Turn]
    changed: dict[str, float]


def policy_of(force: bool, clamp: bool) -> str:
    """The policy of the ``force`` and ``clamp`` options (ValueError for both)."""
    if force and clamp:
        raise ValueError("--force and --clamp exclude each other: choose one")
    return "force" if force else "clamp" if clamp else "refuse"


def made_safe(coefs: Sequence[Coefficient], policy: str, fmt: str,
              source: str | None) -> tuple[list[Coefficient], Safety]:
    """The coefficients an export writes, checked for dissipativity at every speed in the
    format's own form (:func:`turns`): refused, clamped (:func:`clamp`) or kept as they
    are (``force``).

    Raises
    ------
    NotDissipativeError
        With ``refuse``, naming the coefficient, the speed where the damping turns and the
        choices.
    """
    if policy not in POLICIES:
        raise ValueError(f"unknown policy {policy!r}; use one of {POLICIES}")
    found = turns(coefs)
    if not found or policy == "force":
        return list(coefs), Safety(policy, found, {})
    if policy == "refuse":
        raise NotDissipativeError(
            f"{source or 'the model'} as {fmt} is not dissipative everywhere: "
            f"{'; '.join(t.text() for t in found)}; a simulator gains energy there. "
            "Export the nearest dissipative model with --clamp (labelled in the file) or "
            "the model as it is with --force (labelled NOT DISSIPATIVE)")
    clamped, changed = clamp(coefs)
    return clamped, Safety(policy, found, changed)


#: The name prefix of a coefficient :func:`refolded` wrote.
REFOLDED = "refold:"


def refolded(mf: Model, model: DampingModel | None, theta: FloatArray,
             written: Sequence[Coefficient], left_out: Sequence[str],
             entries: Sequence[Entry], fmt: str, refold: bool | None
             ) -> tuple[list[Coefficient], list[str], list[str]]:
    """An export's ``refold``: ``written`` with coefficients on the format's ``entries``
    that reproduce, over the model's flown envelope, the force of its static parameters the
    format does not write (:func:`~dampest_ros.core.identification.refold.refold`), each
    added to the written coefficient of its entry if there is one (the simulator sees the
    sum, so the dissipativity check and a clamp judge the sum); ``left_out`` (lines
    ``"name = value (why)"``) without those parameters; and the header lines that say so,
    with the share of their force reproduced per DOF.

    ``refold`` False leaves everything as it is; None (the default of every export) does the
    same, with a line saying so, for a model file that records no flown speeds (the
    envelope to refold over); True refuses such a file.

    Raises
    ------
    ConfigError
        ``refold`` True and the model file records no flown speeds.
    """
    placed = {c.name for c in written}
    which = np.array([] if model is None else
                     [b.name not in placed and not b.more and term.kind != "freq"
                      for term in model.terms for b in term.bases], dtype=bool)
    if refold is False or model is None or not which.any():
        return list(written), list(left_out), []
    flown = mf.flown
    if flown is None:
        if refold:
            raise ConfigError("--refold", "the model file records no flown speeds "
                                          "(extra.flown_speeds), the envelope to refold "
                                          "over: identify it again with this version")
        return list(written), list(left_out), [
            f"Not refolded: the model file records no flown speeds, so the terms {fmt} "
            "cannot carry are left out (listed below)."]
    r = refit_onto(model, theta, which, flown, entries)
    out = list(written)
    for (i, j, k), v in zip(r.entries, r.values, strict=True):
        kind = "const" if k < 0 else "abs"
        at = next((n for n, c in enumerate(out) if (c.row, c.col, c.kind, c.k) == (i, j, kind, k)),
                  None)
        name = f"{REFOLDED}{FORCE_NAMES[i]}_{DOF_NAMES[j]}" + (f"|{DOF_NAMES[k]}|" if k >= 0
                                                                else "")
        if at is None:
            out.append(Coefficient(i, j, kind, k, float(v), name))
        else:
            c = out[at]
            out[at] = replace(c, value=c.value + float(v), name=f"{c.name} + {name}")
    names = [n for n, w in zip(model.parameter_names, which, strict=True) if w]
    share = " ".join("-" if not np.isfinite(x) else f"{x:.4f}" for x in r.share)
    lines = [f"REFOLDED: {', '.join(names)}, which {fmt} cannot carry, are written as "
             f"{len(r.entries)} {fmt} coefficients ({REFOLDED}..., added to the model's own "
             "where they share one) fitted by least squares to their force over the flown "
             "envelope (5^6 velocities between the flown minima and maxima, and at 1/2, 1/4 "
             "and 1/10 of that size): an approximation, not an estimate. Share of their force "
             f"reproduced per DOF X Y Z K M N: {share}; RMS of what is missed: "
             + " ".join(f"{x:.3g}" for x in r.rms) + " N, N m."]
    return out, [line for line in left_out if line.split(" = ", 1)[0] not in names], lines


def label(mf: Model, name: str, safety: Safety) -> str:
    """``estimate``, ``constrained (was …)``, ``held at prior`` or ``refolded``: what a
    written coefficient's value is."""
    if name in safety.changed:
        return f"constrained (was {num(safety.changed[name])})"
    if name.startswith(REFOLDED):
        return "refolded (an approximation, see above)"
    if f" + {REFOLDED}" in name:
        return f"{label(mf, name.split(' + ')[0], safety)} + refolded (see above)"
    why = mf.held.get(name, "")
    was = re.search(r"unconstrained \S+ = (\S+)", why)
    if was is not None:
        return f"constrained (was {was.group(1)})"
    return "held at prior" if "prior" in why else "estimate"


def held_at_prior(mf: Model) -> list[str]:
    """``"name = value (reason)"`` of the coefficients whose value is their prior."""
    return [f"{n} = {num(mf.theta[mf.parameter_names.index(n)])} ({why})"
            for n, why in mf.held.items() if "prior" in why and "unconstrained" not in why]


def exported_result(fmt: str, text: str, left_out: Sequence[str], notes: Sequence[str],
                    held: Sequence[str], safety: Safety) -> Exported:
    """The result, with an :class:`ExportWarning` for what was left out or held."""
    if left_out:
        warnings.warn(f"{fmt} export left out {len(left_out)} parameter(s): "
                      + "; ".join(left_out), ExportWarning, stacklevel=3)
    if held:
        warnings.warn(f"{fmt} export holds {len(held)} coefficient(s) the data did not "
                      "determine, at their prior: " + "; ".join(held), ExportWarning,
                      stacklevel=3)
    unsafe = () if safety.changed else tuple(t.text() for t in safety.turns)
    return Exported(fmt, text, tuple(left_out), tuple(notes), tuple(held), unsafe,
                    dict(safety.changed))


def xml_comment(lines: Sequence[str]) -> str:
    """Comment text for XML (no ``--`` inside, which XML forbids)."""
    text = "\n".join(f"  {line}" if line else "" for line in lines)
    return "\n" + text.replace("--", "- -") + "\n"


def header_lines(mf: Model, source: str | None, written: Sequence[Coefficient],
                 safety: Safety) -> list[str]:
    """The first lines of every export: origin and vehicle, dissipativity, and each written
    coefficient's label (:func:`label`)."""
    where = f" from {source}" if source else ""
    owner = (f"vehicle {mf.identity.label()}" if mf.identity is not None else
             "no vehicle identity in the model file")
    lines = [f"Exported by dampest_ros{where} (model version {mf.version}, {owner}, "
             f"dampest convention {SIGN_CONVENTION}: +D(nu)nu on the left-hand side, FRD)."]
    found = safety.turns
    if not found:
        lines.append("Dissipative at every speed in this format's form (per DOF linear >= 0 "
                     "and quadratic >= 0; couplings checked on nu directions).")
    elif safety.changed:
        lines += ["CONSTRAINED to the nearest dissipative model (clamp); as estimated:",
                  *(f"  {t.text()};" for t in found),
                  "  changed: " + ", ".join(f"{n} = 0 (was {num(v)})"
                                            for n, v in safety.changed.items())]
    else:
        lines += [f"NOT DISSIPATIVE beyond |nu| = {found[0].speed:.3g}; as written:",
                  *(f"  {t.text()};" for t in found),
                  "  written as is on request (force): a simulator gains energy there."]
    if written:
        lines.append("Coefficients (dampest names and values; estimate = the data's, "
                     "held at prior = not determined by the data):")
        lines += [f"  {c.name} = {num(c.value)}: {label(mf, c.name, safety)}"
                  for c in written]
    return lines


def neg(x: float) -> float:
    """−x without producing −0.0."""
    return 0.0 - x



# --- dissipative everywhere ---------------------------------------------------------------------

#: Unit directions the cubic part of the power is checked on (axes, pairs, seeded sphere).
_N_DIRECTIONS = 4096


@dataclass(frozen=True)
class Turn:
    """Where a written coefficient set stops being dissipative.

    Attributes
    ----------
    name : str
        The coefficient with the most negative share of νᵀD(ν)ν there.
    speed : float
        |ν| (m/s, rad/s mixed as in ν) beyond which the power is negative along ``direction``
        (0: near rest, a negative linear part).
    direction : ndarray, shape (6,)
        Unit ν direction (FRD).
    """

    name: str
    speed: float
    direction: FloatArray

    def text(self) -> str:
        where = ", ".join(f"{DOF_NAMES[i]} {x:+.2f}" for i, x in enumerate(self.direction)
                          if abs(x) > 0.005)
        at = (f"beyond |nu| = {self.speed:.3g}" if self.speed > 0 else "near rest")
        return f"{self.name}: the damping turns non-dissipative {at} along ({where})"


def _directions() -> FloatArray:
    """Unit ν directions, shape (n, 6): ±axes, ±pairs of axes, then seeded random ones."""
    eye = np.eye(6)
    pairs = [s * eye[i] + t * eye[j] for i in range(6) for j in range(i + 1, 6)
             for s in (1, -1) for t in (1, -1)]
    rand = np.random.default_rng(0).standard_normal((_N_DIRECTIONS, 6))
    d = np.vstack([eye, -eye, np.array(pairs), rand])
    return np.asarray(d / np.linalg.norm(d, axis=1, keepdims=True))


def _shares(coefs: Sequence[Coefficient], d: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Per coefficient its share of the power along unit directions ``d`` (n, 6): the
    ν-independent part (of |ν|², linear terms) and the part of |ν|³, each shape (n, c)."""
    two = np.zeros((len(d), len(coefs)))
    three = np.zeros((len(d), len(coefs)))
    for m, c in enumerate(coefs):
        base = c.value * d[:, c.row] * d[:, c.col]
        if c.kind == "const":
            two[:, m] = base
        else:
            three[:, m] = base * (np.abs(d[:, c.k]) if c.kind == "abs" else d[:, c.k])
    return two, three


def turns(coefs: Sequence[Coefficient]) -> list[Turn]:
    """Where the damping force Σ c·α(ν)·ν_col on each row stops dissipating, at any speed:
    one :class:`Turn` per coefficient blamed, the lowest speed first ([] when dissipative
    everywhere).

    The power is P(sd) = s² L(d) + s³ Q(d) along a unit direction d (L from the constant
    coefficients, Q from those with α = |ν_k| or ν_k). It is ≥ 0 for every s > 0 iff
    L(d) ≥ 0 and Q(d) ≥ 0; where Q(d) < 0 it turns at s = L(d)/−Q(d), where L(d) < 0 near
    rest. Exact on the axes (the diagonal form: per DOF linear ≥ 0 and quadratic ≥ 0) and
    on pairs of axes, checked on seeded directions elsewhere. The coefficient blamed in a
    direction is the one with the most negative share of the part that is negative.
    """
    if not coefs:
        return []
    d = _directions()
    two, three = _shares(coefs, d)
    L, Q = two.sum(axis=1), three.sum(axis=1)
    tol = 1e-12 * max(1.0, float(np.abs(two).max()), float(np.abs(three).max()))
    bad = np.flatnonzero((L < -tol) | (Q < -tol))
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = np.where(L < -tol, 0.0, np.maximum(L, 0.0) / -np.minimum(Q, -tol))
    found: dict[str, Turn] = {}
    for n in bad[np.argsort(speed[bad], kind="stable")]:
        name = coefs[int(np.argmin(two[n] if L[n] < -tol else three[n]))].name
        found.setdefault(name, Turn(name, float(speed[n]), d[n]))
    return list(found.values())


def clamp(coefs: Sequence[Coefficient]) -> tuple[list[Coefficient], dict[str, float]]:
    """The nearest dissipative set: the coefficient :func:`turns` blames first set to 0, until
    none turns. For the diagonal form this is the projection onto linear ≥ 0 and quadratic
    ≥ 0 per DOF; a cross coupling that makes the power negative is dropped.

    Returns
    -------
    coefs : list of Coefficient
        The clamped set (same order).
    changed : dict of str to float
        Name → the value it had.
    """
    out = list(coefs)
    changed: dict[str, float] = {}
    while found := turns(out):
        for m, c in enumerate(out):
            if c.name == found[0].name:
                changed.setdefault(c.name, c.value)
                out[m] = replace(c, value=0.0)
    return out, changed


# --- reading XML -------------------------------------------------------------------------------


def parse_xml(source: str | Path) -> tuple[ET.Element, str]:
    """The root element of an XML file or text, and a label for messages (a binary file is
    refused as XML that is not valid, naming the file)."""
    text: str | bytes
    if isinstance(source, Path) or not str(source).lstrip().startswith("<"):
        path = Path(source)
        if path.is_dir():
            raise IsADirectoryError(f"{path} is a directory; give the SDF, URDF or XML file "
                                    "that holds the hydrodynamics")
        if not path.is_file():
            raise FileNotFoundError(f"no file {path}")
        text, label = path.read_bytes(), str(path)  # the parser decodes as the file says
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


@dataclass
class CoefficientTables:
    """The coefficients read from a simulator file, in FRD and dampest signs (dissipative
    > 0), indices 0..5 = force X..N (i) and velocity u..r (j, k).

    Attributes
    ----------
    lin : dict (i, j) → float
        Coefficient of ν_j in force i (gz ``<iJ>``, UUV ``linear_damping``).
    quad : dict i → float
        Coefficient of ν_i |ν_i| (gz ``<iIabsI>``, UUV diagonal ``quadratic_damping``).
    abs_cross : dict (i, j, k) → float
        Other coefficients of ν_j |ν_k| (gz ``<iJabsK>``).
    lin_cross : dict (i, j, k) → float
        Coefficients of ν_j ν_k (gz ``<iJK>``, UUV ``linear_damping_forward_speed`` with
        k = 0).
    link_mass : ndarray, shape (6, 6)
        M_A (positive) in the file's link frame (kg, kg·m, kg·m²); meaningful when
        ``has_added``.
    has_added : bool
        Whether the file gives any added mass.
    disabled : dict of str to bool
        gz ``<disable_added_mass>`` and ``<disable_coriolis>``, where given.
    notes : list of str
        What was ignored or interpreted.
    """

    lin: dict[tuple[int, int], float] = field(default_factory=dict)
    quad: dict[int, float] = field(default_factory=dict)
    abs_cross: dict[tuple[int, int, int], float] = field(default_factory=dict)
    lin_cross: dict[tuple[int, int, int], float] = field(default_factory=dict)
    link_mass: FloatArray = field(default_factory=lambda: np.zeros((6, 6)))
    has_added: bool = False
    disabled: dict[str, bool] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


def damping_spec(tags: CoefficientTables) -> tuple[dict[str, float], dict[str, float],
                                           list[dict[str, Any]]]:
    """The ``linear``, ``quadratic`` and ``cross`` sections of a damping spec for the
    coefficients of ``tags``: diagonal linear terms first, then the off-diagonal ones; cross
    terms named ``Y_vr`` (``Y_vr_lin`` for a signed ν_k when an |ν_k| term has that name)."""
    lin = tags.lin
    lin_spec = {linear_name(i, i): lin[(i, i)] for i in range(6) if (i, i) in lin}
    lin_spec.update({linear_name(i, j): v for (i, j), v in sorted(lin.items()) if i != j})
    quad_spec = {f"{FORCE_NAMES[i]}_{DOF_NAMES[i]}{DOF_NAMES[i]}": tags.quad[i]
                 for i in range(6) if i in tags.quad}
    taken = set(lin_spec) | set(quad_spec)
    cross: list[dict[str, Any]] = []
    for (i, j, k), v in sorted(tags.abs_cross.items()):
        name = f"{FORCE_NAMES[i]}_{DOF_NAMES[j]}{DOF_NAMES[k]}"
        taken.add(name)
        cross.append({"row": FORCE_NAMES[i], "col": DOF_NAMES[j],
                      "alpha": f"|{DOF_NAMES[k]}|", "name": name, "value": v})
    for (i, j, k), v in sorted(tags.lin_cross.items()):
        name = f"{FORCE_NAMES[i]}_{DOF_NAMES[j]}{DOF_NAMES[k]}"
        name = f"{name}_lin" if name in taken else name
        cross.append({"row": FORCE_NAMES[i], "col": DOF_NAMES[j], "alpha": DOF_NAMES[k],
                      "name": name, "value": v})
    return lin_spec, quad_spec, cross


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
