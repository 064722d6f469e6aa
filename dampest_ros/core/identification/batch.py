"""Offline batch identification of the damping parameters θ from samples.

Regression form (FRD, per sample n): y_n = τ_n − M ν̇_n − C(ν_n)ν_n − g(η_n) = Φ(ν_n) θ + e_n,
reduced to per-DOF, per-fold normal equations (:mod:`dampest_ros.core.identification.regression`).
Everything here (OLS, per-DOF weighted LS, ridge, bounded LS, MAP, held-out residuals,
AIC/BIC) is closed-form in them; the covariance is block-robust plus the sensor-bias budget
(:mod:`dampest_ros.core.identification.covariance`), and the estimate is held dissipative
(:mod:`dampest_ros.core.identification.dissipative`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, special
from scipy.sparse import csgraph

from dampest_ros.core.identification.axis_check import (
    AxisCheck,
    AxisStatistics,
    axis_check,
    axis_statistics,
)
from dampest_ros.core.identification.covariance import (
    BiasStatistics,
    MapParts,
    bias_statistics,
    block_count,
    block_length,
    covariance,
    settled_block,
    whole,
)
from dampest_ros.core.identification.dissipative import (
    Violations,
    dissipation_points,
    impose,
    misfit_report,
    scan,
    violations,
)
from dampest_ros.core.identification.model import Model
from dampest_ros.core.identification.quadratic import solve_normal
from dampest_ros.core.identification.regression import (
    NormalEquations,
    accumulate,
    total_sum_of_squares,
)
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.identity import Identity
from dampest_ros.core.physics.rigid_body import DOF_NAMES, ConfigError, RigidBody
from dampest_ros.core.signals.extent import Extent
from dampest_ros.core.signals.samples import CHUNK, Samples

FloatArray = NDArray[np.float64]

METHODS = ("ols", "wls", "ridge", "bounded", "map")
#: Noise floor of each DOF relative to its RMS target force: the WLS weight 1/σ_i² uses
#: σ_i ≥ FLOOR · RMS(y_i). No thrust model or force measurement is better than 0.1 %, so a
#: smaller residual is the structure fitting exactly, not noise; unfloored, such a DOF
#: outweighs the others by the rounding of its residual (up to 1e12).
FLOOR = 1e-3
#: A parameter with more than this share of its unit vector (scaled coordinates) in the
#: directions collinearity leaves undetermined is reported only through a combination.
SHARE = 0.01

@dataclass(frozen=True)
class Combination:
    """A linear combination of parameters that the data determine while its members are not.

    Two columns the flown data cannot tell apart (X_uu and a u‖v‖ term when v stays small)
    leave their split undetermined but their joint force known: Σ_k a_k θ_k is that force's
    coefficient over the flown speeds.

    Attributes
    ----------
    names : list of str
        The members, shape (m,).
    coef : ndarray, shape (m,)
        Coefficients a_k, the largest |a_k| equal to 1; a_k = ‖Φ_k‖ / ‖Φ_l‖ (l the member
        with a_l = 1) for two columns that move together, so the sum is in the units of θ_l.
    value : float
        Σ_k a_k θ̂_k.
    std : float
        √(aᵀ Σ a), Σ the covariance of θ̂.
    """

    names: list[str]
    coef: FloatArray
    value: float
    std: float

    def __str__(self) -> str:
        parts = [("" if f"{abs(a):.3g}" == "1" else f"{abs(a):.3g}·") + n
                 for a, n in zip(self.coef, self.names, strict=True)]
        text = "".join((" − " if a < 0 else " + ") + t if k else ("−" if a < 0 else "") + t
                       for k, (a, t) in enumerate(zip(self.coef, parts, strict=True)))
        return f"{text} = {self.value:.4g} ± {self.std:.2g} over the flown speeds"


@dataclass
class Fit:
    """Result of a batch identification.

    Attributes
    ----------
    names : list of str
    theta : ndarray, shape (p,)
        Estimate. Parameters the data say nothing about (``held``) hold their prior (or 0)
        and are listed in ``flags``; members of an undetermined combination hold the
        minimum-norm split of it (``combinations``); ``constrained`` ones hold the value
        dissipativity allows.
    cov : ndarray, shape (p, p)
        Covariance (block-robust) of the unconstrained estimate in the directions the data
        determine, the parameters of a row whose pure-axis law the samples along that axis
        contradict scaled by its Birge ratio (``axes``); NaN rows/columns for held
        parameters.
    sigma : ndarray, shape (6,)
        Residual standard deviation per DOF (N, N·m).
    flags : dict of str to str
        Parameter name → why the data do not determine it on its own.
    held : ndarray of bool, shape (p,)
        True where θ is the prior value (no excitation, poorly determined, low speed only).
    combinations : list of Combination
        What the data determine of collinear parameters.
    constrained : dict of str to str
        Parameter name → the dissipativity constraint that holds it (and the unconstrained
        value); a structural misfit when the unconstrained estimate violated it.
    rank : int
        Number of directions of θ the data determine (the free parameters of AIC/BIC).
    axes : AxisCheck, optional
        The model's damping along each axis against the samples flown along it
        (:mod:`~dampest_ros.core.identification.axis_check`).
    """

    names: list[str]
    theta: FloatArray
    cov: FloatArray
    sigma: FloatArray
    method: str
    n: int
    rss: FloatArray
    tss: FloatArray
    cond: float
    flags: dict[str, str] = field(default_factory=dict)
    cv_rmse: FloatArray = field(default_factory=lambda: np.zeros(6))
    n_eff: float = 0.0
    blocks: int = 0
    held: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))
    combinations: list[Combination] = field(default_factory=list)
    constrained: dict[str, str] = field(default_factory=dict)
    rank: int = 0
    axes: AxisCheck | None = None

    @property
    def identified(self) -> NDArray[np.bool_]:
        """True where the data alone determine the parameter, shape (p,): not held at the
        prior, not only part of a combination, not held by a constraint."""
        return np.array([n not in self.flags and n not in self.constrained
                         for n in self.names], dtype=bool)

    @property
    def std(self) -> FloatArray:
        """Standard deviations, shape (p,)."""
        return np.sqrt(np.abs(np.diag(self.cov)))

    def quantile(self, level: float = 0.95) -> float:
        """Half-width of a two-sided ``level`` interval in standard deviations: Student-t
        with (blocks − 1) degrees of freedom, as suits a covariance estimated from that many
        block scores; normal when the block count is unknown. (scipy.special's quantiles,
        which scipy.stats's t and norm call: the same numbers without its second of
        import.)"""
        q = 0.5 + level / 2
        return float(special.stdtrit(self.blocks - 1, q) if self.blocks > 1
                     else special.ndtri(q))

    def interval(self, level: float = 0.95) -> FloatArray:
        """Two-sided confidence intervals (:meth:`quantile`), shape (p, 2)."""
        z = self.quantile(level)
        return np.stack([self.theta - z * self.std, self.theta + z * self.std], axis=1)

    @property
    def corr(self) -> FloatArray:
        """Correlation matrix of the estimates, shape (p, p)."""
        s = self.std
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.asarray(self.cov / np.outer(s, s))

    @property
    def r2(self) -> FloatArray:
        """Coefficient of determination per DOF (NSE), shape (6,)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.asarray(1.0 - self.rss / self.tss)

    @property
    def rmse(self) -> FloatArray:
        """In-sample RMS force error per DOF, shape (6,)."""
        return np.asarray(np.sqrt(self.rss / self.n))

    @property
    def log_likelihood(self) -> float:
        """Gaussian log-likelihood with per-DOF variances, on the effective sample count."""
        s2 = np.maximum(self.rss / self.n, 1e-300)
        return float(-0.5 * self.n_eff * np.sum(np.log(2 * np.pi * s2) + 1.0))

    @property
    def n_free(self) -> int:
        """Number of estimated directions of θ (held parameters and the undetermined split
        of collinear ones are not estimated)."""
        return self.rank

    @property
    def aic(self) -> float:
        """Akaike information criterion."""
        return -2 * self.log_likelihood + 2 * self.n_free

    @property
    def bic(self) -> float:
        """Bayesian information criterion."""
        return -2 * self.log_likelihood + self.n_free * float(np.log(self.n_eff))

    @property
    def held_reasons(self) -> dict[str, str]:
        """The coefficients not identified with why: their flag, else the constraint."""
        return {n: self.flags.get(n) or self.constrained[n]
                for n, ok in zip(self.names, self.identified, strict=True) if not ok}

    def to_model(self, damping: DampingModel, body: RigidBody,
                 extra: dict[str, Any] | None = None,
                 identity: Identity | None = None) -> Model:
        """The fit as a :class:`~dampest_ros.core.identification.model.Model`: θ and σ, the
        coefficients not identified held with their reason (``flags``, else the constraint), the
        body's mass matrix, added mass and switches, and as ``extra`` the method, sample count, 95 %
        intervals, per-DOF NSE and RMSE and condition number, plus ``extra``.

        Parameters
        ----------
        damping : DampingModel
            The structure fitted (its names are :attr:`names`).
        body : RigidBody
        extra : dict, optional
            More provenance (e.g. ``source``, ``flown_speeds``).
        identity : Identity, optional
            The vehicle the data are of (:attr:`Vehicle.identity
            <dampest_ros.core.physics.vehicle.Vehicle.identity>`).
        """
        ci = self.interval()
        held = self.held_reasons
        figures = {"method": self.method, "samples": int(self.n),
                   "ci95_low": [float(x) for x in ci[:, 0]],
                   "ci95_high": [float(x) for x in ci[:, 1]],
                   "nse": [float(x) for x in self.r2], "rmse": [float(x) for x in self.rmse],
                   "condition_number": float(self.cond)}
        return Model(self.names, self.theta, self.std, body.M, damping=damping,
                     extra={**(extra or {}), **figures}, M_A=body.added_mass,
                     added_mass_terms=body.added_mass_terms, held=held, identity=identity)


