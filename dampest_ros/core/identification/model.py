"""The identified model: the one type every part of dampest_ros passes around.

A :class:`Model` holds what identification found (θ by name with its standard deviations,
which coefficients the data determined and why the others were held), what it needs to be
evaluated (the damping term structure, the mass matrix M = M_RB + M_A with the added mass and
its switches) and where it came from (version, provenance entries). The batch fit
(:meth:`dampest_ros.core.identification.batch.Fit.to_model`), the online estimator, the gap workflow
and the importers produce one; the model file (:mod:`dampest_ros.io.yaml_io`), the model server, the
client and the exporters read and write one. Controllers evaluate it: D(ν), D(ν)ν with its
uncertainty, and C(ν)ν with the plant's added-mass switches (FRD body frame, SI units).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.identified import (
    BoolArray,
    check_model_numbers,
    damping_from_names,
    identified_mask,
)
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.identity import Identity, mismatch, unchecked
from dampest_ros.core.physics.rigid_body import AddedMassTerms, ConfigError, split_coriolis_force

FloatArray = NDArray[np.float64]


@dataclass
class Model:
    """An identified damping model with its mass matrix.

    Parameters
    ----------
    parameter_names : list of str
        Names in θ order (SNAME style, as :class:`DampingModel` names them).
    theta, theta_std : ndarray, shape (p,)
        Coefficients (positive when dissipative) and standard deviations, SI units; a held
        coefficient's σ may be NaN.
    M : ndarray, shape (6, 6) (or 36 numbers, row-major)
        M_RB + M_A (kg, kg·m, kg·m²), FRD body frame.
    version : int
        Bumped at each publish.
    damping : DampingModel or None
        The term structure (its names are ``parameter_names``); None when a file did not
        carry it: :attr:`structure` rebuilds linear and quadratic terms from the names.
    extra : dict
        Provenance and figures of merit (source, method, samples, flown_speeds, …).
    M_A : ndarray, shape (6, 6), or None
        The added mass inside ``M``; needed when ``added_mass_terms`` turn an effect off.
    added_mass_terms : AddedMassTerms or None
        Which effects of M_A act; None: all (C(ν)ν of M as a whole).
    held : dict of str to str
        The coefficients the data did not determine (θ is their prior or the value a
        constraint allows), with the reason; empty: all identified.
    identity : Identity or None
        The vehicle it belongs to (:mod:`dampest_ros.core.physics.identity`); None only for
        files written before models carried one.

    Raises
    ------
    ConfigError
        Shapes that disagree, switches that need M_A without it, a structure whose names
        differ, or numbers no reader would take (:func:`check_model_numbers`).
    """

    parameter_names: list[str]
    theta: FloatArray
    theta_std: FloatArray
    M: FloatArray
    version: int = 1
    damping: DampingModel | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    M_A: FloatArray | None = None
    added_mass_terms: AddedMassTerms | None = None
    held: dict[str, str] = field(default_factory=dict)
    identity: Identity | None = None

    def __post_init__(self) -> None:
        self.parameter_names = [str(n) for n in self.parameter_names]
        self.theta = np.asarray(self.theta, dtype=float)
        self.theta_std = np.asarray(self.theta_std, dtype=float)
        p = len(self.parameter_names)
        if not p or self.theta.shape != (p,) or self.theta_std.shape != (p,):
            raise ConfigError("model.theta", f"need p ≥ 1 names, theta and theta_std of one "
                                             f"length, got {p}, {self.theta.shape}, "
                                             f"{self.theta_std.shape}")
        for name in ("M", "M_A"):
            value = getattr(self, name)
            if value is None:
                continue
            value = np.asarray(value, dtype=float)
            if value.size != 36:
                raise ConfigError(f"model.{name}", f"needs 36 entries, got shape {value.shape}")
            setattr(self, name, value.reshape(6, 6))
        self.version = int(self.version)
        self.held = {str(k): str(v) for k, v in (self.held or {}).items()}
        check_model_numbers(self.parameter_names, self.theta, self.theta_std, self.M,
                            self.held)
        if self.damping is not None and self.damping.parameter_names != self.parameter_names:
            raise ConfigError("model.terms", f"the terms give {self.damping.parameter_names}, "
                                             f"not {self.parameter_names}")
        terms = self.added_mass_terms
        if terms is not None and not terms.all and self.M_A is None:
            raise ConfigError("model.M_A", f"added_mass_terms {terms.as_dict()} turn effects "
                                           "off and need M_A to split M")

    def belongs_to(self, expected: Identity, source: str) -> str | None:
        """Check that the model is one of ``expected``'s (the vehicle or arm in use).

        Parameters
        ----------
        expected : Identity
        source : str
            The model's file, for the message.

        Returns
        -------
        str or None
            The warning for a model without an identity (written before models carried
            one), else None.

        Raises
        ------
        ConfigError
            ``model.identity``: it belongs to another vehicle; the message names both and
            the fix.
        """
        why = mismatch(self.identity, expected, source)
        if why is not None:
            raise ConfigError("model.identity", why)
        return unchecked(self.identity, expected, source)

    # --- what the data determined ----------------------------------------------------------

    @property
    def identified(self) -> BoolArray:
        """Per coefficient (θ order), True when the data determined it; False: see
        :attr:`held` for why."""
        return identified_mask(self.parameter_names, self.held)

    def value(self, name: str) -> float:
        """θ of one named parameter."""
        return float(self.theta[self.parameter_names.index(name)])

    @property
    def flown(self) -> FloatArray | None:
        """The smallest and largest velocity per DOF of the data the model was fitted on,
        shape (2, 6) (``extra['flown_speeds']`` ``min``, ``max``; m/s, rad/s), or None.

        Raises
        ------
        ConfigError
            When the entry is not two lists of 6 finite numbers.
        """
        given = self.extra.get("flown_speeds")
        if given is None:
            return None
        try:
            flown = np.array([given["min"], given["max"]], dtype=float)
        except (KeyError, TypeError, ValueError):
            flown = np.zeros(0)
        if flown.shape != (2, 6) or not np.all(np.isfinite(flown)):
            raise ConfigError("model.flown_speeds", "needs min: and max: of 6 finite "
                                                    "numbers each")
        return flown

    @property
    def acting_terms(self) -> AddedMassTerms:
        """The added-mass switches, all true when the model has none."""
        return self.added_mass_terms or AddedMassTerms()

    # --- evaluation ------------------------------------------------------------------------

    @property
    def structure(self) -> DampingModel:
        """The term structure: :attr:`damping`, else rebuilt from the names (linear and
        quadratic only; ConfigError for other names)."""
        return self.damping if self.damping is not None else \
            damping_from_names(self.parameter_names)

    def D(self, nu: FloatArray) -> FloatArray:
        """Static D(ν), shape (6, 6) for ν (6,) or (N, 6, 6) for (N, 6)."""
        nu = np.asarray(nu, dtype=float)
        D = self.structure.matrix(np.atleast_2d(nu), self.theta)
        return D[0] if nu.ndim == 1 else D

    def damping_force(self, nu: FloatArray) -> FloatArray:
        """D(ν)ν (N, N·m), shape like ν; a memory term needs its filter states (ValueError:
        evaluate it with :meth:`DampingModel.force`)."""
        nu = np.asarray(nu, dtype=float)
        f = self.structure.force(np.atleast_2d(nu), self.theta)
        return f[0] if nu.ndim == 1 else f

    def damping_force_std(self, nu: FloatArray) -> FloatArray:
        """Standard deviation of D(ν)ν from θ_std (independent parameters), shape like ν:
        √(Σ_j Φ_ij(ν)² σ_j²)."""
        nu = np.asarray(nu, dtype=float)
        Phi = self.structure.regressor(np.atleast_2d(nu))
        # √(Σ_j Φ_ij² σ_j²)
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
