"""Offline batch identification of the damping parameters θ from samples.

Regression form (FRD, per sample n): y_n = τ_n − M ν̇_n − C(ν_n)ν_n − g(η_n) = Φ(ν_n) θ + e_n.

Normal equations are accumulated in chunks of samples (memory does not grow with the length
of the data) separately per degree of freedom i and per cross-validation fold f:
A_{f,i} = Σ Φ_iᵀ Φ_i, b_{f,i} = Σ Φ_iᵀ y_i, c_{f,i} = Σ y_i². Everything below (OLS, per-DOF
weighted LS, ridge, bounded LS, MAP, held-out residuals, AIC/BIC) is closed-form in them.
A second pass computes block scores for a covariance that is robust to correlated residuals.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, optimize, stats

from dampest_ros.core.damping import DampingModel
from dampest_ros.core.frames import matrix_from_euler
from dampest_ros.core.preprocess import zero_phase
from dampest_ros.core.rigid_body import DOF_NAMES, ConfigError, RigidBody
from dampest_ros.core.samples import Samples

FloatArray = NDArray[np.float64]

METHODS = ("ols", "wls", "ridge", "bounded", "map")
CHUNK = 8000  # samples per chunk of Φ (n, 6, p): ~10 MB for p = 24, whatever the log length
STRETCH = 20000  # samples per stretch of the sensor-bias sensitivity on long logs


def target(samples: Samples, body: RigidBody, index: slice | None = None) -> FloatArray:
    """y = τ − M ν̇ − C(ν)ν − g(η), the force the damping must explain, shape (N, 6).

    M and C_A act as the vehicle's ``added_mass_terms`` say (:attr:`RigidBody.M_inertial`,
    :meth:`RigidBody.coriolis_force`)."""
    sl = index if index is not None else slice(None)
    nu, nu_dot = samples.nu[sl], samples.nu_dot[sl]
    R = matrix_from_euler(samples.euler[sl])
    # y = τ − M ν̇ − C(ν)ν − g(η)
    return np.asarray(samples.tau[sl] - nu_dot @ body.M_inertial.T - body.coriolis_force(nu)
                      - body.restoring(R), dtype=float)


def memory_states(samples: Samples, model: DampingModel) -> FloatArray:
    """Memory filter states of the model along every segment, shape (N, n_states)."""
    out = np.zeros((len(samples), len(model.memory_rates)))
    if out.shape[1]:
        for sl in samples.segments():
            out[sl] = model.memory_states(samples.t[sl], samples.nu[sl])
    return out


def iter_regression(samples: Samples, model: DampingModel, body: RigidBody,
                    chunk: int = CHUNK, cutoff: float = 0.0, margin: float = 5.0,
                    offset: FloatArray | None = None, decimate: bool = False,
                    regressor: Callable[[FloatArray, FloatArray | None], FloatArray] | None
                    = None
                    ) -> Iterator[tuple[slice | NDArray[np.int64], FloatArray, FloatArray]]:
    """Yield (rows, Φ (n, 6, p), y (n, 6)) over chunks of at most ``chunk`` samples.

    With ``cutoff`` > 0 both y and every column of Φ are low-passed (zero phase) along time
    within each segment: "parallel filtering". Since θ is constant, LP(y) = LP(Φ) θ holds
    exactly however nonlinear Φ is, whereas filtering ν before forming |ν|ν does not. Chunks
    are filtered with ``margin`` seconds of neighbouring data on both sides, so memory stays
    flat while the result equals filtering whole segments (to the filter's decay).

    ``offset`` (6,) is added to ν first: the data as a sensor bias would have made them.

    ``regressor(ν, z)`` replaces ``model.regressor`` (the model still gives the memory states
    z): any array with time on axis 0, e.g. (n, 1, m) features shared by every row.

    With ``decimate`` (and ``cutoff`` > 0) only every k-th sample is yielded, k the largest
    step that keeps four samples per period of the cutoff: the low-passed signals carry no
    more information than that, and the normal equations cost k times less. Rows are then
    global sample indices (the same whatever the chunking).
    """
    if offset is not None:
        samples = Samples(samples.t, samples.nu + offset, samples.nu_dot, samples.tau,
                          samples.euler, samples.depth, samples.segment)
    z = memory_states(samples, model)
    has_z = z.shape[1] > 0
    pad = round(margin * samples.rate) if cutoff > 0 else 0
    step = max(1, int(samples.rate / (4.0 * cutoff))) if decimate and cutoff > 0 else 1
    for seg in samples.segments():
        s0, s1 = seg.start or 0, seg.stop or 0
        for start in range(s0, s1, chunk):
            stop = min(start + chunk, s1)
            a, b = max(s0, start - pad), min(s1, stop + pad)
            ext = slice(a, b)
            Phi = (regressor or model.regressor)(samples.nu[ext], z[ext] if has_z else None)
            y = target(samples, body, ext)
            if cutoff > 0:
                Phi = zero_phase(Phi, samples.rate, cutoff)
                y = zero_phase(y, samples.rate, cutoff)
            if step > 1:
                rows = np.arange(start + (-start) % step, stop, step)
                yield rows, Phi[rows - a], y[rows - a]
            else:
                core = slice(start - a, stop - a)
                yield slice(start, stop), Phi[core], y[core]


@dataclass
class NormalEquations:
    """Per-fold, per-DOF sufficient statistics of the regression.

    Attributes
    ----------
    A : ndarray, shape (F, 6, p, p)
    b : ndarray, shape (F, 6, p)
    c : ndarray, shape (F, 6)
        Σ y².
    n : ndarray, shape (F,)
        Samples per fold.
    """

    A: FloatArray
    b: FloatArray
    c: FloatArray
    n: FloatArray

    def total(self, weights: FloatArray, exclude: int | None = None
              ) -> tuple[FloatArray, FloatArray, float]:
        """Σ over folds (but ``exclude``) and DOFs of w_i A, w_i b, w_i c."""
        keep = np.ones(len(self.n), dtype=bool)
        if exclude is not None:
            keep[exclude] = False
        A = np.einsum("i,fipq->pq", weights, self.A[keep])
        b = np.einsum("i,fip->p", weights, self.b[keep])
        return A, b, float(np.einsum("i,fi->", weights, self.c[keep]))

    def rss(self, theta: FloatArray, fold: int | None = None) -> FloatArray:
        """Residual sum of squares per DOF, Σ (y − Φθ)², shape (6,)."""
        sel = slice(None) if fold is None else slice(fold, fold + 1)
        A, b, c = self.A[sel].sum(0), self.b[sel].sum(0), self.c[sel].sum(0)
        # ‖y − Φθ‖² = yᵀy − 2 θᵀΦᵀy + θᵀΦᵀΦθ (≥ 0; rounding can dip below for exact fits)
        return np.maximum(c - 2 * b @ theta + np.einsum("ipq,p,q->i", A, theta, theta), 0.0)


def fold_index(n: int, folds: int) -> NDArray[np.int64]:
    """The contiguous time fold (0..folds−1) of each of n samples, shape (n,)."""
    return np.minimum((np.arange(n) * folds) // max(n, 1), folds - 1)


def accumulate(samples: Samples, model: DampingModel, body: RigidBody, folds: int = 5,
               chunk: int = CHUNK, cutoff: float = 0.0) -> NormalEquations:
    """Accumulate :class:`NormalEquations` over contiguous time folds in chunks.

    Parameters
    ----------
    samples : Samples
    model : DampingModel
    body : RigidBody
    folds : int
        Number of contiguous blocks for cross-validation.
    chunk : int
        Samples per chunk (memory ∝ chunk · 6 · p).
    cutoff : float
        Parallel low-pass of y and Φ (Hz); 0: none.
    """
    p, N = model.n_params, len(samples)
    fold_of = fold_index(N, folds)
    A = np.zeros((folds, 6, p, p))
    b = np.zeros((folds, 6, p))
    c = np.zeros((folds, 6))
    n = np.zeros(folds)
    for sl, Phi, y in iter_regression(samples, model, body, chunk, cutoff, decimate=True):
        fo = fold_of[sl]
        for f in np.unique(fo):
            m = fo == f
            P, Y = Phi[m], y[m]
            # per DOF i: ΦᵢᵀΦᵢ, Φᵢᵀyᵢ, yᵢᵀyᵢ
            A[f] += np.einsum("nip,niq->ipq", P, P)
            b[f] += np.einsum("nip,ni->ip", P, Y)
            c[f] += np.einsum("ni,ni->i", Y, Y)
            n[f] += len(Y)
    return NormalEquations(A, b, c, n)


@dataclass
class Fit:
    """Result of a batch identification.

    Attributes
    ----------
    names : list of str
    theta : ndarray, shape (p,)
        Estimate; unidentifiable parameters hold their prior (or 0) and are listed in
        ``flags``.
    cov : ndarray, shape (p, p)
        Covariance (block-robust), NaN rows/columns for unidentifiable parameters.
    sigma : ndarray, shape (6,)
        Residual standard deviation per DOF (N, N·m).
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

    @property
    def std(self) -> FloatArray:
        """Standard deviations, shape (p,)."""
        return np.sqrt(np.abs(np.diag(self.cov)))

    def interval(self, level: float = 0.95) -> FloatArray:
        """Two-sided confidence intervals, shape (p, 2).

        Student-t with (blocks − 1) degrees of freedom, as suits a covariance estimated from
        that many block scores; normal when the block count is unknown.
        """
        z = float(stats.t.ppf(0.5 + level / 2, self.blocks - 1) if self.blocks > 1
                  else stats.norm.ppf(0.5 + level / 2))
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
        """Number of estimated parameters (unidentifiable ones are fixed)."""
        return len(self.names) - len(self.flags)

    @property
    def aic(self) -> float:
        """Akaike information criterion."""
        return -2 * self.log_likelihood + 2 * self.n_free

    @property
    def bic(self) -> float:
        """Bayesian information criterion."""
        return -2 * self.log_likelihood + self.n_free * float(np.log(self.n_eff))


@dataclass(frozen=True)
class FitOptions:
    """Solver settings.

    Attributes
    ----------
    method : {'ols', 'wls', 'ridge', 'bounded', 'map'}
    ridge : float
        Ridge strength relative to the diagonal of the information matrix.
    block : float
        Block length (s) for the robust covariance.
    max_rel_halfwidth : float
        A parameter whose 95 % half-width exceeds this fraction of its scale is flagged.
    max_vif : float
        Variance inflation above this flags a parameter as collinear.
    cutoff : float
        Parallel low-pass applied to y and Φ (Hz); 0 disables it. It also sets the effective
        sample count n_eff = 2 · cutoff · T used by AIC/BIC.
    gyro_bias, dvl_bias : float
        Standard deviation of an unknown constant gyro (rad/s) and DVL (m/s) bias per axis:
        the sensor error budget that :func:`bias_covariance` propagates into θ. 0 ignores
        it.
    speed_range : tuple of 6 float, optional
        Speeds the vehicle can reach per DOF; quadratic terms of DOFs flown below 15 % of
        it are flagged (:func:`speed_coverage_flags`).
    """

    method: str = "wls"
    ridge: float = 1e-3
    block: float = 10.0
    max_rel_halfwidth: float = 0.5
    max_vif: float = 1e4
    cutoff: float = 2.0
    gyro_bias: float = 2e-4
    dvl_bias: float = 1e-3
    speed_range: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ConfigError("method", f"unknown method {self.method!r}; use one of {METHODS}")


def rank_solve(A: FloatArray, b: FloatArray, tol: float = 1e-10
               ) -> tuple[FloatArray, NDArray[np.int64]]:
    """Solve A x = b for a symmetric PSD A that may be singular, never raising.

    Cholesky when A is clearly positive definite; otherwise a rank-revealing QR with column
    pivoting: columns whose pivot |R_kk| falls below ``tol`` · |R_00| depend (to that
    tolerance) on the columns chosen before them and are held at 0.

    Parameters
    ----------
    A : ndarray, shape (p, p)
        Normal-equation matrix, best with a unit diagonal (scale the columns first).
    b : ndarray, shape (p,)
    tol : float
        Relative pivot tolerance (A is a Gram matrix: 1e-10 is a column condition of 1e5).

    Returns
    -------
    x : ndarray, shape (p,)
    dropped : ndarray of int
        Indices of the columns held at 0, in the order QR found them dependent.
    """
    p = len(b)
    x = np.zeros(p)
    if p == 0:
        return x, np.zeros(0, dtype=np.int64)
    try:
        c = linalg.cho_factor(A)
        if np.min(np.abs(np.diag(c[0]))) ** 2 > tol * max(float(np.max(np.diag(A))), 1e-300):
            return np.asarray(linalg.cho_solve(c, b), dtype=float), np.zeros(0, dtype=np.int64)
    except (linalg.LinAlgError, ValueError):
        pass
    _, R, piv = linalg.qr(A, pivoting=True, mode="economic")
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > tol * max(float(d[0]), 1e-300))) if np.isfinite(d).all() else 0
    keep = np.sort(piv[:rank])
    if rank:
        x[keep] = linalg.lstsq(A[np.ix_(keep, keep)], b[keep])[0]
    return x, np.asarray(piv[rank:], dtype=np.int64)


