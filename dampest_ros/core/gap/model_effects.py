"""Candidate effects in the model itself: an added-mass error (scale or per DOF), a missing
linear or quadratic damping coefficient, a cross-coupling term and fluid memory."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.gap.data import Chunk, GapData
from dampest_ros.core.gap.effects import Effect, LinearEffect
from dampest_ros.core.physics.damping import DampingModel, filter_memory
from dampest_ros.core.physics.rigid_body import (
    DOF_NAMES,
    FORCE_NAMES,
    AddedMassTerms,
    ConfigError,
    added_coriolis_force,
)
from dampest_ros.core.physics.terms import CrossSpec, cross_term

FloatArray = NDArray[np.float64]

#: Ways an added-mass error can act: as the vehicle's switches say, or through one term only
ADDED_MASS_FORMS = ("acting", "inertial", "coriolis")


def _form_terms(terms: AddedMassTerms, form: str) -> AddedMassTerms:
    """The added-mass switches of a candidate's ``form`` on a vehicle with ``terms``.

    ``acting``: the vehicle's; ``inertial``: M_A ν̇ only; ``coriolis``: C_A(ν)ν only, with
    the vehicle's zeroed entries (Munk, ``coriolis_zero``) when its Coriolis term acts, else
    the whole C_A (as gz-sim applies it).
    """
    if form == "acting":
        return terms
    if form == "inertial":
        return AddedMassTerms(inertial=True, coriolis=False, munk=False)
    return replace(terms, inertial=False) if terms.coriolis else AddedMassTerms(inertial=False)


def _added_mass_force(M_A: FloatArray, terms: AddedMassTerms, ch: Chunk) -> FloatArray:
    """M_A ν̇ (if ``terms.inertial``) + the acting part of C_A(ν)ν, shape (n, 6)."""
    out = added_coriolis_force(M_A, terms, ch.nu)
    if terms.inertial:
        out = out + ch.nu_dot @ M_A.T
    return np.asarray(out, dtype=float)


def _form_available(terms: AddedMassTerms, form: str, acting_key: str) -> str:
    """Why an added-mass ``form`` is not a separate candidate on a vehicle with ``terms``."""
    t = _form_terms(terms, form)
    if not (t.inertial or t.coriolis):
        return "the vehicle's added-mass switches turn every added-mass effect off"
    if form != "acting" and t == terms:
        return f"the same as {acting_key} under the vehicle's added-mass switches"
    return ""


class AddedMassScale(LinearEffect):
    """M_A scaled by (1 + ε) in the terms of ``form``: ρ = ε × (those terms of M_A).

    ``acting``: the terms the vehicle's ``added_mass_terms`` switch on (M_A changes);
    ``inertial``: ε M_A ν̇ only; ``coriolis``: ε C_A(ν)ν only. The model file has one M_A for
    all its terms, so a one-term form is written as the nearest switch: the term acts
    (factor [on] + ε ≥ ½) or not; the factor itself is kept under ``model.gap``. A plant
    without the inertial term analysed with a model that has it shows ε ≈ −1 in the
    inertial form (MuJoCo's fluid model, gz-sim's ``disable_added_mass``).
    """

    family = "added_mass"
    params = ("epsilon",)
    units = ("",)
    steps = (0.02,)

    def __init__(self, form: str = "acting") -> None:
        if form not in ADDED_MASS_FORMS:
            raise ConfigError("form", f"unknown added-mass form {form!r}; use one of "
                              f"{ADDED_MASS_FORMS}")
        self.form = form
        self.key = "added_mass_scale" if form == "acting" else f"added_mass_{form}"
        self.title = {"acting": "added-mass error (all of M_A scaled)",
                      "inertial": "inertial added-mass error (M_A ν̇ scaled, C_A(ν)ν not)",
                      "coriolis": "added-mass Coriolis error (C_A(ν)ν scaled, M_A ν̇ not)",
                      }[form]

    def available(self, data: GapData) -> str:
        if not np.any(data.M_A):
            return "the model has no added mass to scale"
        return _form_available(data.body.added_mass_terms, self.form, "added_mass_scale")

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        t = _form_terms(data.body.added_mass_terms, self.form)
        return _added_mass_force(data.M_A, t, ch)[:, :, None]

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        what = {"acting": "M_A", "inertial": "M_A ν̇", "coriolis": "C_A(ν)ν"}[self.form]
        return (f"ε = {100 * float(p[0]):+.2f} ± {100 * float(np.sqrt(abs(cov[0, 0]))):.2g} % "
                f"of {what}")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        if self.form == "acting":
            return {"M": float(p[0]) * data.M_A}
        terms = data.body.added_mass_terms
        factor = float(getattr(terms, self.form)) + float(p[0])
        on = factor >= 0.5
        switch: dict[str, Any] = {self.form: on}
        if self.form == "coriolis":
            switch["munk"] = on and (terms.munk or not terms.coriolis)
            switch["coriolis_zero"] = terms.coriolis_zero if on else ()
        return {"terms": switch, "extra": {f"added_mass_{self.form}_factor": factor}}


class AddedMassDof(LinearEffect):
    """Added mass of one DOF wrong by Δm (kg or kg·m²), acting as the vehicle's switches say:
    ρ = Δm e_i ν̇_i (if inertial) + the acting part of C(Δm E_ii, ν)ν."""

    family = "added_mass"
    units = ("kg",)

    def __init__(self, dof: int) -> None:
        self.dof = dof
        n = DOF_NAMES[dof]
        self.key = f"added_mass.{n}"
        self.params = (f"{FORCE_NAMES[dof]}_{n}dot",)
        self.title = f"added-mass error in {n} ({self.params[0]}, ∝ {n}̇)"
        self.units = ("kg",) if dof < 3 else ("kg·m²",)
        self.steps = (0.5,) if dof < 3 else (0.01,)
        self.dofs = (dof,)

    def available(self, data: GapData) -> str:
        return _form_available(data.body.added_mass_terms, "acting", self.key)

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        E = np.zeros((6, 6))
        E[self.dof, self.dof] = 1.0
        return _added_mass_force(E, data.body.added_mass_terms, ch)[:, :, None]

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        return (f"Δ{self.params[0]} = {float(p[0]):+.4g} ± {float(np.sqrt(abs(cov[0, 0]))):.2g} "
                f"{self.units[0]}")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        E = np.zeros((6, 6))
        E[self.dof, self.dof] = float(p[0])
        return {"M": E}


class Coefficient(LinearEffect):
    """A damping coefficient of one DOF missing or wrong: linear (ν_i) or quadratic (|ν_i|ν_i).

    ρ = Δθ α(ν) ν_i e_i with α = 1 (e.g. X_u) or |ν_i| (e.g. X_uu).
    """

    family = "damping"

    def __init__(self, dof: int, quadratic: bool) -> None:
        self.dof = dof
        self.quadratic = quadratic
        n = DOF_NAMES[dof]
        self.name = f"{FORCE_NAMES[dof]}_{n}{n}" if quadratic else f"{FORCE_NAMES[dof]}_{n}"
        self.key = ("quadratic." if quadratic else "linear.") + self.name
        self.params = (self.name,)
        self.title = (f"{'quadratic' if quadratic else 'linear'} damping in {n} "
                      f"({self.name}, force ∝ {n + '|' + n + '|' if quadratic else n})")
        lin = dof < 3
        self.units = ((("N·s²/m²" if lin else "N·m·s²") if quadratic else
                       ("N·s/m" if lin else "N·m·s")),)
        self.steps = (1.0,) if lin else (0.05,)
        self.dofs = (dof,)

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        x = np.zeros((len(ch), 6, 1))
        v = ch.nu[:, self.dof]
        x[:, self.dof, 0] = np.abs(v) * v if self.quadratic else v
        return x

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        return (f"Δ{self.name} = {float(p[0]):+.4g} ± {float(np.sqrt(abs(cov[0, 0]))):.2g} "
                f"{self.units[0]}")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"theta": {self.name: float(p[0])}}


class Cross(LinearEffect):
    """A cross-coupling damping coefficient, e.g. sway–yaw Y_v|r|: ρ = θ α(ν) ν_col e_row."""

    family = "damping"
    units = ("SI",)

    def __init__(self, spec: CrossSpec) -> None:
        self.spec = spec
        self._model = DampingModel([cross_term([spec])])
        self.key = f"cross.{spec.label}"
        self.params = (spec.label,)
        a = spec.alpha.label()
        self.title = (f"cross-coupling {spec.label} ({FORCE_NAMES[spec.row]} force ∝ "
                      f"{DOF_NAMES[spec.col]}{'' if a == '1' else '·' + a})")
        self.steps = (1.0,) if spec.row < 3 else (0.1,)
        self.dofs = (spec.row,)

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        return self._model.regressor(ch.nu)

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        return f"{self.spec.label} = {float(p[0]):+.4g} ± {float(np.sqrt(abs(cov[0, 0]))):.2g}"

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        s = self.spec
        return {"cross": [{"row": FORCE_NAMES[s.row], "col": DOF_NAMES[s.col],
                           "alpha": s.alpha.label(), "name": s.label, "value": float(p[0])}]}


class Memory(Effect):
    """Fluid memory in one DOF: K(t) = c e^{−λt}, ρ = c z e_i with ż = −λ z + ν_i.

    The states run over whole segments (from z = 0 at each segment start).
    """

    family = "memory"
    grid = (0.15, 0.3, 0.6, 1.2, 2.4, 4.8, 9.6)
    magnitudes = (0,)  # c; λ only shapes the kernel

    def __init__(self, dof: int) -> None:
        self.dof = dof
        n = DOF_NAMES[dof]
        self.key = f"memory.{n}"
        self.params = ("c", "lambda")
        self.title = f"fluid memory in {n} (force ∝ ν filtered by e^(−λt))"
        self.units = ("N/m" if dof < 3 else "N·m", "1/s")
        self.steps = (0.5 if dof < 3 else 0.05, 0.05)
        self.dofs = (dof,)

    def implausible(self, data: GapData, p: FloatArray) -> str:
        # the regression sees ν low-passed at the cutoff f_c: a kernel faster than
        # 2π f_c / 2 is indistinguishable from linear damping, one slower than the grid is a
        # trend or an offset
        fast = np.pi * data.cutoff if data.cutoff > 0 else 0.5 * np.pi * data.rate
        if float(p[1]) >= fast:
            return (f"λ = {float(p[1]):.3g} 1/s is faster than the regression resolves "
                    f"({fast:.3g} 1/s): that is linear damping, not memory")
        if float(p[1]) <= 1.05 * self.grid[0] / 2:
            return f"λ = {float(p[1]):.3g} 1/s: a trend or an offset, not memory"
        return ""

    def states(self, data: GapData, lam: float) -> FloatArray:
        """z for every sample at rate λ, shape (N,) (cached)."""
        def make() -> FloatArray:
            s = data.samples
            z = np.zeros(len(s))
            for sl in s.segments():
                z[sl] = filter_memory(s.t[sl], s.nu[sl, self.dof:self.dof + 1],
                                      np.array([lam]))[:, 0]
            return z

        out: FloatArray = data.memo(("memory", self.dof, round(float(lam), 9)), make)
        return out

    def starts(self, data: GapData) -> list[FloatArray]:
        return [np.array([0.0, lam]) for lam in self.grid]

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        return np.array([-np.inf, 0.05]), np.array([np.inf, 20.0])

    def predict(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        out = np.zeros((len(ch), 6))
        out[:, self.dof] = float(p[0]) * self.states(data, float(p[1]))[ch.rows]
        return out

    def columns(self, data: GapData, ch: Chunk, p: FloatArray) -> FloatArray:
        out = np.zeros((len(ch), 6, 2))
        lam, h = float(p[1]), self.steps[1] * float(p[1])
        out[:, self.dof, 0] = self.states(data, lam)[ch.rows]
        dz = (self.states(data, lam + h) - self.states(data, lam - h))[ch.rows] / (2 * h)
        out[:, self.dof, 1] = float(p[0]) * dz
        return out

    def describe(self, p: FloatArray, cov: FloatArray) -> str:
        s = np.sqrt(np.abs(np.diag(cov)))
        return (f"c = {float(p[0]):.4g} ± {s[0]:.2g} {self.units[0]}, λ = {float(p[1]):.3g} ± "
                f"{s[1]:.2g} 1/s (steady gain c/λ = {float(p[0] / p[1]):.3g})")

    def model_update(self, data: GapData, p: FloatArray) -> dict[str, Any]:
        return {"freq": [{"dof": DOF_NAMES[self.dof], "rate": float(p[1]), "c": float(p[0])}]}
