"""Least squares on the base regressor, per-joint weights, covariance, and the physically
consistent fit.

Data enter once, as per-joint normal equations (:class:`JointNormals`, accumulated in
chunks, so an hour at 1 kHz never holds its regressor in memory). Rows of joint j are used
only where |q̇_j| ≥ v_min: a Coulomb term is undefined at rest, and a real (or MuJoCo's soft)
dry friction does not follow sign(q̇) near a velocity reversal.

OLS weights all joints alike; WLS weights joint j by 1/σ_j², σ_j its OLS residual
(Gautier & Poignet 2001). Covariance of the base parameters: (Σ_j G_j / σ_j²)⁻¹.

Physically consistent fit: each link's ten parameters come from its pseudo-inertia
J = [[½ tr(I) 1 − I, m c], [(m c)ᵀ, m]] = L Lᵀ, L lower triangular with a positive (log-
parameterised) diagonal (Rucker & Wensing 2022), bounded below at 1e-5 of the nominal's, so
every link has m > 0 and J ≻ 0 with a margin; armature, viscous and Coulomb terms are ≥ 0.
It minimises the same weighted squared residual (scipy's bounded trust-region least squares,
analytic Jacobian), and among the full parameter sets with the same base parameters picks the
one nearest the nominal (weight ``prior_weight``, tiny): the nominal never sets a base
parameter. Near a link's bound the solver creeps (its own tolerances are met after thousands
of evaluations, if ever), so it also stops, converged, once the last ``SETTLE_WINDOW``
iterations lowered the objective by less than ``SETTLE_RTOL`` of itself and moved no base
parameter by more than ``SETTLE_SIGMA`` of its standard deviation: what more evaluations
would change is below what the data resolve.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from dampest_ros.core.arm.base import BaseParameters

FloatArray = NDArray[np.float64]

#: Iterations over which the physically consistent fit's progress is judged.
SETTLE_WINDOW = 50
#: Relative decrease of its objective over the window below which it has settled.
SETTLE_RTOL = 3e-3
#: Largest move of a base parameter over the window, in its standard deviations.
SETTLE_SIGMA = 0.02


@dataclass
class JointNormals:
    """Per-joint normal equations of τ_j = Y_j π (Y in full parameters).

    Attributes
    ----------
    G : ndarray, shape (n, p, p)
        Σ Y_jᵀ Y_j over the rows used.
    g : ndarray, shape (n, p)
        Σ Y_jᵀ τ_j.
    c : ndarray, shape (n,)
        Σ τ_j² (N² m²).
    count : ndarray, shape (n,)
        Rows used per joint.
    """

    G: FloatArray
    g: FloatArray
    c: FloatArray
    count: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @classmethod
    def empty(cls, n: int, p: int) -> JointNormals:
        """Zero sums for n joints and p parameters."""
        return cls(np.zeros((n, p, p)), np.zeros((n, p)), np.zeros(n),
                   np.zeros(n, dtype=np.int64))

    def add(self, Y: FloatArray, tau: FloatArray, use: NDArray[np.bool_]) -> None:
        """Accumulate a chunk.

        Parameters
        ----------
        Y : ndarray, shape (N, n, p)
            Regressor rows.
        tau : ndarray, shape (N, n)
            Measured torques (N m).
        use : ndarray of bool, shape (N, n)
            Which rows enter.
        """
        w = use.astype(float)
        for j in range(Y.shape[1]):  # per joint (n), over the columns its row has
            rows = Y[:, j, :]
            cols = np.flatnonzero(np.any(rows != 0.0, axis=0))
            Yj = rows[:, cols]
            Yw = Yj * w[:, j, None]
            # G_j += Y_jᵀ W Y_j, g_j += Y_jᵀ W τ_j on those columns (a row of a serial arm
            # holds only the links beyond its joint: the others' blocks stay zero)
            self.G[j][np.ix_(cols, cols)] += Yw.T @ Yj
            self.g[j, cols] += Yw.T @ tau[:, j]
        self.c += np.einsum("kj,kj->j", w, tau * tau)
        self.count += use.sum(axis=0)

    def rss(self, theta: FloatArray) -> FloatArray:
        """Residual sum of squares per joint of full parameters θ, shape (n,) (N² m²)."""
        return (self.c - 2.0 * self.g @ theta
                + np.einsum("p,jpq,q->j", theta, self.G, theta))


@dataclass(frozen=True)
class BaseFit:
    """Base parameters fitted by weighted least squares.

    Attributes
    ----------
    theta : ndarray, shape (b,)
        Base parameters.
    cov : ndarray, shape (b, b)
        Their covariance.
    sigma : ndarray, shape (n,)
        Residual standard deviation per joint (N m).
    weights : ndarray, shape (n,)
        Row weight per joint (1/σ_j² for WLS, 1 for OLS).
    """

    theta: FloatArray
    cov: FloatArray
    sigma: FloatArray
    weights: FloatArray

    @property
    def std(self) -> FloatArray:
        """Standard deviation of each base parameter, shape (b,)."""
        return np.sqrt(np.diag(self.cov))


def _restrict(normals: JointNormals, base: BaseParameters
              ) -> tuple[FloatArray, FloatArray]:
    """The normal equations in the base parameters: G_b (n, b, b), g_b (n, b)."""
    i = base.independent
    return normals.G[:, i][:, :, i], normals.g[:, i]


def fit_base(normals: JointNormals, base: BaseParameters, weighted: bool = True,
             rows_per_independent: float = 1.0) -> BaseFit:
    """OLS (``weighted=False``) or two-pass WLS of the base parameters.

    Parameters
    ----------
    normals : JointNormals
        In full parameters.
    base : BaseParameters
    weighted : bool
    rows_per_independent : float
        Rows per independent noise sample (≥ 1): low-passed noise sampled faster than twice
        its bandwidth is correlated from row to row, and the covariance grows by this factor.

    Returns
    -------
    BaseFit

    Raises
    ------
    ValueError
        If a joint has no usable rows or the base parameters are not determined by the data
        (the information matrix is singular: the trajectory does not excite them).
    """
    if np.any(normals.count == 0):
        raise ValueError("a joint has no rows with |q̇| above the minimum speed; the "
                         "trajectory must move every joint")
    Gb, gb = _restrict(normals, base)
    n = len(normals.c)
    dof = np.maximum(normals.count - base.size / n, 1.0)

    def solve(w: FloatArray) -> tuple[FloatArray, FloatArray]:
        A = np.einsum("j,jpq->pq", w, Gb)
        cond = np.linalg.cond(A)
        if not np.isfinite(cond) or cond > 1e14:
            raise ValueError(f"the information matrix is singular (condition {cond:.3g}): "
                             "the data do not excite every base parameter")
        theta = np.linalg.solve(A, np.einsum("j,jp->p", w, gb))
        full = np.zeros(normals.G.shape[1])
        full[base.independent] = theta
        return theta, full

    w = np.ones(n)
    theta, full = solve(w)
    sigma = np.sqrt(np.maximum(normals.rss(full), 0.0) / dof)
    if weighted:
        # σ_j floored at 1e-6 of the joint's RMS torque (noise-free data: equal footing)
        rms = np.sqrt(normals.c / np.maximum(normals.count, 1))
        w = 1.0 / np.maximum(sigma, 1e-6 * rms + 1e-300) ** 2
        theta, full = solve(w)
        sigma = np.sqrt(np.maximum(normals.rss(full), 0.0) / dof)
    # Cov = (Σ_j w_j G_j)⁻¹ Σ_j w_j² σ_j² G_j (Σ_j w_j G_j)⁻¹ (= (Σ G_j/σ_j²)⁻¹ for WLS)
    Ainv = np.linalg.inv(np.einsum("j,jpq->pq", w, Gb))
    meat = np.einsum("j,jpq->pq", w * w * sigma * sigma, Gb)
    return BaseFit(theta, max(rows_per_independent, 1.0) * Ainv @ meat @ Ainv, sigma, w)


# --- physically consistent fit -----------------------------------------------------------

_TRIL = np.tril_indices(4)


def _params_of_J(J: FloatArray) -> FloatArray:
    """Ten inertial parameters of pseudo-inertias J, shape (..., 4, 4) → (..., 10)."""
    S, h, m = J[..., :3, :3], J[..., :3, 3], J[..., 3, 3]
    tr = np.trace(S, axis1=-2, axis2=-1)
    # I = tr(Σ) 1 − Σ  (Σ = ½ tr(I) 1 − I)
    return np.stack([m, h[..., 0], h[..., 1], h[..., 2], tr - S[..., 0, 0], -S[..., 0, 1],
                     tr - S[..., 1, 1], -S[..., 0, 2], -S[..., 1, 2], tr - S[..., 2, 2]],
                    axis=-1)


def links_from_cholesky(x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Inertial parameters of links from the log-Cholesky factors of their pseudo-inertias,
    and the Jacobian.

    Parameters
    ----------
    x : ndarray, shape (n, 10)
        Per link: lower triangle of L (row-major), diagonal entries as their logarithms.

    Returns
    -------
    params : ndarray, shape (n, 10)
        [m, m c, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz] (about the frame origin).
    jac : ndarray, shape (n, 10, 10)
        d params / d x per link.
    """
    n = x.shape[0]
    diag = _TRIL[0] == _TRIL[1]
    vals = np.where(diag, np.exp(np.where(diag, x, 0.0)), x)
    L = np.zeros((n, 4, 4))
    L[:, _TRIL[0], _TRIL[1]] = vals
    # dL / dx_k: a unit at entry k (L_kk on the diagonal, from the exp)
    dL = np.zeros((n, 10, 4, 4))
    dL[:, np.arange(10), _TRIL[0], _TRIL[1]] = np.where(diag, vals, 1.0)
    # J = L Lᵀ,  dJ = dL Lᵀ + L dLᵀ
    dJ = dL @ np.swapaxes(L, 1, 2)[:, None]
    dJ = dJ + np.swapaxes(dJ, 2, 3)
    return _params_of_J(L @ np.swapaxes(L, 1, 2)), np.swapaxes(_params_of_J(dJ), 1, 2)