@dataclass(frozen=True)
class FitOptions:
    """Solver settings.

    Attributes
    ----------
    method : {'ols', 'wls', 'ridge', 'bounded', 'map'}
    ridge : float
        Ridge strength relative to the diagonal of the information matrix.
    block : float
        Longest block (s) of the robust covariance; a log too short for 2 r + 1 such blocks
        (r the directions estimated) gets shorter ones (:func:`block_length`).
    max_rel_halfwidth : float
        A parameter whose 95 % half-width exceeds this fraction of its scale
        (:func:`parameter_scale`) is flagged and held at its prior.
    max_vif : float
        A direction of θ whose variance is inflated above this by collinearity is not
        estimated; its members are reported as a :class:`Combination`.
    cutoff : float
        Parallel low-pass applied to y and Φ (Hz); 0 disables it. It also sets the effective
        sample count n_eff = 2 · cutoff · T used by AIC/BIC.
    gyro_bias, dvl_bias : float
        Standard deviation of an unknown constant gyro (rad/s) and DVL (m/s) bias per axis:
        the sensor error budget that
        :func:`~dampest_ros.core.identification.covariance.bias_covariance` propagates into
        θ. 0 ignores it.
    bias_stretch : int
        Of a segment longer than three times this many samples, the sensor-bias refits use
        three evenly spread stretches of it
        (:func:`~dampest_ros.core.identification.covariance.bias_rows`).
    speed_range : tuple of 6 float, optional
        Speeds the vehicle can reach per DOF; quadratic terms of DOFs flown below 15 % of
        it are flagged (:func:`speed_coverage_flags`).
    dissipative : bool
        Constrain the estimate to νᵀD(ν)ν ≥ 0 on the data and over the flown envelope
        (:func:`envelope`); memory terms are left out of the constraint.
    """

    method: str = "wls"
    ridge: float = 1e-3
    block: float = 10.0
    max_rel_halfwidth: float = 0.5
    max_vif: float = 1e4
    cutoff: float = 2.0
    gyro_bias: float = 2e-4
    dvl_bias: float = 1e-3
    bias_stretch: int = 20000
    speed_range: tuple[float, ...] | None = None
    dissipative: bool = True

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ConfigError("method", f"unknown method {self.method!r}; use one of {METHODS}")


