"""The recursive least-squares update of the stacked damping parameters θ, one sample (m rows:
the vehicle's 6 DOFs, an arm's joints) at a time, in blocks of samples, and the forgetting
that keeps P bounded.

Model per sample n (FRD body frame; the target and regressor of
:mod:`dampest_ros.core.identification.batch`):

    y_n = Φ_n θ + e_n,    y_n ∈ ℝ⁶ (N, N·m),  Φ_n ∈ ℝ^{6×p},  e_n ~ N(0, R),  R = diag(r)

Exponentially weighted least squares minimises Σ_n λ^{N−n} ‖y_n − Φ_n θ‖²_{R⁻¹} (plus the prior
term). Its recursion is a Kalman filter with F = I, Q = 0 and a fading-memory prediction
P⁻ = P / λ:

    G = P⁻ Φᵀ,  S = Φ G + R,  K = G S⁻¹,  ε = y − Φ θ,  θ⁺ = θ + K ε,
    P⁺ = (I − KΦ) P⁻ (I − KΦ)ᵀ + K R Kᵀ        (Joseph form)

The Joseph form is evaluated without forming I − KΦ, as P⁻ + A + Aᵀ with
A = K (½ S Kᵀ − Gᵀ) (= P⁻ − K Gᵀ − G Kᵀ + K S Kᵀ): two p × 6 by 6 × p products, O(6 p²) per
sample, and symmetric by construction.

**Blocks** (:meth:`~dampest_ros.core.online.rls.least_squares.RecursiveLeastSquares.update_many`): n
consecutive samples are one update of the stacked sample (6n rows) with P̃ = P / λⁿ and the
noise of sample j (0-based) scaled by λ^{−(n−1−j)}: in information form both give λⁿ Ω + Σ_j
λ^{n−1−j} Φ_jᵀ R⁻¹ Φ_j, so θ and P are the sequential ones (to rounding). With S̃ = C Cᵀ
(Cholesky) and w = C⁻¹ (y − Φ θ), the sequential innovation of sample j is C_jj w_j with
covariance λ^{n−1−j} C_jj C_jjᵀ (the block LDLᵀ of S̃), and θ after sample j is θ + Σ_{i≤j}
B_iᵀ w_i with B = C⁻¹ Φ P̃: the diagnostics and the change detector see every sample as the
sequential recursion does. The blocks hold at most :data:`BLOCK` samples, and are used only
where the sequential steps would forget by exactly 1/λ (trace bound inactive, exponential mode,
fixed weights, not frozen); the rest runs sample by sample. For p = 12 that is about 2.5 times
less CPU per sample.

Against wind-up (P growing as λ⁻ⁿ in directions the data do not excite):

- **trace bound**: the forgetting inflation is limited so that the scaled trace
  Σ_j P_jj / s_j² never exceeds ``trace_max`` (s the parameter scales; with s the prior
  standard deviations and ``trace_max = p`` the covariance never grows past the prior);
- **directional forgetting** (optional): the information is forgotten only along the output
  directions that the current sample excites. In whitened coordinates Ŝ = R^{-1/2} Φ P Φᵀ
  R^{-1/2} = V diag(s_k) Vᵀ, the variance of the k-th output combination is inflated by
  1/λ_k with 1 − λ_k = (1 − λ) min(1, s_k / ρ) and nothing else changes:
  P ← P + Σ_k (1/λ_k − 1) g_k g_kᵀ / s_k, g_k = P Φᵀ R^{-1/2} v_k. s_k is the sample's
  information along that direction relative to the information already held; under steady
  excitation s_k ≈ 1 − λ, so ``rho = 0.1 (1 − λ)`` forgets wherever the excitation is at least
  about a third (RMS) of its usual level and freezes the covariance where it is not.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import lapack

from dampest_ros.core.physics.rigid_body import ConfigError

FloatArray = NDArray[np.float64]

FORGETTING_MODES = ("exponential", "directional")
#: Most samples in one block update of :meth:`RecursiveLeastSquares.update_many`.
BLOCK = 10


@dataclass
class StepResult:
    """Everything one RLS step computes (the function form returns the first three).

    Attributes
    ----------
    theta : ndarray, shape (p,)
        Updated estimate.
    P : ndarray, shape (p, p)
        Updated covariance.
    innovation : ndarray, shape (m,)
        ε = y − Φ θ_prior (N, N·m).
    S : ndarray, shape (m, m)
        Innovation covariance Φ P⁻ Φᵀ + R.
    """

    theta: FloatArray
    P: FloatArray
    innovation: FloatArray
    S: FloatArray


def _noise_matrix(R: FloatArray | float, m: int) -> FloatArray:
    """R as an (m, m) matrix from a scalar, a (m,) diagonal or an (m, m) matrix."""
    R = np.asarray(R, dtype=float)
    if R.ndim == 0:
        return np.eye(m) * float(R)
    if R.ndim == 1:
        return np.diag(R)
    return R


def scaled_trace(P: FloatArray, scale: FloatArray | None = None) -> float:
    """Σ_j P_jj / s_j² (the plain trace when ``scale`` is None)."""
    d = P.diagonal()
    return float(P.trace() if scale is None else d @ (1.0 / (scale * scale)))


def forget(P: FloatArray, Phi: FloatArray, lam: float, R: FloatArray, *,
           mode: str = "exponential", trace_max: float | None = None,
           scale: FloatArray | None = None, rho: float | None = None) -> FloatArray:
    """The forgetting (prediction) step P⁻ of the RLS recursion.

    Parameters
    ----------
    P : ndarray, shape (p, p)
        Covariance after the previous sample (units of θ²).
    Phi : ndarray, shape (m, p)
        Regressor of the coming sample (directional mode only).
    lam : float
        Forgetting factor λ in (0, 1].
    R : ndarray, shape (m, m)
        Measurement noise covariance (directional mode only).
    mode : {'exponential', 'directional'}
    trace_max : float, optional
        Upper bound of the scaled trace after forgetting (the forgetting is reduced, never
        the existing covariance).
    scale : ndarray, shape (p,), optional
        Parameter scales s_j for the trace bound (units of θ_j).
    rho : float, optional
        Directional mode: excitation ratio at which a direction is forgotten fully
        (default 0.1 (1 − λ)).

    Returns
    -------
    ndarray, shape (p, p)
        A new array; ``P`` is not modified.
    """
    if lam >= 1.0:
        return P.copy()
    if mode == "exponential":
        f = 1.0 / lam
        if trace_max is not None:
            tr = scaled_trace(P, scale)
            if tr * f > trace_max:
                # P⁻ = f P with f ∈ [1, 1/λ]: inflate at most up to the bound
                f = max(1.0, trace_max / max(tr, 1e-300))
        return P * f
    if mode != "directional":
        raise ConfigError("forgetting_mode", f"unknown mode {mode!r}; use {FORGETTING_MODES}")
    w = 1.0 / np.sqrt(np.maximum(np.diagonal(R), 1e-300))
    G = P @ Phi.T  # (p, m)
    Gw = G * w  # P Φᵀ R^{-1/2}
    S_hat = (Phi @ Gw) * w[:, None]  # R^{-1/2} Φ P Φᵀ R^{-1/2}
    s, V = np.linalg.eigh(0.5 * (S_hat + S_hat.T))
    r = 0.1 * (1.0 - lam) if rho is None else rho
    # 1 − λ_k = (1 − λ) min(1, s_k/ρ);  coefficient (1/λ_k − 1)/s_k, finite as s_k → 0
    one_minus = (1.0 - lam) * np.minimum(1.0, np.maximum(s, 0.0) / r)
    lam_k = 1.0 - one_minus
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(s > 1e-300, (1.0 / lam_k - 1.0) / s, 0.0)
    if not np.any(c > 0):
        return P.copy()
    Gk = Gw @ V  # columns g_k
    inc = (Gk * c) @ Gk.T
    if trace_max is not None:
        tr, dtr = scaled_trace(P, scale), scaled_trace(inc, scale)
        if tr + dtr > trace_max and dtr > 0:
            inc *= max(0.0, (trace_max - tr) / dtr)
    return P + inc


def step(theta: FloatArray, P: FloatArray, Phi: FloatArray, y: FloatArray, lam: float,
          R: FloatArray | float, *, mode: str = "exponential", trace_max: float | None = None,
          scale: FloatArray | None = None, rho: float | None = None) -> StepResult:
    Phi = np.asarray(Phi, dtype=float)
    m = Phi.shape[0]
    Rm = _noise_matrix(R, m)
    Pp = forget(P, Phi, lam, Rm, mode=mode, trace_max=trace_max, scale=scale,
                rho=rho) if lam < 1.0 else P
    G = Pp @ Phi.T  # (p, m)
    S = Phi @ G + Rm
    S = 0.5 * (S + S.T)
    innovation = np.asarray(y, dtype=float) - Phi @ theta
    # K = G S⁻¹; S is small (m × m) and symmetric positive definite
    K = G @ np.linalg.inv(S)
    theta_new = theta + K @ innovation
    return StepResult(theta_new, _joseph(Pp, G, S, K), innovation, S)


def _joseph(Pp: FloatArray, G: FloatArray, S: FloatArray, K: FloatArray) -> FloatArray:
    """The covariance update in Joseph form, (I − KΦ) P⁻ (I − KΦ)ᵀ + K R Kᵀ
    = P⁻ − K Gᵀ − G Kᵀ + K S Kᵀ, in O(m p²) as P⁻ + A + Aᵀ with A = K (½ S Kᵀ − Gᵀ): exactly
    symmetric, one p × m × p product.

    Parameters
    ----------
    Pp : ndarray, shape (p, p)
        P⁻, the covariance after forgetting.
    G : ndarray, shape (p, m)
        P⁻ Φᵀ.
    S : ndarray, shape (m, m)
        Φ P⁻ Φᵀ + R, symmetric.
    K : ndarray, shape (p, m)
        G S⁻¹.
    """
    A = K @ (0.5 * (S @ K.T) - G.T)
    P_new = A + A.T
    P_new += Pp
    return P_new


@dataclass
class BlockResult:
    """A block of n samples processed at once (:func:`block_update`).

    Attributes
    ----------
    thetas : ndarray, shape (n, p)
        θ after each sample.
    P : ndarray, shape (p, p)
        Covariance after the last sample.
    innovation : ndarray, shape (n, m)
        ε_j = y_j − Φ_j θ_{j−1} (N, N·m).
    S_diag : ndarray, shape (n, m)
        Diagonals of the innovation covariances Φ_j P⁻_j Φ_jᵀ + R.
    """

    thetas: FloatArray
    P: FloatArray
    innovation: FloatArray
    S_diag: FloatArray


def block_update(theta: FloatArray, P: FloatArray, Phi: FloatArray, y: FloatArray, lam: float,
                 r: FloatArray) -> BlockResult | None:
    """n sequential RLS steps with exponential forgetting (no trace bound) as one update of
    the stacked samples (see the module notes); O(n³ m³ + n² m² p) for n ≤ :data:`BLOCK`.

    Parameters
    ----------
    theta : ndarray, shape (p,)
    P : ndarray, shape (p, p)
    Phi : ndarray, shape (n, m, p)
    y : ndarray, shape (n, m)
    lam : float
        λ in (0, 1].
    r : ndarray, shape (m,)
        Diagonal noise variances.

    Returns
    -------
    BlockResult, or None when the stacked innovation covariance is not numerically
    positive definite (then take the samples one by one).
    """
    n, m, p = Phi.shape
    g = lam ** np.arange(n - 1, -1, -1, dtype=float)  # λ^{n−1−j}
    Pp = P * (1.0 / lam) ** n if lam < 1.0 else P
    A = Phi.reshape(n * m, p)
    G = Pp @ A.T
    S = A @ G
    S = 0.5 * (S + S.T)
    S[np.diag_indices(n * m)] += (r[None, :] / g[:, None]).ravel()
    # LAPACK directly: the scipy.linalg wrappers cost more than the 60 × 60 work itself
    C, info = lapack.dpotrf(S, lower=1)  # S̃ = C Cᵀ
    if info:
        return None
    W, _ = lapack.dtrtrs(C, np.column_stack([(y - Phi @ theta).ravel(), G.T]), lower=1)
    w, B = W[:, 0].reshape(n, m), W[:, 1:]  # C⁻¹ (y − Φθ), C⁻¹ Φ P̃
    Kt, _ = lapack.dtrtrs(C, B, lower=1, trans=1)  # S̃⁻¹ Φ P̃ = Kᵀ
    thetas = theta + np.cumsum(np.einsum("jip,ji->jp", B.reshape(n, m, p), w), axis=0)
    j = np.arange(n)
    Cjj = C.reshape(n, m, n, m)[j, :, j, :]  # diagonal blocks, (n, m, m)
    return BlockResult(thetas, _joseph(Pp, G, S, Kt.T), np.einsum("jab,jb->ja", Cjj, w),
                       np.einsum("jab,jab->ja", Cjj, Cjj) * g[:, None])


def rls_update(theta: FloatArray, P: FloatArray, Phi: FloatArray, y: FloatArray, lam: float,
               R: FloatArray | float, *, mode: str = "exponential",
               trace_max: float | None = None, scale: FloatArray | None = None,
               rho: float | None = None) -> tuple[FloatArray, FloatArray, FloatArray]:
    """One multi-output RLS update with forgetting (Joseph form).

    Parameters
    ----------
    theta : ndarray, shape (p,)
        Current estimate.
    P : ndarray, shape (p, p)
        Its covariance, symmetric positive definite.
    Phi : ndarray, shape (m, p)
        Regressor of this sample (m = 6 for one 6-DOF sample).
    y : ndarray, shape (m,)
        Target of this sample (N, N·m).
    lam : float
        Forgetting factor λ in (0, 1]; 1: none.
    R : float or ndarray, shape (m,) or (m, m)
        Measurement noise variance (per-DOF weights 1/r_i).
    mode, trace_max, scale, rho
        Forgetting options, see :func:`forget`.

    Returns
    -------
    theta : ndarray, shape (p,)
    P : ndarray, shape (p, p)
    innovation : ndarray, shape (m,)
        y − Φ θ before the update.
    """
    r = step(theta, P, Phi, y, lam, R, mode=mode, trace_max=trace_max, scale=scale, rho=rho)
    return r.theta, r.P, r.innovation