def _solve(A: FloatArray, b: FloatArray, free: NDArray[np.bool_], fixed: FloatArray,
           lower: FloatArray | None = None) -> FloatArray:
    """Minimise θᵀAθ − 2bᵀθ over the free parameters, the others held at ``fixed``."""
    theta = fixed.copy()
    if not free.any():
        return theta
    Af = A[np.ix_(free, free)]
    bf = b[free] - A[np.ix_(free, ~free)] @ fixed[~free]
    s = 1.0 / np.sqrt(np.maximum(np.diag(Af), 1e-300))
    As = Af * np.outer(s, s)  # column-scaled: well conditioned across units
    if lower is None or not np.isfinite(lower[free]).any():
        theta[free] = s * rank_solve(As, s * bf)[0]
        return theta
    # bounded: ‖Lᵀx − L⁻¹b‖² has the same minimiser as xᵀAx − 2bᵀx (A = L Lᵀ)
    L = linalg.cholesky(As, lower=True)
    rhs = linalg.solve_triangular(L, s * bf, lower=True)
    lo = lower[free] / s
    res = optimize.lsq_linear(L.T, rhs, bounds=(lo, np.full(len(lo), np.inf)),
                              method="bvls", tol=1e-12)
    theta[free] = s * res.x
    return theta