def pseudo_inertia(params: FloatArray) -> FloatArray:
    """Pseudo-inertias J = [[½ tr(I) 1 − I, m c], [(m c)ᵀ, m]] of links, (n, 10) → (n, 4, 4)."""
    p = np.atleast_2d(np.asarray(params, dtype=float)).reshape(-1, 10)
    Im = p[:, [4, 5, 7, 5, 6, 8, 7, 8, 9]].reshape(-1, 3, 3)
    J = np.zeros((len(p), 4, 4))
    J[:, :3, :3] = 0.5 * np.trace(Im, axis1=1, axis2=2)[:, None, None] * np.eye(3) - Im
    J[:, :3, 3] = J[:, 3, :3] = p[:, 1:4]
    J[:, 3, 3] = p[:, 0]
    return J


def cholesky_of_link(params: FloatArray) -> FloatArray:
    """Inverse of :func:`links_from_cholesky` for one physically consistent link (J ≻ 0),
    shape (10,) → (10,)."""
    L = np.linalg.cholesky(pseudo_inertia(params)[0])
    d = np.diag_indices(4)
    L[d] = np.log(L[d])
    return np.asarray(L[_TRIL], dtype=float)


def pseudo_inertia_eigenvalues(params: FloatArray) -> FloatArray:
    """Eigenvalues of each link's pseudo-inertia, (10 n,) → (n, 4): all > 0 ⇔ physical."""
    return np.asarray(np.linalg.eigvalsh(pseudo_inertia(params)), dtype=float)