def determined_directions(A: FloatArray, free: NDArray[np.bool_], max_vif: float
                          ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Split θ_free into the directions the data determine and those collinearity hides.

    In column-scaled coordinates x = θ/s (s_j = 1/√A_jj, so G = S A S has a unit diagonal)
    an eigenvector v_k of G with eigenvalue λ_k is a combination whose variance is σ²/λ_k,
    and the variance inflation of parameter j is VIF_j = Σ_k V_jk²/λ_k. Directions with
    λ_k < 1/``max_vif`` (or below 1e-10: numerically singular) are not determined: the data
    fix x only in the others, and x = 0 along these (the minimum-norm split).

    Parameters
    ----------
    A : ndarray, shape (p, p)
        Weighted normal-equation matrix.
    free : ndarray of bool, shape (p,)
    max_vif : float

    Returns
    -------
    T : ndarray, shape (p_free, r)
        θ_free = T β over the determined directions (T = S V_determined).
    W : ndarray, shape (p_free, k)
        The undetermined directions in scaled coordinates (orthonormal columns).
    s : ndarray, shape (p_free,)
        The column scaling.
    """
    Af = A[np.ix_(free, free)]
    s = 1.0 / np.sqrt(np.maximum(np.diag(Af), 1e-300))
    lam, V = np.linalg.eigh(Af * np.outer(s, s))
    weak = lam < max(1.0 / max_vif, 1e-10)
    return s[:, None] * V[:, ~weak], V[:, weak], s


def combinations_of(W: FloatArray, s: FloatArray, names: list[str], theta: FloatArray,
                    cov: FloatArray, share: float = SHARE) -> list[Combination]:
    """What the data determine of the parameters in undetermined directions.

    A parameter belongs to an undetermined direction when more than ``share`` of its unit
    vector lies in the undetermined subspace (its min-norm value then moves with what the
    data cannot fix); members that share a direction form a group. Within the span of a
    group's members, the directions orthogonal to its undetermined ones are determined:
    each is reported as Σ a_k θ_k (a = u / s, u a unit vector in scaled coordinates).

    Parameters
    ----------
    W : ndarray, shape (p_free, k)
        Undetermined directions (scaled coordinates), from :func:`determined_directions`.
    s : ndarray, shape (p_free,)
    names : list of str
        Names of the free parameters, shape (p_free,).
    theta : ndarray, shape (p_free,)
    cov : ndarray, shape (p_free, p_free)
    """
    out: list[Combination] = []
    if not W.shape[1]:
        return out
    member = np.sum(W**2, axis=1) > share  # share of e_j in the undetermined subspace
    links = (W**2 > share / W.shape[1]) & member[:, None]
    # groups: members connected through a shared undetermined direction
    _, label = csgraph.connected_components(links.astype(float) @ links.T.astype(float) > 0,
                                            directed=False)
    for lab in np.unique(label[member]):
        group = np.flatnonzero((label == lab) & member)
        k = np.flatnonzero(links[group].any(axis=0))
        # the determined directions within the group's span: the null space of W_gᵀ
        U = linalg.null_space(W[np.ix_(group, k)].T)
        for u in U.T:
            a = u / s[group]
            a = a / a[np.argmax(np.abs(u))]  # the member with the largest share gets 1
            a = np.where(np.abs(a) < 1e-3, 0.0, a)
            used = a != 0
            idx = group[used]
            out.append(Combination([names[i] for i in idx], a[used],
                                   float(a[used] @ theta[idx]),
                                   float(np.sqrt(abs(a[used] @ cov[np.ix_(idx, idx)]
                                                     @ a[used])))))
    return out


def _flags(theta: FloatArray, cov: FloatArray, names: list[str], scale: FloatArray,
           opts: FitOptions, candidates: NDArray[np.bool_]) -> dict[str, str]:
    """Parameters among ``candidates`` whose 95 % half-width exceeds
    ``opts.max_rel_halfwidth`` of their data scale (:func:`parameter_scale`)."""
    z = float(special.ndtri(0.975))  # the normal's 97.5 % quantile
    half = z * np.sqrt(np.abs(np.diag(cov)))
    return {name: (f"poorly determined: 95 % half-width {half[j]:.3g} exceeds "
                   f"{opts.max_rel_halfwidth:.0%} of {scale[j]:.3g} (the larger of |estimate| "
                   "and the value giving 10 % of the force its DOF explains); the data's "
                   "estimate is kept with its interval; excite this degree of freedom more "
                   "(speed range, amplitude)")
            for j, name in enumerate(names)
            if candidates[j] and half[j] > opts.max_rel_halfwidth * scale[j]}


def speed_coverage_flags(model: DampingModel, speed: FloatArray, speed_range: FloatArray,
                         min_share: float = 0.15) -> dict[str, str]:
    """Quadratic coefficients of DOFs whose speed range the data do not cover.

    A quadratic drag coefficient fitted only at low speed is an extrapolation wherever the
    vehicle is faster; when the 99th percentile of |ν_i| stays below ``min_share`` of the
    vehicle's speed range in DOF i, every quadratic parameter of that DOF is flagged.

    Parameters
    ----------
    speed : ndarray, shape (6,)
        The 99th percentile of |ν_i| in the data (m/s, rad/s; :class:`Extent`'s ``speed``).
    speed_range : ndarray, shape (6,)
        Speeds the vehicle reaches (e.g. at half thrust), m/s and rad/s.
    """
    quad = model.term("quadratic")
    if quad is None:
        return {}
    flags = {}
    for name, b in zip(quad.parameter_names, quad.bases, strict=True):
        i = int(np.argmax(np.abs(np.diag(b.B))))
        if speed[i] < min_share * speed_range[i]:
            flags[name] = (f"low speed only: |{DOF_NAMES[i]}| ≤ {speed[i]:.3g} in these data, "
                           f"{speed[i] / speed_range[i]:.0%} of the {speed_range[i]:.3g} the "
                           f"vehicle reaches; fly faster in {DOF_NAMES[i]} to identify it")
    return flags


def parameter_scale(ne: NormalEquations, theta: FloatArray) -> FloatArray:
    """The size a parameter must be known to, from the data alone, shape (p,).

    max(|θ̂_j|, F_j): a parameter is determined when its value is known relative to itself,
    or when the force it contributes is known relative to the force the model explains in
    the DOF i it acts on (the row of its largest column): F_j = 0.1 ‖Φ_i θ̂‖ / ‖Φ_ij‖ is the
    value whose force is 10 % of that, RMS over the flown data. A small coefficient whose
    force is pinned down is identified; a column of sensor noise in a DOF that did not move
    is not, as its DOF explains no force. No prior enters: the same data give the same scale.
    """
    A = ne.A.sum(0)  # (6, p, p)
    Ad = np.einsum("ipp->ip", A)  # Σ Φ_{·,i,j}² per DOF i and parameter j
    i = np.argmax(Ad, axis=0)
    # ‖Φ_i θ‖² = θᵀ (Σ Φ_iᵀΦ_i) θ: the force the model explains in DOF i
    explained = np.sqrt(np.maximum(np.einsum("ipq,p,q->i", A, theta, theta), 0.0))
    col = np.sqrt(np.maximum(Ad[i, np.arange(len(i))], 1e-300))
    return np.asarray(np.maximum(np.abs(theta), 0.1 * explained[i] / col))


@dataclass(frozen=True)
class _Problem:
    """The normal equations of a fit with its method's regularisation, solved for given
    per-DOF weights.

    Attributes
    ----------
    ne : NormalEquations
        Per-DOF, per-fold statistics of y = Φ(ν)θ + e.
    opts : FitOptions
        The method (``ridge`` and ``map`` add to the equations, ``ols`` weights all DOFs
        alike) and its settings.
    prior : ndarray, shape (p,)
        Value of the parameters that are not free, and the prior mean of MAP (SI units of θ).
    prior_std : ndarray, shape (p,), optional
        Prior standard deviations of MAP.
    lower : ndarray, shape (p,), optional
        Lower bounds (``bounded``; −inf: none).
    """

    ne: NormalEquations
    opts: FitOptions
    prior: FloatArray
    prior_std: FloatArray | None
    lower: FloatArray | None

    @property
    def n(self) -> int:
        """Number of samples the normal equations hold."""
        return int(self.ne.n.sum())

    def equations(self, weights: FloatArray, exclude: int | None = None
                  ) -> tuple[FloatArray, FloatArray]:
        """A, shape (p, p), and b, shape (p,), of the weighted normal equations summed over the
        folds but ``exclude``, with the ridge (relative to diag A) or the MAP prior 1/σ² added.

        Raises
        ------
        ConfigError
            ``map`` without ``prior_std``.
        """
        A, b, _ = self.ne.total(weights, exclude)
        if self.opts.method == "ridge":
            A = A + self.opts.ridge * np.diag(np.diag(A))
        if self.opts.method == "map":
            if self.prior_std is None:
                raise ConfigError("prior", "MAP needs a prior with standard deviations")
            P = 1.0 / np.maximum(np.asarray(self.prior_std, float), 1e-12) ** 2
            A = A + np.diag(P)
            b = b + P * self.prior
        return A, b

    def solve(self, weights: FloatArray, free: NDArray[np.bool_],
              basis: FloatArray | None = None, exclude: int | None = None,
              power: FloatArray | None = None) -> FloatArray:
        """θ, shape (p,), from :meth:`equations` (:func:`solve_normal`): the ``free``
        parameters, shape (p,), estimated in the directions ``basis`` spans, shape
        (p_free, r), and kept to g_kᵀθ ≥ 0 for the rows of ``power``, shape (m, p); the others
        at the prior."""
        A, b = self.equations(weights, exclude)
        return solve_normal(A, b, free, self.prior, self.lower, basis, power)

    def weights(self, theta: FloatArray) -> FloatArray:
        """Per-DOF weights 1/σ_i², shape (6,), for the residuals of ``theta`` (ones for
        ``ols``).

        σ_i² = max(RSS_i / N, (FLOOR · RMS y_i)²), in N² and (N·m)²: the DOF's noise variance,
        never below what its own force scale makes credible.
        """
        if self.opts.method == "ols":
            return np.ones(6)
        N = self.n
        force_rms = np.sqrt(self.ne.c.sum(0) / N)  # RMS target force per DOF (N, N·m)
        s2 = np.maximum(self.ne.rss(theta) / N, (FLOOR * force_rms) ** 2)
        return np.asarray(1.0 / np.maximum(s2, 1e-300))


def _excited(ne: NormalEquations, names: list[str]
             ) -> tuple[NDArray[np.bool_], dict[str, str]]:
    """The parameters whose regressor column is not zero in these data, shape (p,), and a
    flag for each of the others.

    Unweighted: the weights do not excite anything.
    """
    d = np.diag(ne.total(np.ones(6))[0])
    live = d > 1e-12 * max(float(d.max()), 1e-300)
    flags = {n: "no excitation: its regressor column is zero in these data"
             for n, ok in zip(names, live, strict=True) if not ok}
    return live, flags


def _reweighted(problem: _Problem, live: NDArray[np.bool_]) -> FloatArray:
    """Per-DOF weights 1/σ_i², shape (6,), after three rounds of reweighting from equal
    weights, each on the residuals of the ``live`` parameters, shape (p,), fitted with the
    previous weights (:meth:`_Problem.weights`)."""
    w = np.ones(6)
    for _ in range(3):
        w = problem.weights(problem.solve(w, live))
    return w


def _free(model: DampingModel, extent: Extent, opts: FitOptions, live: NDArray[np.bool_],
          prior: FloatArray, flags: dict[str, str]) -> NDArray[np.bool_]:
    """The parameters the fit estimates, shape (p,): excited (``live``) and, with
    ``opts.speed_range``, not quadratic terms of a DOF flown too slowly
    (:func:`speed_coverage_flags`).

    ``flags`` gains the speed-coverage flags, and the flag of every other parameter says that
    it is held at its ``prior`` value, shape (p,).
    """
    names = model.parameter_names
    if opts.speed_range is not None:
        flags.update(speed_coverage_flags(model, extent.speed, np.asarray(opts.speed_range)))
    free = live & np.array([n not in flags for n in names])
    for j in np.flatnonzero(~free):
        flags[names[j]] = f"held at prior {prior[j]:.4g} ({flags[names[j]]})"
    return free


def _combinations(W: FloatArray, s: FloatArray, names: list[str], free: NDArray[np.bool_],
                  theta: FloatArray, cov: FloatArray, flags: dict[str, str]
                  ) -> list[Combination]:
    """What the data determine of the free parameters in undetermined directions
    (:func:`combinations_of`); ``flags`` gains, for each member not flagged yet, that only its
    combination is identified.

    Parameters
    ----------
    W : ndarray, shape (p_free, k)
        Undetermined directions (scaled coordinates), from :func:`determined_directions`.
    s : ndarray, shape (p_free,)
        The column scaling.
    names : list of str
        All parameter names, shape (p,).
    free : ndarray of bool, shape (p,)
    theta : ndarray, shape (p,)
    cov : ndarray, shape (p, p)
    flags : dict of str to str
    """
    fi = np.flatnonzero(free)
    combos = combinations_of(W, s, [names[j] for j in fi], theta[fi], cov[np.ix_(fi, fi)])
    for c in combos:
        for n in c.names:
            flags.setdefault(n, f"not identified on its own: only {c} is")
    return combos


def _dissipative(problem: _Problem, model: DampingModel, flown: FloatArray,
                 scan_data: Callable[[FloatArray], Violations], theta: FloatArray,
                 cov: FloatArray, w: FloatArray, free: NDArray[np.bool_], T: FloatArray,
                 chunk: int) -> tuple[FloatArray, dict[str, str], FloatArray]:
    """With ``dissipative``, impose νᵀD(ν)ν ≥ 0 where ``theta`` violates it, on every sample
    (``scan_data(θ)``: :func:`violations` of the samples) and over the envelope ``flown``
    (shape (2, 6): the samples' smallest and largest ν; the grid's power rows formed once
    for every round) (:func:`impose`).

    Returns
    -------
    theta : ndarray, shape (p,)
        The constrained estimate (``theta`` when nothing is violated).
    constrained : dict of str to str
        Parameters an active constraint moved, and why (:func:`misfit_report`).
    power : ndarray, shape (m, p)
        The constraint rows g_k (νᵀD(ν)ν = g_kᵀθ, W) the estimate is held to; m = 0 when none.
    """
    constrained: dict[str, str] = {}
    power = np.zeros((0, len(theta)))
    if not (problem.opts.dissipative and model.n_params):
        return theta, constrained, power

    def points(th: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
        # the grid over the envelope of the samples is kept for the next round
        return dissipation_points(model, th, np.zeros((0, 6)), flown, chunk, scan_data(th))

    pts, on_data = points(theta)
    if len(pts):
        constrained = misfit_report(model, theta, pts[:1000], on_data[:1000], cov, free)
        theta, power = impose(theta, pts, model, lambda E: problem.solve(w, free, T, power=E),
                              lambda th: points(th)[0])
    return theta, constrained, power


def _scan_parts(theta: FloatArray, map_parts: MapParts, model: DampingModel, chunk: int
                ) -> Violations:
    """:func:`violations` of the samples, part by part where ``map_parts`` holds them."""
    parts = map_parts(partial(_part_violations, model=model, theta=theta, chunk=chunk))
    return np.concatenate([v[0] for v in parts]), np.concatenate([v[1] for v in parts])


def _part_violations(part: Samples, first: int, model: DampingModel, theta: FloatArray,
                     chunk: int) -> Violations:
    """:func:`violations` of one part's velocities (a :data:`MapParts` call)."""
    return violations(model, theta, part.nu, chunk)


def _part_axis_statistics(part: Samples, first: int, model: DampingModel, body: RigidBody,
                          cutoff: float, limits: FloatArray, chunk: int) -> AxisStatistics:
    """:func:`axis_statistics` of a part of the samples (a :data:`MapParts` call)."""
    return axis_statistics(part, model, body, cutoff, limits, chunk)


def _cross_validated_rss(problem: _Problem, w: FloatArray, free: NDArray[np.bool_],
                         T: FloatArray, power: FloatArray) -> FloatArray:
    """Held-out residual sum of squares per DOF, shape (6,) (N², (N·m)²): each fold scored
    with the estimate fitted on the others, with the same weights ``w``, directions ``T`` and
    constraints ``power``."""
    cv = np.zeros(6)
    for f in range(len(problem.ne.n)):
        th_f = problem.solve(w, free, T, exclude=f, power=power)
        cv += problem.ne.rss(th_f, fold=f)
    return cv


def _scaled_condition(ne: NormalEquations, free: NDArray[np.bool_]) -> float:
    """Condition number of the unweighted normal-equation matrix of the ``free`` parameters,
    shape (p,), with its columns scaled to a unit diagonal (1 when none is free)."""
    A_s, _, _ = ne.total(np.ones(6))
    d = np.sqrt(np.maximum(np.diag(A_s[np.ix_(free, free)]), 1e-300))
    ev = np.linalg.eigvalsh(A_s[np.ix_(free, free)] / np.outer(d, d)) if free.any() else [1.0]
    return float(max(ev) / max(min(ev), 1e-300))


def _effective_samples(extent: Extent, n: int, cutoff: float) -> float:
    """n_eff = 2 · cutoff · T of AIC/BIC (T the duration, s; ``cutoff`` in Hz), at most the
    sample count ``n``; ``n`` without a low-pass."""
    duration = extent.duration if extent.rate else float(n)
    return min(float(n), 2 * cutoff * duration) if cutoff > 0 else float(n)


def fit(samples: Samples, model: DampingModel, body: RigidBody,
        options: FitOptions | None = None, prior: FloatArray | None = None,
        prior_std: FloatArray | None = None, normal: NormalEquations | None = None,
        chunk: int = CHUNK, bias: BiasStatistics | None = None,
        extent: Extent | None = None) -> Fit:
    """Identify θ from samples.

    1. Per-DOF weights 1/σ_i² from the residuals (``wls``), σ_i floored at
       :data:`FLOOR` of the DOF's RMS target force.
    2. Columns that are zero in these data, and quadratic terms of DOFs flown too slowly
       (``speed_range``), hold their prior: the data say nothing about them.
    3. Directions of θ whose variance collinearity inflates above ``max_vif`` are not
       estimated (minimum norm); their members are reported with the combination the data
       determine (:class:`Combination`).
    4. Parameters whose 95 % half-width exceeds ``max_rel_halfwidth`` of their data scale
       (:func:`parameter_scale`) are flagged; their estimate is the data's. No step uses the
       prior's magnitude, so a prior scaled by any factor gives the same flags and the same
       θ but for the held parameters.
    5. With ``dissipative``, the estimate is constrained to νᵀD(ν)ν ≥ 0 on every sample and
       over the flown envelope; parameters an active constraint moved are reported.

    Parameters
    ----------
    samples : Samples
    model : DampingModel
        Term structure to identify.
    body : RigidBody
        Known M (rigid body + added mass) and restoring data.
    options : FitOptions, optional
    prior : ndarray, shape (p,), optional
        Prior mean (MAP) and the value of the parameters the data say nothing about.
    prior_std : ndarray, shape (p,), optional
        Prior standard deviations for MAP.
    normal : NormalEquations, optional
        Precomputed statistics (saves the first pass); formed here with the robust
        covariance's blocks when their length is settled
        (:func:`~dampest_ros.core.identification.covariance.settled_block`).
    chunk : int
        Samples per chunk.
    bias : BiasStatistics, optional
        Precomputed data of the sensor-bias refits
        (:func:`~dampest_ros.core.identification.covariance.bias_statistics` of ``samples``,
        formed here when not given and the options give a sensor a bias).
    extent : Extent, optional
        :meth:`Extent.of` ``samples`` (formed here when not given).

    Returns
    -------
    Fit
    """
    opts = options or FitOptions()
    _enough(len(samples), model.n_params)
    extent = extent or Extent.of(samples)
    ne = normal or accumulate(samples, model, body, chunk=chunk, cutoff=opts.cutoff,
                              block=settled_block(extent, opts, model.n_params))
    if bias is None:
        bias = bias_statistics(samples, model, body, opts, chunk)
    return fit_statistics(extent, ne, bias, whole(samples), model, body, opts, prior,
                          prior_std, scan(model, samples.nu, chunk), chunk)


def _enough(n: int, p: int) -> None:
    """Refuse fewer than ten samples per parameter (ConfigError)."""
    if n < 10 * max(p, 1):
        raise ConfigError("samples", f"{n} samples are too few for {p} parameters")


def fit_statistics(extent: Extent, normal: NormalEquations, bias: BiasStatistics | None,
                   map_parts: MapParts, model: DampingModel, body: RigidBody,
                   options: FitOptions | None = None, prior: FloatArray | None = None,
                   prior_std: FloatArray | None = None,
                   scan_data: Callable[[FloatArray], Violations] | None = None,
                   chunk: int = CHUNK) -> Fit:
    """:func:`fit` of samples that are not here: from their extent and statistics, with the
    passes over them run part by part where the parts are held (a pooled fit's logs, each
    on its worker).

    Parameters
    ----------
    extent : Extent
        That of the samples (:meth:`Extent.of`, or joined over the parts).
    normal : NormalEquations
        Their statistics (:func:`accumulate`).
    bias : BiasStatistics or None
        Those of the sensor-bias refits (None: the options give no sensor a bias).
    map_parts : MapParts
        Runs a function on every part of the samples where it is held
        (:data:`~dampest_ros.core.identification.covariance.MapParts`): the robust
        covariance's pass when ``normal`` holds no blocks of its length, and the
        dissipativity scan but for ``scan_data``.
    model, body, options, prior, prior_std
        As for :func:`fit`.
    scan_data : callable, optional
        θ → :func:`violations` of all the samples (default: part by part through
        ``map_parts``).
    chunk : int
        Samples per chunk.
    """
    opts = options or FitOptions()
    names = model.parameter_names
    p = len(names)
    _enough(extent.n, p)
    prior_v = np.zeros(p) if prior is None else np.asarray(prior, dtype=float)
    problem = _Problem(normal, opts, prior_v, prior_std,
                       model.lower_bounds() if opts.method == "bounded" else None)
    live, flags = _excited(normal, names)
    w = _reweighted(problem, live)
    free = _free(model, extent, opts, live, prior_v, flags)
    T, W, s = determined_directions(normal.total(w)[0], free, opts.max_vif)
    theta = problem.solve(w, free, T)
    cov = covariance(extent, model, body, theta, w, normal, free, T, opts, bias, map_parts,
                     chunk)
    combos = _combinations(W, s, names, free, theta, cov, flags)
    flags.update(_flags(theta, cov, names, parameter_scale(normal, theta), opts,
                        free & np.array([n not in flags for n in names])))
    theta, constrained, power = _dissipative(
        problem, model, extent.flown,
        scan_data or partial(_scan_parts, map_parts=map_parts, model=model, chunk=chunk),
        theta, cov, w, free, T, chunk)
    N = problem.n
    rss = normal.rss(theta)
    limits = np.asarray(opts.speed_range if opts.speed_range is not None else extent.speed)
    axes = axis_check(AxisStatistics.join(map_parts(partial(
        _part_axis_statistics, model=model, body=body, cutoff=opts.cutoff,
        limits=np.maximum(limits, 1e-9), chunk=chunk))), theta, cov)
    return Fit(names=names, theta=theta, cov=axes.scaled(cov, model), axes=axes,
               sigma=np.sqrt(rss / N), method=opts.method,
               n=N, rss=rss, tss=total_sum_of_squares(normal),
               cond=_scaled_condition(normal, free),
               flags=flags, cv_rmse=np.sqrt(_cross_validated_rss(problem, w, free, T, power) / N),
               n_eff=_effective_samples(extent, N, opts.cutoff),
               blocks=block_count(extent, block_length(extent, opts, T.shape[1])),
               held=~free, combinations=combos, constrained=constrained, rank=T.shape[1])