def _flags(A: FloatArray, theta: FloatArray, cov: FloatArray, names: list[str],
           scale: FloatArray, opts: FitOptions) -> dict[str, str]:
    """Named reasons why parameters cannot be determined from the data."""
    flags: dict[str, str] = {}
    d = np.diag(A)
    dmax = float(d.max()) if len(d) else 0.0
    z = float(stats.norm.ppf(0.975))
    live = d > 1e-12 * max(dmax, 1e-300)
    s = 1.0 / np.sqrt(np.maximum(d, 1e-300))
    As = A * np.outer(s, s)
    vif = np.full(len(d), np.inf)
    try:
        vif[live] = np.diag(linalg.inv(As[np.ix_(live, live)]))
    except linalg.LinAlgError:
        pass
    corr = As.copy()
    np.fill_diagonal(corr, 0.0)
    for j, name in enumerate(names):
        if d[j] <= 1e-12 * max(dmax, 1e-300):
            flags[name] = "no excitation: its regressor column is zero in these data"
        elif vif[j] > opts.max_vif:
            k = int(np.argmax(np.abs(corr[j])))
            flags[name] = (f"collinear with {names[k]} (variance inflation {vif[j]:.3g}); "
                           "the data cannot separate them")
        elif z * np.sqrt(abs(cov[j, j])) > opts.max_rel_halfwidth * scale[j]:
            flags[name] = (f"poorly determined: 95 % half-width {z * np.sqrt(abs(cov[j, j])):.3g}"
                           f" exceeds {opts.max_rel_halfwidth:.0%} of its scale {scale[j]:.3g}"
                           "; excite this degree of freedom more (speed range, amplitude)")
    return flags


