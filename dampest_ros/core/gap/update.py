"""The believed model with the effects found applied (:func:`updated_model`) and the
free-run velocity error of both (:func:`free_run_errors`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from dampest_ros.core.gap.data import FORCE_UNITS, GapData, bind
from dampest_ros.core.gap.effects import Effect
from dampest_ros.core.identification.validate import free_run_error, longest_segment
from dampest_ros.core.physics.damping import TERM_KINDS, DampingModel, DampingTerm
from dampest_ros.core.physics.rigid_body import (
    DOF_NAMES,
    FORCE_NAMES,
    AddedMassTerms,
    ConfigError,
    RigidBody,
)
from dampest_ros.core.physics.terms import (
    CrossSpec,
    cross_term,
    linear_term,
    memory_term,
    quadratic_term,
)
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]

# --- the model with the effects ------------------------------------------------------------


@dataclass
class UpdatedModel:
    """The believed model with named effects added (:func:`updated_model`).

    Attributes
    ----------
    model : DampingModel
    theta : ndarray, shape (p',)
    M : ndarray, shape (6, 6)
        M_RB + M_A (kg, kg·m, kg·m²).
    M_A : ndarray, shape (6, 6)
        Its added mass.
    added_mass_terms : AddedMassTerms
        Which effects of M_A act.
    extra : dict
        The effects that are not part of the damping or the mass (current, buoyancy, …).
    """

    model: DampingModel
    theta: FloatArray
    M: FloatArray
    M_A: FloatArray
    added_mass_terms: AddedMassTerms
    extra: dict[str, Any]

    def body(self, data: GapData) -> RigidBody:
        """The believed rigid body with this M_A and these switches (ConfigError when M_A is
        not symmetric positive semi-definite or M not positive definite)."""
        b = data.body
        return RigidBody(b.mass, b.inertia, b.r_g, b.r_b, b.volume, self.M_A, b.rho, b.gravity,
                         self.added_mass_terms)


def _with_bases(old: DampingTerm | None, new: DampingTerm) -> DampingTerm:
    """``old`` (if any) with the bases of ``new`` appended."""
    return DampingTerm(new.kind, (old or new).meaning, (old.bases if old else []) + new.bases)


def updated_model(data: GapData, effects: Sequence[tuple[Effect, FloatArray]]) -> UpdatedModel:
    """The believed model with the named effects added.

    Damping coefficients change θ: a coefficient or cross-coupling the model already has
    (by name, in any of its terms) is updated by the effect's Δ; one it lacks is added to its
    term. Memory becomes a state (a state of the same DOF and rate is updated); added-mass
    errors change M or the added-mass switches; every other effect (current, buoyancy, CG,
    thrusters, delay, sensor bias) is returned in ``extra``.

    Returns
    -------
    UpdatedModel
    """
    values = dict(zip(data.model.parameter_names, data.theta.tolist(), strict=True))
    terms: dict[str, DampingTerm] = {t.kind: t for t in data.model.terms}
    M = data.body.M.copy()
    switches = asdict(data.body.added_mass_terms)
    extra: dict[str, Any] = {}
    freq: dict[tuple[int, float], float] = {}
    old = terms.get("freq")
    if old is not None:
        freq = {(int(d), float(r)): values[n] for d, r, n in
                zip(old.state_dofs, old.rates, old.parameter_names, strict=True)}
    for e, p in effects:
        u = e.model_update(data, p)
        for name, d in u.get("theta", {}).items():
            if name not in values:
                dof = FORCE_NAMES.index(name.split("_")[0])
                quad = name.split("_")[1] == DOF_NAMES[dof] * 2
                kind = "quadratic" if quad else "linear"
                terms[kind] = _with_bases(terms.get(kind), quadratic_term([dof]) if quad
                                          else linear_term([dof]))
            values[name] = values.get(name, 0.0) + float(d)
        for c in u.get("cross", []):
            if c["name"] not in values:
                terms["cross"] = _with_bases(terms.get("cross"),
                                             cross_term([CrossSpec.from_dict(c)]))
            values[c["name"]] = values.get(c["name"], 0.0) + float(c["value"])
        for f in u.get("freq", []):
            key = (DOF_NAMES.index(f["dof"]), float(f["rate"]))
            freq[key] = freq.get(key, 0.0) + float(f["c"])
        if "M" in u:
            M = M + np.asarray(u["M"], dtype=float)
        switches.update(u.get("terms", {}))
        extra.update(u.get("extra", {}))
    if freq:
        rates: dict[str | int, list[float]] = {}
        for d, r in freq:
            rates.setdefault(d, []).append(r)
        mem = memory_term(rates)
        terms["freq"] = mem
        values.update({n: freq[(int(d), float(r))] for n, d, r in
                       zip(mem.parameter_names, mem.state_dofs, mem.rates, strict=True)})
    model = DampingModel([terms[k] for k in TERM_KINDS if k in terms])
    theta = np.array([values.get(n, 0.0) for n in model.parameter_names])
    switches["munk"] = switches["munk"] and switches["coriolis"]
    return UpdatedModel(model, theta, M, M - data.M_RB, AddedMassTerms(**switches), extra)


# --- free run ----------------------------------------------------------------------------------


DOF_WORDS = ("surge", "sway", "heave", "roll", "pitch", "yaw")


def divergence_reason(model: DampingModel, theta: FloatArray, nu: FloatArray,
                      reach: float = 3.0, points: int = 400) -> str:
    """Why a free run of ``model`` can run away: a DOF whose steady damping force stops
    growing with speed.

    Along each DOF axis and sign, the steady force f(s) = ±[D(s e_i) s e_i]_i (memory
    states at their steady value ν/λ) is evaluated from rest to ``reach`` × the largest
    flown speed; where it peaks and then falls, a thrust above the peak has no steady speed.

    Parameters
    ----------
    model : DampingModel
    theta : ndarray, shape (p,)
    nu : ndarray, shape (N, 6)
        Flown velocities (m/s, rad/s).
    reach : float
    points : int

    Returns
    -------
    str
        E.g. ``diverges: Z_ww < 0 leaves no steady heave speed above 62 N``; empty when
        every axis' force grows with speed.
    """
    s = np.linspace(0.0, reach * max(float(np.abs(nu).max()), 1e-3), points)
    rates, dofs = model.memory_rates, model.memory_dofs
    for i in range(6):
        for sign in (1.0, -1.0):
            v = np.zeros((points, 6))
            v[:, i] = sign * s
            z = v[:, dofs] / rates if len(rates) else None
            f = sign * model.force(v, theta, z)[:, i]
            k = int(np.argmax(f))
            if k == points - 1 and f[1] >= 0:
                continue
            Phi = model.regressor(v[-1:], z[-1:] if z is not None else None)[0, i]
            names = [n for n, th, x in zip(model.parameter_names, theta, Phi, strict=True)
                     if th < 0 and x != 0]
            what = " and ".join(names) + " < 0" if names else "the damping"
            return (f"diverges: {what} leaves no steady {DOF_WORDS[i]} speed above "
                    f"{float(f[k]):.3g} {FORCE_UNITS[i]} ({'+' if sign > 0 else '−'}"
                    f"{DOF_NAMES[i]})")
    return ""


def free_run_errors(data: GapData, effects: Sequence[tuple[Effect, FloatArray]],
                    seconds: float = 120.0) -> dict[str, Any] | str:
    """Free-run velocity RMSE of the believed model and of the model with the effects.

    Uses :func:`dampest_ros.core.identification.validate.free_run_error`. The model
    with the effects has the changed damping terms, M and added-mass switches; effects that
    change the applied force (thrust gain, buoyancy, delay, dead-zone) enter as a corrected
    τ. Current, CG offset and sensor biases depend on the state and are not represented in
    the free run. A run that diverges has RMSE inf and a reason (:func:`divergence_reason`).

    Returns
    -------
    dict with ``nominal`` and ``final`` (RMSE per DOF, shape (6,)), ``seconds``,
    ``omitted`` (titles of effects left out) and ``notes`` (model → why its run diverged),
    or a string saying why it was skipped or failed.
    """
    s = data.samples
    rows = longest_segment(s, seconds)
    upd = updated_model(data, effects)
    try:
        body = upd.body(data)
    except ConfigError as exc:
        return f"free run skipped: the corrected mass matrix is invalid ({exc})"
    dtau = np.zeros((len(s), 6))
    omitted = []
    for e, p in effects:
        if e.applied_force:
            # the applied force the vehicle felt: τ − ρ (ρ = what the effect left in r)
            dtau -= data.filtered(bind(e.predict, data, p))
        elif e.model_update(data, p).keys() <= {"extra"}:
            omitted.append(e.title)
    # the filtered correction is applied to the sampled τ (which is not filtered at 2 Hz);
    # the difference is the correction's content above the cutoff, which is small
    fixed = Samples(s.t, s.nu, s.nu_dot, s.tau + dtau, s.euler, s.depth, s.segment)
    runs = {"believed": (s, data.model, data.body, data.theta),
            "with the named effects": (fixed, upd.model, body, upd.theta)}
    rmse: dict[str, FloatArray] = {}
    notes: dict[str, str] = {}
    with np.errstate(all="ignore"):
        for name, (smp, model, b, theta) in runs.items():
            try:
                rmse[name] = np.asarray(free_run_error(smp, model, b, theta, rows)["rmse"],
                                        dtype=float)
            except (ValueError, ArithmeticError, linalg.LinAlgError) as exc:
                return f"free run failed for the {name} model: {exc}"
            if not np.all(np.isfinite(rmse[name])):
                notes[name] = (divergence_reason(model, theta, s.nu[rows])
                               or "diverges (no single degree of freedom explains it)")
    return {"nominal": rmse["believed"], "final": rmse["with the named effects"],
            "seconds": float((rows.stop - rows.start) / s.rate), "omitted": omitted,
            "notes": notes}
