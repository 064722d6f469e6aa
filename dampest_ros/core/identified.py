"""An identified damping model as controllers use it: D(ν), the damping force and its
uncertainty, and C(ν)ν from the mass matrix with the added-mass switches of the plant (FRD body
frame, SI units).

Two checks every reader of a model shares: :func:`check_model_numbers` (θ, M and the σ of the
identified coefficients finite) and :func:`non_dissipative` (νᵀD(ν)ν ≥ 0 over a grid of the
speed envelope, memory gains ≥ 0). A model says per coefficient whether the data determined it
(``held``: name → why it stayed at its prior; :attr:`IdentifiedModel.identified`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.damping import DampingModel
from dampest_ros.core.dissipative import envelope, power_rows
from dampest_ros.core.rigid_body import (
    DOF_NAMES,
    FORCE_NAMES,
    AddedMassTerms,
    ConfigError,
    split_coriolis_force,
)
from dampest_ros.core.vehicle import damping_from_spec

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Speeds (m/s, rad/s) whose box ±v :func:`non_dissipative` checks when a model carries no
#: flown speeds (``model.flown_speeds``).
DEFAULT_ENVELOPE = (2.0, 2.0, 2.0, 1.0, 1.0, 1.0)


def damping_from_names(names: Sequence[str]) -> DampingModel:
    """Rebuild a damping model from SNAME names alone (linear ``X_u``, ``Y_r``; quadratic
    ``X_uu`` … ``N_rr``), for model files written without ``model.terms``."""
    linear: dict[str, float] = {}
    quadratic: dict[str, float] = {}
    for n in names:
        force, _, vel = n.partition("_")
        if force in FORCE_NAMES and len(vel) == 2 and vel[0] == vel[1] and vel[0] in DOF_NAMES:
            quadratic[n] = 0.0
        elif force in FORCE_NAMES and vel in DOF_NAMES:
            linear[n] = 0.0
        else:
            raise ConfigError("model.parameter_names",
                              f"{n!r} needs model.terms to be rebuilt (not linear/quadratic)")
    spec: dict[str, dict[str, float]] = {}
    if linear:
        spec["linear"] = linear
    if quadratic:
        spec["quadratic"] = quadratic
    model, _ = damping_from_spec(spec)
    if model.parameter_names != list(names):
        raise ConfigError("model.parameter_names", "order must be linear terms, then quadratic")
    return model


def identified_mask(names: Sequence[str], held: Mapping[str, str]) -> BoolArray:
    """Per coefficient, True when the data determined it (its name is not in ``held``)."""
    return np.array([n not in held for n in names], dtype=bool)


def check_model_numbers(names: Sequence[str], theta: FloatArray, theta_std: FloatArray,
                        M: FloatArray, held: Mapping[str, str] | None = None,
                        where: str = "") -> None:
    """Refuse a model whose numbers no controller or simulator can use.

    θ and every entry of M must be finite; σ must be finite for each identified
    coefficient (one in ``held`` stayed at its prior: its σ may be NaN, not estimated);
    ``held`` names parameters of the model.

    Parameters
    ----------
    names : sequence of str
        Parameter names, θ order.
    theta, theta_std : ndarray, shape (p,)
    M : ndarray, 36 entries
    held : mapping of str to str, optional
        The coefficients held at their prior, with the reason.
    where : str
        Appended to the message (e.g. `` (in model.yaml)``).

    Raises
    ------
    ConfigError
        Naming the entry and its value, e.g. ``model.theta: Z_ww = nan (in m.yaml)``.
    """
    theta = np.asarray(theta, dtype=float)
    std = np.asarray(theta_std, dtype=float)
    M = np.asarray(M, dtype=float).reshape(-1)
    unknown = sorted(set(held or {}) - set(names))
    if unknown:
        raise ConfigError("model.held", f"names no parameter of the model: {unknown}{where}")
    bad = [f"{n} = {v}" for n, v in zip(names, theta, strict=True) if not np.isfinite(v)]
    if bad:
        raise ConfigError("model.theta", f"not finite: {', '.join(bad)}{where}")
    mask = identified_mask(names, held or {})
    bad = [f"{n} = {v}" for n, v, ok in zip(names, std, mask, strict=True)
           if ok and not np.isfinite(v)]
    if bad:
        raise ConfigError("model.theta_std", f"not finite for an identified coefficient: "
                                             f"{', '.join(bad)}{where}")
    bad = [f"M[{FORCE_NAMES[k // 6]},{DOF_NAMES[k % 6]}] = {v}" for k, v in enumerate(M)
           if not np.isfinite(v)]
    if bad:
        raise ConfigError("model.M", f"not finite: {', '.join(bad)}{where}")


def non_dissipative(model: DampingModel, theta: FloatArray,
                    flown: FloatArray | None = None) -> list[str]:
    """Where a damping model generates energy, in words (empty: it dissipates everywhere).

    Checked as the fit constrains it (:func:`~dampest_ros.core.batch.fit`): the static terms
    on the grid over the flown envelope (:func:`~dampest_ros.core.batch.envelope`), reporting
    the point of the most negative νᵀD(ν)ν and the coefficient whose share θ_j g_j(ν) of
    that power is the most negative; and every memory gain c ≥ 0 (a passive kernel).

    Parameters
    ----------
    model : DampingModel
    theta : ndarray, shape (p,)
    flown : ndarray, shape (n, 6), optional
        Velocities whose per-DOF smallest and largest values bound the envelope (e.g. the
        lowest and highest flown); default ±:data:`DEFAULT_ENVELOPE`.

    Returns
    -------
    list of str
        E.g. ``"νᵀD(ν)ν = -10.1 W at ν = [0, 0, -0.8, 0, 0, 0]: Z_ww = -61 contributes
        -31.2 W"``.
    """
    theta = np.asarray(theta, dtype=float)
    names = model.parameter_names
    if flown is None:
        flown = np.array([DEFAULT_ENVELOPE]) * [[-1.0], [1.0]]
    out = []
    grid = envelope(np.asarray(flown, dtype=float))
    share = power_rows(model, grid) * theta  # W per coefficient
    power = share.sum(axis=1)
    k = int(np.argmin(power))
    # rounding: shares that cancel to ~1e-9 of their size are no violation
    if power[k] < -1e-9 * np.abs(share[k]).sum():
        j = int(np.argmin(share[k]))
        speeds = ", ".join(f"{x:.3g}" for x in grid[k])
        out.append(f"νᵀD(ν)ν = {power[k]:.4g} W at ν = [{speeds}]: {names[j]} = "
                   f"{theta[j]:.4g} contributes {share[k, j]:.4g} W")
    if model.term("freq") is not None:
        mem = model.slice("freq")
        out += [f"{n} = {c:.4g} < 0: a negative memory gain feeds energy back"
                for n, c in zip(names[mem], theta[mem], strict=True) if c < 0]
    return out


class IdentifiedModel:
    """θ of a damping model with its standard deviations and the mass matrix.

    Parameters
    ----------
    names : sequence of str
        Parameter names, θ order.
    theta, theta_std : ndarray, shape (p,)
    M : ndarray, shape (6, 6) or (36,)
        M_RB + M_A, row-major.
    damping : DampingModel, optional
        Term structure; rebuilt from the names when omitted.
    version : int
    M_A : ndarray, shape (6, 6) or (36,), optional
        The added mass inside ``M``; needed when ``added_mass_terms`` turn an effect off.
    added_mass_terms : AddedMassTerms, optional
        Which effects of M_A act (None: all, C(ν)ν of M as a whole).
    held : mapping of str to str, optional
        Coefficients the data did not determine (their θ is the prior), with the reason.

    Raises
    ------
    ConfigError
        Shapes that disagree, or numbers :func:`check_model_numbers` refuses.
    """

    def __init__(self, names: Sequence[str], theta: FloatArray, theta_std: FloatArray,
                 M: FloatArray, damping: DampingModel | None = None, version: int = 0,
                 M_A: FloatArray | None = None,
                 added_mass_terms: AddedMassTerms | None = None,
                 held: Mapping[str, str] | None = None) -> None:
        self.names = [str(n) for n in names]
        self.theta = np.asarray(theta, dtype=float)
        self.theta_std = np.asarray(theta_std, dtype=float)
        self.M = np.asarray(M, dtype=float).reshape(6, 6)
        self.held = dict(held or {})
        self.damping = damping if damping is not None else damping_from_names(self.names)
        self.version = int(version)
        self.M_A = None if M_A is None else np.asarray(M_A, dtype=float).reshape(6, 6)
        self.added_mass_terms = added_mass_terms
        if added_mass_terms is not None and not added_mass_terms.all and self.M_A is None:
            raise ConfigError("model.M_A", f"added_mass_terms {added_mass_terms.as_dict()} "
                                           "turn effects off and need M_A to split M")
        p = len(self.names)
        if self.theta.shape != (p,) or self.theta_std.shape != (p,):
            raise ConfigError("model.theta", f"theta and theta_std need {p} values")
        check_model_numbers(self.names, self.theta, self.theta_std, self.M, self.held)
        if self.damping.parameter_names != self.names:
            raise ConfigError("model.terms", "the terms do not give model.parameter_names")
        if self.damping.term("freq") is not None:
            raise ConfigError("model.terms", "a memory (freq) term needs its filter states; "
                                             "evaluate it with DampingModel.force")

    @property
    def identified(self) -> BoolArray:
        """Per coefficient (θ order), True when the data determined it; False: θ is the
        prior (the reason is in :attr:`held`)."""
        return identified_mask(self.names, self.held)

    def value(self, name: str) -> float:
        """θ of one named parameter."""
        return float(self.theta[self.names.index(name)])

    def D(self, nu: FloatArray) -> FloatArray:
        """D(ν), shape (6, 6) for ν (6,) or (N, 6, 6) for (N, 6)."""
        nu = np.asarray(nu, dtype=float)
        D = self.damping.matrix(np.atleast_2d(nu), self.theta)
        return D[0] if nu.ndim == 1 else D

    def damping_force(self, nu: FloatArray) -> FloatArray:
        """D(ν)ν (N, N·m), shape like ν."""
        nu = np.asarray(nu, dtype=float)
        f = self.damping.force(np.atleast_2d(nu), self.theta)
        return f[0] if nu.ndim == 1 else f

    def damping_force_std(self, nu: FloatArray) -> FloatArray:
        """Standard deviation of D(ν)ν from θ_std (independent parameters), shape like ν:
        √(Σ_j Φ_ij(ν)² σ_j²)."""
        nu = np.asarray(nu, dtype=float)
        Phi = self.damping.regressor(np.atleast_2d(nu))
        s = np.sqrt(np.einsum("nip,p->ni", Phi * Phi, self.theta_std**2))
        return s[0] if nu.ndim == 1 else s

    def coriolis_force(self, nu: FloatArray) -> FloatArray:
        """C_RB(ν)ν + the acting part of C_A(ν)ν (switches ``coriolis``, ``munk``; no
        current), N and N·m, shape like ν."""
        return split_coriolis_force(self.M, self.M_A, self.added_mass_terms,
                                    np.asarray(nu, dtype=float))

    def feedforward(self, nu: FloatArray) -> FloatArray:
        """D(ν)ν + C(ν)ν, the model-based feed-forward of a velocity controller."""
        return self.damping_force(nu) + self.coriolis_force(nu)