def speed_coverage_flags(model: DampingModel, samples: Samples, speed_range: FloatArray,
                         min_share: float = 0.15) -> dict[str, str]:
    """Quadratic coefficients of DOFs whose speed range the data do not cover.

    A quadratic drag coefficient fitted only at low speed is an extrapolation wherever the
    vehicle is faster; when the 99th percentile of |ν_i| stays below ``min_share`` of the
    vehicle's speed range in DOF i, every quadratic parameter of that DOF is flagged.

    Parameters
    ----------
    speed_range : ndarray, shape (6,)
        Speeds the vehicle reaches (e.g. at half thrust), m/s and rad/s.
    """
    quad = model.term("quadratic")
    if quad is None or len(samples) == 0:
        return {}
    # column by column: no copy of the whole (n, 6) velocity array on long logs
    flown = np.array([np.percentile(np.abs(samples.nu[:, i]), 99) for i in range(6)])
    flags = {}
    for name, b in zip(quad.parameter_names, quad.bases, strict=True):
        i = int(np.argmax(np.abs(np.diag(b.B))))
        if flown[i] < min_share * speed_range[i]:
            flags[name] = (f"low speed only: |{DOF_NAMES[i]}| ≤ {flown[i]:.3g} in these data, "
                           f"{flown[i] / speed_range[i]:.0%} of the {speed_range[i]:.3g} the "
                           f"vehicle reaches; fly faster in {DOF_NAMES[i]} to identify it")
    return flags