@dataclass(frozen=True)
class ConsistentFit:
    """Physically consistent full parameters.

    Attributes
    ----------
    full : ndarray, shape (14 n,)
        Every link physical, armature/viscous/Coulomb ≥ 0.
    theta : ndarray, shape (b,)
        Their base parameters.
    cost_increase : float
        Weighted residual sum of squares above the unconstrained fit's, in units of the
        unconstrained fit's per-row variance (0 when the constraint does not bind).
    converged : bool
        The solver met its tolerances, or settled (module docstring); False: it stopped at
        its evaluation limit, the parameters are physical but their cost may still fall.
    evaluations : int
        Residual evaluations the solver used.
    """

    full: FloatArray
    theta: FloatArray
    cost_increase: float
    converged: bool
    evaluations: int

    @property
    def status(self) -> str:
        """One line: converged, or where the solver stopped."""
        return (f"converged after {self.evaluations} evaluations" if self.converged else
                f"NOT converged: stopped after {self.evaluations} evaluations, physical but "
                "its cost may still fall")


class _Settled:
    """A least-squares callback that stops the solver once it has settled: over the last
    ``SETTLE_WINDOW`` iterations the objective fell by at most ``SETTLE_RTOL`` of itself and
    no base parameter moved by more than ``SETTLE_SIGMA`` standard deviations."""

    def __init__(self, theta_of: Callable[[FloatArray], FloatArray], std: FloatArray) -> None:
        self.theta_of = theta_of
        self.std = np.maximum(std, 1e-300)
        self.history: list[tuple[float, FloatArray]] = []
        self.settled = False

    def __call__(self, intermediate_result: scipy.optimize.OptimizeResult) -> None:
        """Record an iteration; raise StopIteration once settled."""
        self.history.append((float(intermediate_result.cost),
                             self.theta_of(intermediate_result.x)))
        if len(self.history) <= SETTLE_WINDOW:
            return
        (f0, t0), (f1, t1) = self.history[-SETTLE_WINDOW - 1], self.history[-1]
        if (f0 - f1 <= SETTLE_RTOL * f1
                and np.max(np.abs(t1 - t0) / self.std) <= SETTLE_SIGMA):
            self.settled = True
            raise StopIteration