def parameter_scale(ne: NormalEquations, theta: FloatArray, prior: FloatArray) -> FloatArray:
    """The size a parameter must be known to, shape (p,).

    |prior| where the prior is nonzero (an estimate that is inflated by confounding must not
    raise its own bar); otherwise max(|θ̂|, force scale), the force scale being the value
    whose force is 10 % of the RMS target force in the DOF the parameter acts on, so that
    parameters whose truth may be zero are judged on what they could contribute.
    """
    Ad = np.einsum("ipp->ip", ne.A.sum(0))  # Σ Φ_{·,i,j}² per DOF i and parameter j
    c = ne.c.sum(0)
    i = np.argmax(Ad, axis=0)
    col = np.sqrt(np.maximum(Ad[i, np.arange(len(i))], 1e-300))
    force = 0.1 * np.sqrt(c[i]) / col
    return np.where(prior != 0, np.abs(prior), np.maximum(np.abs(theta), force))


def fit(samples: Samples, model: DampingModel, body: RigidBody,
        options: FitOptions | None = None, prior: FloatArray | None = None,
        prior_std: FloatArray | None = None, normal: NormalEquations | None = None,
        chunk: int = CHUNK) -> Fit:
    """Identify θ from samples.

    Parameters
    ----------
    samples : Samples
    model : DampingModel
        Term structure to identify.
    body : RigidBody
        Known M (rigid body + added mass) and restoring data.
    options : FitOptions, optional
    prior : ndarray, shape (p,), optional
        Prior mean (MAP), the value of unidentifiable parameters, and the scale that judges
        whether a parameter is determined.
    prior_std : ndarray, shape (p,), optional
        Prior standard deviations for MAP.
    normal : NormalEquations, optional
        Precomputed statistics (saves the first pass).
    chunk : int
        Samples per chunk.

    Returns
    -------
    Fit
    """
    opts = options or FitOptions()
    names = model.parameter_names
    p = len(names)
    if len(samples) < 10 * max(p, 1):
        raise ConfigError("samples", f"{len(samples)} samples are too few for {p} parameters")
    ne = normal or accumulate(samples, model, body, chunk=chunk, cutoff=opts.cutoff)
    prior_v = np.zeros(p) if prior is None else np.asarray(prior, dtype=float)
    N = int(ne.n.sum())
    w = np.ones(6)
    free = np.ones(p, dtype=bool)
    lower = model.lower_bounds() if opts.method == "bounded" else None

    def solve(weights: FloatArray, free_: NDArray[np.bool_], exclude: int | None = None
              ) -> FloatArray:
        A, b, _ = ne.total(weights, exclude)
        if opts.method == "ridge":
            A = A + opts.ridge * np.diag(np.diag(A))
        if opts.method == "map":
            if prior_std is None:
                raise ConfigError("prior", "MAP needs a prior with standard deviations")
            P = 1.0 / np.maximum(np.asarray(prior_std, float), 1e-12) ** 2
            A = A + np.diag(P)
            b = b + P * prior_v
        return _solve(A, b, free_, prior_v, lower)

    def weights_for(theta: FloatArray) -> FloatArray:
        if opts.method == "ols":
            return np.ones(6)
        # per-DOF noise variances from the residuals → weights 1/σ²
        s2 = np.maximum(ne.rss(theta) / N, 1e-12)
        return np.asarray(1.0 / s2)

    # columns that are zero in these data cannot be estimated at all: hold them from the start
    d = np.diag(ne.total(w)[0])
    free = d > 1e-12 * max(float(d.max()), 1e-300)
    theta = solve(w, free)
    for _ in range(3):
        w = weights_for(theta)
        theta = solve(w, free)
    cov = robust_covariance(samples, model, body, theta, w, ne, free, opts, chunk) \
        + bias_covariance(samples, model, body, theta, w, free, opts, chunk)
    A_w, _, _ = ne.total(w)
    flags = _flags(A_w, theta, cov, names, parameter_scale(ne, theta, prior_v), opts)
    if opts.speed_range is not None:
        flags.update(speed_coverage_flags(model, samples, np.asarray(opts.speed_range)))
    if flags:
        free = np.array([n not in flags for n in names])
        theta = solve(w, free)
        cov = robust_covariance(samples, model, body, theta, w, ne, free, opts, chunk) \
            + bias_covariance(samples, model, body, theta, w, free, opts, chunk)
    cv = np.zeros(6)
    for f in range(len(ne.n)):
        th_f = solve(w, free, exclude=f)
        cv += ne.rss(th_f, fold=f)
    rss = ne.rss(theta)
    tss = total_sum_of_squares(ne)
    A_s, _, _ = ne.total(np.ones(6))
    d = np.sqrt(np.maximum(np.diag(A_s[np.ix_(free, free)]), 1e-300))
    ev = np.linalg.eigvalsh(A_s[np.ix_(free, free)] / np.outer(d, d)) if free.any() else [1.0]
    duration = len(samples) / samples.rate if samples.rate else float(N)
    return Fit(names=names, theta=theta, cov=cov, sigma=np.sqrt(rss / N), method=opts.method,
               n=N, rss=rss, tss=tss, cond=float(max(ev) / max(min(ev), 1e-300)), flags=flags,
               cv_rmse=np.sqrt(cv / N),
               n_eff=min(float(N), 2 * opts.cutoff * duration) if opts.cutoff > 0 else float(N),
               blocks=block_count(samples, opts.block))


def total_sum_of_squares(ne: NormalEquations) -> FloatArray:
    """Σ (y − ȳ)² per DOF from the normal equations' Σ y² and the mean of y, shape (6,).

    The mean is the coefficient of a constant column, which the statistics do not hold, so
    Σ y² is returned: the NSE is then 1 − RSS/Σy², conservative for signals with an offset.
    """
    return np.asarray(ne.c.sum(0))


def block_index(samples: Samples, block: float) -> NDArray[np.int64]:
    """Index 0..B−1 of the ``block``-second block (within its segment) of every sample."""
    block_of = np.floor((samples.t - samples.t[0]) / block).astype(np.int64)
    block_of += samples.segment * (int(block_of.max()) + 1)
    return np.unique(block_of, return_inverse=True)[1].astype(np.int64)


def block_count(samples: Samples, block: float) -> int:
    """Number of blocks B of the robust covariance."""
    return int(block_index(samples, block).max()) + 1 if len(samples) else 0


def robust_covariance(samples: Samples, model: DampingModel, body: RigidBody,
                      theta: FloatArray, weights: FloatArray, ne: NormalEquations,
                      free: NDArray[np.bool_], opts: FitOptions, chunk: int = CHUNK
                      ) -> FloatArray:
    """Block sandwich covariance A⁻¹ (Σ_b s_b s_bᵀ) A⁻¹ of the free parameters.

    s_b = Σ_{n ∈ block b} Σ_i w_i Φ_{n,i}ᵀ r_{n,i} is the weighted score of a block of
    ``opts.block`` seconds; summing within blocks makes the estimate robust to residuals
    that are correlated over less than a block (filtered noise, unmodelled slow effects).
    """
    p = model.n_params
    cov = np.full((p, p), np.nan)
    if not free.any():
        return cov
    A, _, _ = ne.total(weights)
    Af = A[np.ix_(free, free)]
    block_idx = block_index(samples, opts.block)
    S = np.zeros((int(block_idx.max()) + 1, int(free.sum())))
    for sl, Phi, y in iter_regression(samples, model, body, chunk, opts.cutoff,
                                      decimate=True):
        r = y - Phi @ theta
        # weighted score of each sample: Σ_i w_i Φ_iᵀ r_i
        g = np.einsum("nip,ni,i->np", Phi[:, :, free], r, weights)
        np.add.at(S, block_idx[sl], g)
    B = len(S)
    meat = S.T @ S * (B / max(B - 1, 1))
    Ainv = linalg.inv(Af)
    cov[np.ix_(free, free)] = Ainv @ meat @ Ainv
    return cov