def fit_consistent(normals: JointNormals, base: BaseParameters, fit: BaseFit,
                   nominal: FloatArray, prior_weight: float = 1e-5,
                   max_evaluations: int = 4000) -> ConsistentFit:
    """Physically consistent least squares (log-Cholesky links, bounded joint terms).

    Parameters
    ----------
    normals : JointNormals
    base : BaseParameters
    fit : BaseFit
        The unconstrained fit: its weights are used, and its cost is the reference.
    nominal : ndarray, shape (14 n,)
        Start, and the full set preferred among those with the same base parameters; links
        must be physical.
    prior_weight : float
        Weight of ‖π − π_nominal‖ (scaled per parameter) against the data's cost.
    max_evaluations : int
        Residual evaluations after which the solver stops unconverged (the SO-101's links of
        0.1 kg took 2542; at 2000 it stopped 10 % above its optimal cost).

    Returns
    -------
    ConsistentFit
    """
    n = len(normals.c)
    nl = 10 * n
    Gb, _ = _restrict(normals, base)
    A = np.einsum("j,jpq->pq", fit.weights, Gb)
    # the data's cost is (θ − θ̂)ᵀ A (θ − θ̂) + const: its square root as residuals
    vals, vecs = np.linalg.eigh(A)
    Rm = (vecs * np.sqrt(np.maximum(vals, 0.0))).T
    scale = np.maximum(np.abs(nominal), 1e-3)

    # θ = B π: the base parameters as a matrix over the full ones
    B = np.zeros((base.size, nl + 4 * n))
    B[np.arange(base.size), base.independent] = 1.0
    B[:, base.dependent] = base.beta
    data_w = Rm @ B / np.sqrt(max(float(np.sum(fit.weights * fit.sigma ** 2)) / n, 1e-300))
    prior_w = np.sqrt(prior_weight) / scale

    def unpack(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        full = x.copy()
        jac = np.eye(len(x))
        links, ljac = links_from_cholesky(x[:nl].reshape(n, 10))
        full[:nl] = links.ravel()
        for j in range(n):
            jac[10 * j:10 * j + 10, 10 * j:10 * j + 10] = ljac[j]
        return full, jac

    def residual(x: FloatArray) -> FloatArray:
        full, _ = unpack(x)
        return np.concatenate([data_w @ (full - start), prior_w * (full - nominal)])

    def jacobian(x: FloatArray) -> FloatArray:
        _, jac = unpack(x)
        return np.concatenate([data_w @ jac, prior_w[:, None] * jac])

    # any full set with the fitted base parameters: θ̂ on the independent columns
    start = np.zeros(nl + 4 * n)
    start[base.independent] = fit.theta
    x0 = np.concatenate([*(cholesky_of_link(nominal[10 * j:10 * j + 10]) for j in range(n)),
                         nominal[nl:]])
    # bounds: Ia, Fv, Fc ≥ 0 (offsets free); each link's Cholesky diagonal at least 1e-5 of
    # its nominal one (physical with a margin, and an optimum on the boundary is reached in
    # finitely many steps instead of as log L_kk → −∞)
    lo = np.full(len(x0), -np.inf)
    lo[nl:] = np.tile([0.0, 0.0, 0.0, -np.inf], n)
    diag = np.flatnonzero(_TRIL[0] == _TRIL[1])
    for j in range(n):
        lo[10 * j + diag] = x0[10 * j + diag] + np.log(1e-5)
    x0 = np.maximum(x0, np.where(np.isfinite(lo), lo + 1e-9, -np.inf))
    settle = _Settled(lambda x: base.of(unpack(x)[0]), fit.std)
    sol = scipy.optimize.least_squares(residual, x0, jac=jacobian, bounds=(lo, np.inf),
                                       xtol=1e-8, ftol=1e-8, gtol=1e-8,
                                       max_nfev=max_evaluations, callback=settle)
    full, _ = unpack(sol.x)
    theta = base.of(full)
    d = theta - fit.theta
    per_row = float(np.sum(fit.weights * fit.sigma ** 2) / n)
    return ConsistentFit(full, theta, float(d @ A @ d) / max(per_row, 1e-300),
                         converged=bool(sol.status > 0 or settle.settled),
                         evaluations=int(sol.nfev))