def bias_covariance(samples: Samples, model: DampingModel, body: RigidBody,
                    theta: FloatArray, weights: FloatArray, free: NDArray[np.bool_],
                    opts: FitOptions, chunk: int = CHUNK) -> FloatArray:
    """Covariance of θ caused by unknown constant sensor biases (the error budget).

    For each axis k of the gyro (σ = ``opts.gyro_bias``) and of the DVL (``opts.dvl_bias``)
    the data are refitted with ν offset by σ e_k; the change Δθ_k is one standard deviation
    of the error that bias causes, and Σ_k Δθ_k Δθ_kᵀ is the covariance (biases independent).
    Such errors are constant over the record, so the residuals cannot reveal them.
    """
    p = model.n_params
    cov = np.zeros((p, p))
    sigma = np.array([opts.dvl_bias] * 3 + [opts.gyro_bias] * 3)
    if not free.any() or not np.any(sigma > 0):
        return cov
    # a sensitivity is an average property of the data: on long logs, three evenly spread
    # stretches of STRETCH samples give it at a fraction of the cost
    data = samples
    if len(samples) > 3 * STRETCH:
        starts = np.linspace(0, len(samples) - STRETCH, 3).astype(int)
        index = np.concatenate([np.arange(a, a + STRETCH) for a in starts])
        data = samples.take(index)
        data.segment = np.repeat(np.arange(3), STRETCH) + 3 * data.segment

    def refit(offset: FloatArray | None) -> FloatArray:
        A = np.zeros((p, p))
        b = np.zeros(p)
        for _, Phi, y in iter_regression(data, model, body, chunk, opts.cutoff,
                                         offset=offset, decimate=True):
            A += np.einsum("nip,niq,i->pq", Phi, Phi, weights)
            b += np.einsum("nip,ni,i->p", Phi, y, weights)
        return _solve(A, b, free, theta)

    base = theta if data is samples else refit(None)
    for k in np.flatnonzero(sigma > 0):
        offset = np.zeros(6)
        offset[k] = sigma[k]
        d = refit(offset) - base
        cov += np.outer(d, d)
    return cov


def dof_excitation(samples: Samples) -> FloatArray:
    """RMS of each velocity component (m/s, rad/s), shape (6,)."""
    return np.asarray(np.sqrt(np.mean(samples.nu**2, axis=0)))

