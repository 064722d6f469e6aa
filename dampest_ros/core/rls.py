"""Recursive least squares for the stacked damping parameters θ, one sample (6 rows) at a time.

Model per sample n (FRD body frame; the target and regressor of :mod:`dampest_ros.core.batch`):

    y_n = Φ_n θ + e_n,    y_n ∈ ℝ⁶ (N, N·m),  Φ_n ∈ ℝ^{6×p},  e_n ~ N(0, R),  R = diag(r)

Exponentially weighted least squares minimises Σ_n λ^{N−n} ‖y_n − Φ_n θ‖²_{R⁻¹} (plus the prior
term). Its recursion is a Kalman filter with F = I, Q = 0 and a fading-memory prediction
P⁻ = P / λ:

    G = P⁻ Φᵀ,  S = Φ G + R,  K = G S⁻¹,  ε = y − Φ θ,  θ⁺ = θ + K ε,
    P⁺ = (I − KΦ) P⁻ (I − KΦ)ᵀ + K R Kᵀ        (Joseph form)

The Joseph form is evaluated without forming I − KΦ, as P⁻ + A + Aᵀ with
A = K (½ S Kᵀ − Gᵀ) (= P⁻ − K Gᵀ − G Kᵀ + K S Kᵀ): two p × 6 by 6 × p products, O(6 p²) per
sample, and symmetric by construction.

**Blocks** (:meth:`RecursiveLeastSquares.update_many`): n consecutive samples are one update
of the stacked sample (6n rows) with P̃ = P / λⁿ and the noise of sample j (0-based) scaled by
λ^{−(n−1−j)}: in information form both give λⁿ Ω + Σ_j λ^{n−1−j} Φ_jᵀ R⁻¹ Φ_j, so θ and P
are the sequential ones (to rounding). With S̃ = C Cᵀ (Cholesky) and w = C⁻¹ (y − Φ θ), the
sequential innovation of sample j is C_jj w_j with covariance λ^{n−1−j} C_jj C_jjᵀ (the block
LDLᵀ of S̃), and θ after sample j is θ + Σ_{i≤j} B_iᵀ w_i with B = C⁻¹ Φ P̃: the diagnostics
and the change detector see every sample as the sequential recursion does. The blocks hold at
most :data:`BLOCK` samples, and are used only where the sequential steps would forget by
exactly 1/λ (trace bound inactive, exponential mode, fixed weights, not frozen); the rest runs
sample by sample. For p = 12 that is about 2.5 times less CPU per sample.

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

Uncertainty (:attr:`RecursiveLeastSquares.std`): P is the covariance of θ when the residuals
are white with the weighting variances R. They are neither: the noise level is estimated
(c_i = r̂_i / r_i per DOF), and the residuals stay correlated over seconds (low-pass filtered
noise, slow sensor-bias drift, model error), so that κ_i consecutive samples carry the
information of one independent sample (:class:`CorrelationFactor`, the ratio of the
long-run variance of the residuals to their variance). With the information split into the
prior's Ω₀ = P₀⁻¹ and the data's P⁻¹ − Ω₀, whose score covariance is scaled by κ_i c_i, the
sandwich covariance is P (Ω₀ + κ_i c_i (P⁻¹ − Ω₀)) P = P Ω₀ P + κ_i c_i (P − P Ω₀ P): the
prior covariance at the start, P when the residuals are white with variance r_i.

Change detection (:class:`InnovationMonitor`): two-sided CUSUM on block means of normalised
innovations z_i = ε_i / √S_ii, in two forms per DOF: ``bias`` (z_i itself: an offset appeared)
and ``gain`` (z_i · sign(ŷ_i), ŷ = Φθ the predicted damping force: the damping force became
larger or smaller than the model says; a gain change flips sign with the velocity and
averages out of z_i itself). The block means are standardised against their recent history
and whitened, so that the slowly correlated residuals of a real model do not sum into false
alarms. On an alarm the covariance can be reset to the trace bound (``boost_on_alarm``) so
that the estimate re-converges at once.

Outliers (:class:`OutlierGate`, as robot_localization gates its measurements): a raw sample
(before the parallel low-pass, which would spread it over a second of filtered samples) whose
innovation ε = y − Φθ has a squared Mahalanobis distance d² = εᵀ S⁻¹ ε above a χ²(6)
quantile is rejected and counted. S = C^{1/2} Φ P Φᵀ C^{1/2} + V is the predicted innovation
covariance: the parameter uncertainty (P scaled by the estimated noise share C = diag(r̂ / r))
plus V = diag(v), an exponentially weighted mean of the raw innovations' squares (the raw
noise and misfit; winsorised at 3 √S_ii, so that an outlier moves V by at most 9 / window of
itself). The gate opens only after ``warmup`` samples, when V describes the data rather than
the start. The raw innovations are far from Gaussian: steps of the thrust and the
preprocessing's transients at them, and model misfit, give heavy tails (measured on 300 s of
protocol B, after the warm-up: d² up to 870 on noiseless native data and 250 on the MuJoCo
torpedo, where χ²(6) would put the 1e-9 quantile at 53). The default gate, d² = 1e4 (an
innovation of 100 standard deviations), is for gross errors (a corrupt message, a unit slip)
and leaves those tails alone; set it to a χ²(6) quantile for data whose innovations are
Gaussian.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import lapack

from dampest_ros.core.rigid_body import DOF_NAMES, FORCE_NAMES, ConfigError

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

FORGETTING_MODES = ("exponential", "directional")
#: Most samples in one block update of :meth:`RecursiveLeastSquares.update_many`.
BLOCK = 10
#: Default outlier gate, a squared Mahalanobis distance of 1e4 (100 standard deviations): gross
#: errors only, beyond the heavy tails of real innovations (see the module notes).
OUTLIER_GATE = 1e4


@dataclass
class StepResult:
    """Everything one RLS step computes (the function form returns the first three).

    Attributes
    ----------
    theta : ndarray, shape (p,)
        Updated estimate.
    P : ndarray, shape (p, p)
        Updated covariance.
    innovation : ndarray, shape (6,)
        ε = y − Φ θ_prior (N, N·m).
    S : ndarray, shape (6, 6)
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


def _step(theta: FloatArray, P: FloatArray, Phi: FloatArray, y: FloatArray, lam: float,
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
    innovation : ndarray, shape (n, 6)
        ε_j = y_j − Φ_j θ_{j−1} (N, N·m).
    S_diag : ndarray, shape (n, 6)
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
    r = _step(theta, P, Phi, y, lam, R, mode=mode, trace_max=trace_max, scale=scale, rho=rho)
    return r.theta, r.P, r.innovation


@functools.lru_cache(maxsize=64)
def _decay(n: int, d: float) -> tuple[FloatArray, FloatArray]:
    """For x_j = d x_{j−1} + u_j over n steps: T (n, n) with T_jk = d^{j−k} (k ≤ j) and the
    factors d^{j+1} (n, 1) of the initial value, so that x = T u + d^{j+1} x₀."""
    lag = np.subtract.outer(np.arange(n), np.arange(n))
    T = np.where(lag >= 0, d ** np.maximum(lag, 0), 0.0)
    return T, d ** np.arange(1, n + 1, dtype=float)[:, None]


def _ew_mean(m0: FloatArray, x: FloatArray, a: FloatArray) -> FloatArray:
    """m_j = m_{j−1} + a_j (x_j − m_{j−1}) over the rows of x (n, d) from m0 (d,), with
    weights a (n,); returns m_n, computed in one product."""
    d = 1.0 - a
    tail = np.cumprod(d[::-1])[::-1]  # Π_{i≥j} d_i
    after = np.append(tail[1:], 1.0)  # Π_{i>j} d_i
    return np.asarray(tail[0] * m0 + (a * after) @ x, dtype=float)


class Cusum:
    """Two-sided CUSUM on standardised statistics (unit variance, zero mean when no change).

    g⁺ ← max(0, g⁺ + x − k),  g⁻ ← max(0, g⁻ − x − k); an alarm is raised in a channel when
    g⁺ or g⁻ exceeds h, which detects a mean shift of size δ after about h / (δ − k) steps.
    For Gaussian input, k = 0.5 and h = 10 give an in-control average run length of about
    10⁵ steps per side (Siegmund's approximation), a 2σ shift is found in about 7 steps.

    Parameters
    ----------
    n : int
        Number of channels.
    drift : float
        k, the allowance per step (in standard deviations); shifts smaller than k are ignored.
    threshold : float
        h, the decision level (in standard deviations).
    """

    def __init__(self, n: int, drift: float = 0.5, threshold: float = 10.0) -> None:
        if drift < 0 or threshold <= 0:
            raise ConfigError("cusum", f"need drift ≥ 0 and threshold > 0, got {drift}, "
                                       f"{threshold}")
        self.drift = float(drift)
        self.threshold = float(threshold)
        self.pos = np.zeros(n)
        self.neg = np.zeros(n)
        self.alarm = np.zeros(n, dtype=bool)
        self.alarm_sign = np.zeros(n)

    def update(self, x: FloatArray) -> BoolArray:
        """Feed one vector of standardised statistics; returns channels newly in alarm."""
        x = np.where(np.isfinite(x), x, 0.0)
        self.pos = np.maximum(0.0, self.pos + x - self.drift)
        self.neg = np.maximum(0.0, self.neg - x - self.drift)
        up, down = self.pos > self.threshold, self.neg > self.threshold
        new = (up | down) & ~self.alarm
        self.alarm_sign = np.where(new, np.where(up, 1.0, -1.0), self.alarm_sign)
        self.alarm |= up | down
        return np.asarray(new)

    @property
    def statistic(self) -> FloatArray:
        """max(g⁺, g⁻) per channel."""
        return np.maximum(self.pos, self.neg)

    def reset(self) -> None:
        """Clear the sums and the alarms."""
        self.pos[:] = 0.0
        self.neg[:] = 0.0
        self.alarm[:] = False
        self.alarm_sign[:] = 0.0


class CorrelationFactor:
    """Per-DOF ratio κ of the long-run variance of the residuals to their variance: the
    number of consecutive samples that carry the information of one independent sample.

    With u_n the residuals of one DOF and B_b = Σ_{n ∈ b} u_n their sums over consecutive
    blocks of L samples, κ̂ = Σ_b B_b² / Σ_n u_n² (about 1 for white residuals, about the
    correlation time in samples, up to L, for correlated ones; an offset counts as
    correlation). The estimate runs over all time: the correlation is a property of the
    sensors and of the model, not of the moment. κ = max(κ₀, κ̂): κ₀ ≥ 1 is the correlation
    that the processing guarantees (1 for white residuals; more when the samples are
    low-passed), and a smaller ratio from a few blocks is more likely chance than
    anticorrelated residuals.

    Parameters
    ----------
    block : int
        L, samples per block (a few seconds of samples).
    prior : float
        κ₀, the floor (and the factor before the first block is complete).
    """

    def __init__(self, block: int, prior: float = 1.0) -> None:
        self.block, self.prior = int(block), float(prior)
        self.reset()

    def reset(self) -> None:
        """Forget the blocks."""
        self._sum = np.zeros(6)  # Σ u of the open block
        self._sq = np.zeros(6)  # Σ u² of the open block
        self._n = 0
        self.blocks = 0
        self._num = np.zeros(6)  # Σ_b B_b²
        self._den = np.zeros(6)  # Σ u² over the complete blocks

    def update(self, u: FloatArray) -> None:
        """Add the residuals u (n, 6) of n consecutive samples."""
        i = 0
        while i < len(u):
            k = min(len(u) - i, self.block - self._n)
            self._sum += u[i:i + k].sum(axis=0)
            self._sq += (u[i:i + k] ** 2).sum(axis=0)
            self._n += k
            i += k
            if self._n == self.block:
                self._num += self._sum**2
                self._den += self._sq
                self.blocks += 1
                self._sum[:] = 0.0
                self._sq[:] = 0.0
                self._n = 0

    @property
    def factor(self) -> FloatArray:
        """κ per DOF, shape (6,)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            # κ̂ = Σ_b B_b² / Σ_n u_n²
            ratio = np.where(self._den > 0, self._num / self._den, self.prior)
        return np.maximum(self.prior, ratio)


class InnovationMonitor:
    """Change detector on normalised innovations: block means → robust standardisation →
    AR(1) whitening → two-sided :class:`Cusum`.

    Channels (12): ``bias`` z_i and ``gain`` z_i · sign(ŷ_i) for the six DOFs, z_i = ε_i/√S_ii.
    Every ``block`` samples the channel means m_b are standardised by an exponentially
    weighted mean and standard deviation of past block means (``window`` blocks; the update
    is winsorised at ±4σ so that a change enters with bounded weight), then whitened with
    their lag-one autocorrelation ρ (estimated the same way, clipped to [0, 0.95]):
    u_b = (x_b − ρ x_{b−1}) / √(1 − ρ²). Residuals of a real vehicle model are correlated
    over many seconds; without the whitening the CUSUM would sum that correlation into false
    alarms. Detection therefore means "the innovations changed relative to the last
    ``window`` blocks". The first ``warmup`` blocks only initialise the statistics.

    Parameters
    ----------
    block : int
        Samples per block.
    drift, threshold : float
        CUSUM k and h, in standard deviations of a whitened block mean.
    window : float
        Blocks in the exponential window of the standardisation.
    warmup : int
        Blocks before the CUSUM runs.
    """

    def __init__(self, block: int = 50, drift: float = 1.0, threshold: float = 15.0,
                 window: float = 120.0, warmup: int = 20) -> None:
        self.block, self.window, self.warmup = int(block), float(window), int(warmup)
        self.cusum = Cusum(12, drift, threshold)
        self.reset()

    def reset(self) -> None:
        """Forget the statistics and the alarms."""
        self.cusum.reset()
        self._sum = np.zeros(12)
        self._n = 0
        self.blocks = 0
        self._mu = np.zeros(12)
        self._var = np.zeros(12)
        self._c1 = np.zeros(12)
        self._prev = np.zeros(12)
        self.alarm_time: float | None = None

    def update(self, z: FloatArray, sign: FloatArray, t: float | None = None) -> BoolArray:
        """Add one sample's normalised innovations z (6,) and signs of ŷ (6,); returns the
        channels that went into alarm at this sample."""
        self._sum[:6] += z
        self._sum[6:] += z * sign
        self._n += 1
        if self._n < self.block:
            return np.zeros(12, dtype=bool)
        return self._close_block(t)

    def update_many(self, z: FloatArray, sign: FloatArray, t: FloatArray | None = None,
                    stop_at_alarm: bool = False) -> tuple[int, bool]:
        """:meth:`update` for n samples in order, z and sign (n, 6), t (n,); with
        ``stop_at_alarm`` it stops after the first sample that raised an alarm. Returns the
        number of samples taken and whether the last of them raised an alarm."""
        n, i = len(z), 0
        while i < n:
            k = min(n - i, self.block - self._n)
            self._sum[:6] += z[i:i + k].sum(axis=0)
            self._sum[6:] += (z[i:i + k] * sign[i:i + k]).sum(axis=0)
            self._n += k
            i += k
            if self._n < self.block:
                break
            new = self._close_block(None if t is None else float(t[i - 1]))
            if stop_at_alarm and new.any():
                return i, True
        return n, False

    def _close_block(self, t: float | None) -> BoolArray:
        """A block of samples is complete: standardise, whiten and feed its means to the
        CUSUM; returns the channels that went into alarm."""
        m = self._sum / self._n
        self._sum[:] = 0.0
        self._n = 0
        self.blocks += 1
        b = self.blocks
        if b <= self.warmup:
            a = 1.0 / b
            self._mu += a * (m - self._mu)
            self._var += a * ((m - self._mu) ** 2 - self._var)
            self._prev = (m - self._mu) / np.sqrt(self._var + 1e-300)
            return np.zeros(12, dtype=bool)
        sd = np.sqrt(np.maximum(self._var, 1e-300))
        x = (m - self._mu) / sd
        rho = np.clip(self._c1, 0.0, 0.95)
        u = (x - rho * self._prev) / np.sqrt(1.0 - rho * rho)
        new = self.cusum.update(np.clip(u, -50.0, 50.0))
        if new.any() and self.alarm_time is None:
            self.alarm_time = t
        a = 1.0 / min(b, self.window)
        d = np.clip(m - self._mu, -4.0 * sd, 4.0 * sd)
        self._mu += a * d
        self._var += a * (d * d - self._var)
        xc = np.clip(x, -4.0, 4.0)
        self._c1 += a * (xc * np.clip(self._prev, -4.0, 4.0) - self._c1)
        self._prev = xc
        return new

    @property
    def alarm(self) -> bool:
        """True once any channel alarmed (until :meth:`clear`)."""
        return bool(self.cusum.alarm.any())

    def channels(self) -> list[str]:
        """Names of the channels in alarm with the sign of the shift, e.g. ``X gain+``."""
        c = self.cusum
        return [f"{CUSUM_CHANNELS[i]}{'+' if c.alarm_sign[i] > 0 else '-'}"
                for i in np.flatnonzero(c.alarm)]

    def clear(self) -> None:
        """Acknowledge the alarms (the statistics are kept)."""
        self.cusum.reset()
        self.alarm_time = None


class OutlierGate:
    """Rejects raw samples whose innovation is implausible (see the module notes).

    Parameters
    ----------
    threshold : float
        d² above which a sample is rejected (≤ 0: none is).
    warmup : int
        Samples before the gate opens.
    window : float
        Samples of the exponential window of the innovation variances V.
    """

    def __init__(self, threshold: float, warmup: int, window: float) -> None:
        self.threshold, self.warmup, self.window = float(threshold), int(warmup), float(window)
        self.reset()

    def reset(self) -> None:
        """Forget the variances and the count."""
        self.v = np.zeros(6)
        self.n = 0
        self.rejected = 0

    def __call__(self, Phi: FloatArray, y: FloatArray, theta: FloatArray, P: FloatArray,
                 c: FloatArray) -> BoolArray:
        """Which of n consecutive raw samples to reject, shape (n,); updates V and the count.

        Parameters
        ----------
        Phi : ndarray, shape (n, 6, p)
            Raw regressors.
        y : ndarray, shape (n, 6)
            Raw targets (N, N·m).
        theta : ndarray, shape (p,)
        P : ndarray, shape (p, p)
            The estimate and its covariance before these samples (weighting-noise units).
        c : ndarray, shape (6,)
            Estimated over weighting noise variance per DOF, r̂_i / r_i.

        Notes
        -----
        All n samples are judged against θ, P and V as they were before them (O(n · 6p²)).
        """
        n = len(y)
        e = y - np.einsum("nip,p->ni", Phi, theta)
        sc = np.sqrt(c)
        S = np.einsum("nip,pq,njq->nij", Phi, P, Phi) * np.outer(sc, sc)
        S[:, np.arange(6), np.arange(6)] += self.v + 1e-300
        reject = np.zeros(n, dtype=bool)
        if self.threshold > 0 and self.n >= self.warmup:
            d2 = np.einsum("ni,ni->n", e, np.linalg.solve(S, e[:, :, None])[:, :, 0])
            reject = ~(d2 <= self.threshold)  # NaN: rejected
            self.rejected += int(reject.sum())
        # V from the squares winsorised at 3 √S_ii: an outlier moves it by at most
        # 9 / window of itself
        s_diag = np.diagonal(S, axis1=1, axis2=2)
        e2 = np.where(s_diag > 1e-300, np.minimum(e * e, 9.0 * s_diag), e * e)
        a = 1.0 / np.minimum(self.n + 1 + np.arange(n), self.window)
        self.v = _ew_mean(self.v, e2, a)
        self.n += n
        return reject



@dataclass(frozen=True)
class RLSConfig:
    """Settings of :class:`RecursiveLeastSquares`.

    Attributes
    ----------
    forgetting_factor : float
        λ in [0.9, 1]; memory ≈ 1 / (1 − λ) samples.
    forgetting_mode : {'exponential', 'directional'}
    directional_rho : float
        Directional mode: excitation ratio ρ for full forgetting (≤ 0: 0.1 (1 − λ)).
    trace_max : float
        Bound of Σ_j P_jj / s_j² (s the parameter scales); ≤ 0: p (never above the prior
        when the scales are the prior standard deviations).
    noise_var : tuple of 6 float
        Initial per-DOF noise variances r_i (N², N²m²).
    adapt_noise : bool
        Re-estimate r_i from the innovations: r_i = Σ f² ε_i² / Σ f (exponentially weighted)
        with f = r_i / S_ii the share of the innovation variance that is noise. The estimate
        scales the reported standard deviations and normalises the innovations of the change
        detector.
    adapt_weights : bool
        Also weight the update with the estimated r_i. Off by default: a weight that changes
        over time re-weights the samples of a DOF against each other (with λ = 1 the estimate
        then differs from the batch solution by a few percent), while for the diagonal terms
        the DOF weights do not matter at all. Use it, or set ``noise_var``, for terms that
        couple DOFs.
    noise_window : float
        Samples of the exponential window of that estimate.
    noise_floor : float
        Smallest r_i.
    correlation_block : int
        Samples per block of the correlation factor κ_i that widens the reported standard
        deviations (:class:`CorrelationFactor`; a few seconds of samples).
    correlation_prior : float
        κ₀ ≥ 1, the floor of κ_i (1: the samples may be white).
    cusum_drift, cusum_threshold : float
        CUSUM allowance k and decision level h (see :class:`InnovationMonitor`).
    cusum_block : int
        Samples per block mean fed to the detector.
    cusum_window : float
        Blocks in the window of the detector's standardisation.
    cusum_warmup : int
        Blocks that initialise the detector before it runs.
    boost_on_alarm : bool
        On a change alarm, inflate P to the trace bound (covariance resetting) so that the
        estimate re-converges at once instead of at the pace of λ.
    stats_window : float
        Samples of the exponential window of the innovation RMS and the excitation measure.
    min_excitation : float
        A DOF whose largest term force is below this many noise standard deviations is
        reported as not excited (see :attr:`Diagnostics.excitation`).
    outlier_gate : float
        Squared Mahalanobis distance of a raw sample's innovation above which the sample is
        rejected (:class:`OutlierGate`); ≤ 0: no gate. Default :data:`OUTLIER_GATE`.
    gate_warmup : int
        Samples that only initialise the gate's innovation variances.
    gate_window : float
        Samples of the exponential window of those variances.
    """

    forgetting_factor: float = 0.999
    forgetting_mode: str = "exponential"
    directional_rho: float = 0.0
    trace_max: float = 0.0
    noise_var: tuple[float, ...] = (1.0,) * 6
    adapt_noise: bool = True
    adapt_weights: bool = False
    noise_window: float = 5000.0
    noise_floor: float = 1e-12
    correlation_block: int = 250
    correlation_prior: float = 1.0
    cusum_drift: float = 1.0
    cusum_threshold: float = 15.0
    cusum_block: int = 50
    cusum_window: float = 120.0
    cusum_warmup: int = 20
    boost_on_alarm: bool = True
    stats_window: float = 500.0
    min_excitation: float = 2.0
    outlier_gate: float = OUTLIER_GATE
    gate_warmup: int = 250
    gate_window: float = 500.0

    def __post_init__(self) -> None:
        if not 0.9 <= self.forgetting_factor <= 1.0:
            raise ConfigError("forgetting_factor",
                              f"must be in [0.9, 1.0], got {self.forgetting_factor}")
        if self.forgetting_mode not in FORGETTING_MODES:
            raise ConfigError("forgetting_mode", f"must be one of {FORGETTING_MODES}, got "
                                                 f"{self.forgetting_mode!r}")
        if len(self.noise_var) != 6 or min(self.noise_var) <= 0:
            raise ConfigError("noise_var", f"need 6 variances > 0, got {self.noise_var}")
        for name in ("noise_window", "stats_window"):
            if getattr(self, name) < 1:
                raise ConfigError(name, "must be ≥ 1 sample")
        if self.correlation_block < 1 or not self.correlation_prior >= 1.0:
            raise ConfigError("correlation_block", "need correlation_block ≥ 1 and "
                                                   "correlation_prior ≥ 1")
        if self.cusum_block < 1 or self.cusum_warmup < 2 or self.cusum_window < 1:
            raise ConfigError("cusum_block", "need cusum_block ≥ 1, cusum_warmup ≥ 2 and "
                                             "cusum_window ≥ 1")
        if self.gate_warmup < 1 or self.gate_window < 1:
            raise ConfigError("gate_warmup", "need gate_warmup ≥ 1 and gate_window ≥ 1")


@dataclass
class Diagnostics:
    """Health of the estimator (see :meth:`RecursiveLeastSquares.diagnostics`).

    Attributes
    ----------
    samples : int
    innovation_rms : ndarray, shape (6,)
        EW RMS of the innovations per DOF (N, N·m).
    noise_std : ndarray, shape (6,)
        √r_i (N, N·m).
    excitation : ndarray, shape (6,)
        Per DOF i, the largest RMS of a term's force θ_j Φ_ij over the samples the estimate
        remembers (an exponential window of 1 / (1 − λ) samples; all of them at λ = 1), over
        the noise standard deviation. Per term, not the sum Φθ: terms that a misfit sets
        against each other (X_u < 0 with X_uu > 0) cancel in the sum however hard the DOF is
        flown; and over the estimate's memory, not the last ``stats_window`` samples.
    excited : ndarray of bool, shape (6,)
    covariance_trace : float
        Σ_j P_jj / s_j².
    condition_number : float
        Of the information matrix P⁻¹ scaled to unit diagonal (NaN if not computed).
    cusum : ndarray, shape (12,)
        Statistics, ``bias`` channels X..N then ``gain`` channels X..N.
    alarm : bool
    alarm_channels : list of str
        e.g. ``['Y gain+']``: the damping force in Y became larger than predicted.
    outliers : int
        Raw samples the outlier gate rejected (:meth:`RecursiveLeastSquares.outliers`).
    """

    samples: int
    innovation_rms: FloatArray
    noise_std: FloatArray
    excitation: FloatArray
    excited: BoolArray
    covariance_trace: float
    condition_number: float
    cusum: FloatArray
    alarm: bool
    alarm_channels: list[str] = field(default_factory=list)
    outliers: int = 0

    @property
    def unexcited(self) -> list[str]:
        """Names (u..r) of the DOFs that are not excited."""
        return [DOF_NAMES[i] for i in range(6) if not self.excited[i]]


CUSUM_CHANNELS = [f"{f} bias" for f in FORCE_NAMES] + [f"{f} gain" for f in FORCE_NAMES]


class RecursiveLeastSquares:
    """RLS over the damping parameters, with diagnostics and a change detector.

    Parameters
    ----------
    theta0 : ndarray, shape (p,)
        Prior mean.
    P0 : ndarray, shape (p,) or (p, p)
        Prior covariance (a vector: its diagonal).
    config : RLSConfig, optional
    scale : ndarray, shape (p,), optional
        Parameter scales for the trace bound (default: √diag(P0)).

    Notes
    -----
    :meth:`update` calls :func:`rls_update`'s step with the configured options, so the class
    and the function agree to rounding.
    """

    def __init__(self, theta0: FloatArray, P0: FloatArray, config: RLSConfig | None = None,
                 scale: FloatArray | None = None) -> None:
        self.config = config or RLSConfig()
        theta0 = np.asarray(theta0, dtype=float)
        P0 = np.asarray(P0, dtype=float)
        if P0.ndim == 1:
            P0 = np.diag(P0)
        p = theta0.shape[0]
        if P0.shape != (p, p):
            raise ConfigError("P0", f"must be ({p}, {p}) or ({p},), got {P0.shape}")
        if not np.all(np.isfinite(theta0)) or not np.all(np.isfinite(P0)):
            raise ConfigError("prior", "theta0 and P0 must be finite")
        self.theta0 = theta0.copy()
        self.P0 = 0.5 * (P0 + P0.T)
        self.info0 = np.linalg.inv(self.P0)  # Ω₀, the prior information
        self.scale = (np.sqrt(np.diagonal(self.P0)).copy() if scale is None
                      else np.asarray(scale, dtype=float))
        if np.any(self.scale <= 0):
            raise ConfigError("scale", "parameter scales must be > 0")
        self.lam = self.config.forgetting_factor
        self.frozen = False
        self.reset()

    # --- state ----------------------------------------------------------------------------

    @property
    def n_params(self) -> int:
        """p."""
        return int(self.theta0.shape[0])

    @property
    def trace_max(self) -> float:
        """The scaled-trace bound in use."""
        t = self.config.trace_max
        return float(t if t > 0 else self.n_params)

    def reset(self) -> None:
        """Back to the prior; clears the statistics and the change detector."""
        cfg = self.config
        self.theta = self.theta0.copy()
        self.P = self.P0.copy()
        self.R = np.array(cfg.noise_var, dtype=float)  # estimated noise variances
        self.R_w = self.R.copy()  # variances that weight the update
        self._phi2 = np.zeros((6, self.n_params))  # Σ Φ² per row and parameter
        self._term2 = np.zeros((6, self.n_params))  # mean of (θ_j Φ_ij)² over the memory
        self.n = 0
        self._e2 = self.R.copy()  # EW mean of ε², seeded with the prior noise
        # weighted EW estimate of r; the prior counts as 1 % of one informative sample
        self._r_num = 0.01 * self.R
        self._r_den = np.full(6, 0.01)
        self.correlation = CorrelationFactor(cfg.correlation_block, cfg.correlation_prior)
        self.monitor = InnovationMonitor(cfg.cusum_block, cfg.cusum_drift, cfg.cusum_threshold,
                                         cfg.cusum_window, cfg.cusum_warmup)
        self.gate = OutlierGate(cfg.outlier_gate, cfg.gate_warmup, cfg.gate_window)
        self.last_innovation = np.zeros(6)
        self.skipped = 0
        self.boosts = 0

    def set_forgetting_factor(self, lam: float) -> None:
        """Change λ on the fly (validated like the config)."""
        if not 0.9 <= lam <= 1.0:
            raise ConfigError("forgetting_factor", f"must be in [0.9, 1.0], got {lam}")
        self.lam = float(lam)

    @property
    def memory(self) -> float:
        """Samples the estimate remembers, 1 / (1 − λ) (inf at λ = 1)."""
        return 1.0 / (1.0 - self.lam) if self.lam < 1.0 else np.inf

    @property
    def parameter_dof(self) -> NDArray[np.int64]:
        """The DOF (0..5) each parameter acts on most in the data so far, shape (p,)."""
        return np.asarray(np.argmax(self._phi2, axis=0), dtype=np.int64)

    @property
    def std(self) -> FloatArray:
        """Standard deviations of θ, shape (p,): the diagonal of the sandwich covariance
        P Ω₀ P + g_j (P − P Ω₀ P) (see the module notes), g_j = κ_i r̂_i / r_i for the DOF i
        that parameter j acts on most (κ the correlation factor, r̂ the estimated and r the
        weighting noise variance). O(p³) (one p × p product).

        The prior information is taken as not forgotten: its share diag(P Ω₀ P), at most
        P_jj, is exact at the start and with λ = 1, and negligible next to the data's once
        they determine a parameter.
        """
        d = np.maximum(np.diagonal(self.P), 0.0)
        # diag(P Ω₀ P): the prior's part of P
        prior = np.minimum(np.einsum("jk,jk->j", self.P @ self.info0, self.P), d)
        g = (self.correlation.factor * self.R / self.R_w)[self.parameter_dof]
        # P Ω₀ P + g (P − P Ω₀ P) on the diagonal
        return np.sqrt(prior + g * (d - prior))

    # --- update ---------------------------------------------------------------------------

    def outliers(self, Phi: FloatArray, y: FloatArray) -> BoolArray:
        """Which of n consecutive raw samples (before the parallel low-pass) the outlier gate
        rejects, shape (n,); counted in :attr:`Diagnostics.outliers`.

        Parameters
        ----------
        Phi : ndarray, shape (n, 6, p)
        y : ndarray, shape (n, 6)
            Raw target (N, N·m).
        """
        return self.gate(np.asarray(Phi, dtype=float), np.asarray(y, dtype=float), self.theta,
                         self.P, self.R / self.R_w)

    def update(self, Phi: FloatArray, y: FloatArray, t: float | None = None) -> FloatArray:
        """Process one sample; returns the innovation y − Φθ (6,) (before the update).

        Parameters
        ----------
        Phi : ndarray, shape (6, p)
        y : ndarray, shape (6,)
        t : float, optional
            Time of the sample (s), recorded with the first alarm.

        Notes
        -----
        Non-finite samples are skipped (innovation NaN). When frozen, θ and P stay as they are
        but the diagnostics and the change detector still run.
        """
        Phi = np.asarray(Phi, dtype=float)
        y = np.asarray(y, dtype=float)
        if not np.isfinite(Phi.sum() + y.sum()):
            self.skipped += 1
            return np.full(6, np.nan)
        cfg = self.config
        if self.frozen:
            e = y - Phi @ self.theta
            S = Phi @ self.P @ Phi.T + np.diag(self.R_w)
        else:
            r = _step(self.theta, self.P, Phi, y, self.lam, self.R_w, mode=cfg.forgetting_mode,
                      trace_max=self.trace_max, scale=self.scale,
                      rho=cfg.directional_rho if cfg.directional_rho > 0 else None)
            if not np.isfinite(r.theta.sum() + r.P.trace()):
                self.skipped += 1  # defensive: never store a non-finite state
                return np.full(6, np.nan)
            self.theta, self.P, e, S = r.theta, r.P, r.innovation, r.S
        self.n += 1
        self.last_innovation = e
        self._phi2 += Phi * Phi
        c = self.R / self.R_w
        s_diag = np.diagonal(S) * c  # innovation variances with the estimated noise
        # per-DOF statistics: EW means with windows in samples
        a = 1.0 / min(self.n, cfg.stats_window)
        a_r = 1.0 / cfg.noise_window
        self._e2 += (e * e - self._e2) * a
        if not self.frozen:
            # residuals weighted by the noise share r_i / S_ii (the start, when the
            # innovation is mostly parameter uncertainty, counts little)
            self.correlation.update((self.R_w / np.diagonal(S) * e)[None])
        if cfg.adapt_noise and not self.frozen:
            # E[ε_i²] = S_ii, of which the share f_i = r_i / S_ii is noise: f_i ε_i² estimates
            # r_i, with weight f_i (a sample whose innovation is mostly parameter uncertainty
            # says little about the noise). Innovations beyond 3√S_ii are clipped so that a
            # change or an outlier cannot inflate r and stall the tracking.
            f = self.R / s_diag
            e2 = np.minimum(e * e, 9.0 * s_diag)
            self._r_num += f * f * e2 - self._r_num * a_r
            self._r_den += f - self._r_den * a_r
            self.R = np.maximum(self._r_num / self._r_den, cfg.noise_floor)
            if cfg.adapt_weights:
                self.R_w = self.R.copy()
        force = Phi @ self.theta
        term = Phi * self.theta
        self._term2 += (term * term - self._term2) / min(self.n, self.memory)
        new = self.monitor.update(e / np.sqrt(s_diag), np.sign(force), t)
        if cfg.boost_on_alarm and new.any() and not self.frozen:
            self._boost()
        return e

    def _boost(self) -> None:
        """Covariance resetting after a change alarm: P inflated up to the trace bound."""
        tr = scaled_trace(self.P, self.scale)
        self.P = self.P * max(1.0, min(1e4, self.trace_max / max(tr, 1e-300)))
        self.boosts += 1

    def update_many(self, Phi: FloatArray, y: FloatArray,
                    t: FloatArray | None = None) -> FloatArray:
        """:meth:`update` over N samples in order; returns the innovations (N, 6).

        Parameters
        ----------
        Phi : ndarray, shape (N, 6, p)
        y : ndarray, shape (N, 6)
        t : ndarray, shape (N,), optional
            Sample times (s).

        Notes
        -----
        Runs of samples that the sequential recursion forgets by exactly 1/λ are processed as
        blocks of at most :data:`BLOCK` (:func:`block_update`); θ, P, the diagnostics and the
        change detector end as with :meth:`update` sample by sample, to rounding.
        """
        Phi = np.asarray(Phi, dtype=float)
        y = np.asarray(y, dtype=float)
        out = np.empty((len(y), 6))
        k = 0
        while k < len(y):
            n = self._block_length(Phi[k:k + BLOCK], y[k:k + BLOCK])
            done = self._update_block(Phi[k:k + n], y[k:k + n], None if t is None else
                                      np.asarray(t[k:k + n], dtype=float), out[k:k + n]) \
                if n > 1 else 0
            if not done:
                out[k] = self.update(Phi[k], y[k], None if t is None else float(t[k]))
                done = 1
            k += done
        return out

    def _block_length(self, Phi: FloatArray, y: FloatArray) -> int:
        """How many of the next samples (n, 6, p) one block can take exactly: finite ones,
        while the forgetting is 1/λ at every step (0: sample by sample)."""
        cfg = self.config
        if self.frozen or cfg.forgetting_mode != "exponential" or cfg.adapt_weights:
            return 0
        finite = np.isfinite(Phi.sum(axis=(1, 2)) + y.sum(axis=1))
        n = len(y) if finite.all() else int(np.argmin(finite))
        if self.lam < 1.0 and n > 0:
            # P_k ≼ P_{k−1}/λ, so tr(P_k) ≤ tr(P)/λᵏ: the bound cannot act within n steps if
            # tr(P)/λⁿ ≤ trace_max
            tr = scaled_trace(self.P, self.scale)
            room = np.log(self.trace_max / tr) / -np.log(self.lam) if tr > 0 else np.inf
            n = min(n, int(np.floor(room)) if np.isfinite(room) else n)
        return max(n, 0)

    def _update_block(self, Phi: FloatArray, y: FloatArray, t: FloatArray | None,
                      out: FloatArray) -> int:
        """Samples (n, 6, p) as one block; returns how many were taken (fewer when a change
        alarm boosts P after one of them; 0 when the block is not finite)."""
        cfg = self.config
        b = block_update(self.theta, self.P, Phi, y, self.lam, self.R_w)
        if b is None or not np.isfinite(b.thetas[-1].sum() + b.P.trace()):
            return 0  # sample by sample: update() skips what is not finite
        n = len(y)
        e = b.innovation
        u = self.R_w / b.S_diag * e  # residuals weighted by the noise share, as in update()
        if cfg.adapt_noise:
            R_prev, num, den = self._noise_path(e, b.S_diag)
        else:
            R_prev = np.broadcast_to(self.R, (n, 6))
        s_diag = b.S_diag * (R_prev / self.R_w)
        force = np.einsum("jip,jp->ji", Phi, b.thetas)
        term = (Phi * b.thetas[:, None, :]).reshape(n, -1)
        m, alarm = self.monitor.update_many(e / np.sqrt(s_diag), np.sign(force), t,
                                            stop_at_alarm=cfg.boost_on_alarm)
        if m < n:  # the state after sample m, boosted below; the rest is a new block
            prefix = block_update(self.theta, self.P, Phi[:m], y[:m], self.lam, self.R_w)
            assert prefix is not None  # a leading block of a positive definite S̃
            b = prefix
        self.theta, self.P = b.thetas[m - 1].copy(), b.P
        a = 1.0 / np.minimum(self.n + 1 + np.arange(m), cfg.stats_window)
        self.n += m
        out[:m] = e[:m]
        self.last_innovation = e[m - 1].copy()
        self._phi2 += np.einsum("jip,jip->ip", Phi[:m], Phi[:m])
        self._term2 = _ew_mean(self._term2.ravel(), term[:m] ** 2, 1.0 / np.minimum(
            self.n - m + 1 + np.arange(m), self.memory)).reshape(self._term2.shape)
        self._e2 = _ew_mean(self._e2, e[:m] ** 2, a)
        self.correlation.update(u[:m])
        if cfg.adapt_noise:
            self._r_num, self._r_den = num[m - 1], den[m - 1]
            self.R = np.maximum(num[m - 1] / den[m - 1], cfg.noise_floor)
        if alarm:
            self._boost()
        return m

    def _noise_path(self, e: FloatArray, S_diag: FloatArray
                    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The noise estimate of :meth:`update` over n samples: r_i before each sample
        (n, 6) and the weighted sums Σ f² ε², Σ f after each (n, 6).

        The sums are linear recursions with the constant factor 1 − 1/noise_window (a
        lower-triangular Toeplitz product); only the clipping of ε² at 9 S_ii depends on the
        estimate itself, so it is settled row by row: each pass fixes the first sample whose
        clipping differs from the one assumed.
        """
        cfg = self.config
        n = len(e)
        T, dk = _decay(n, 1.0 - 1.0 / cfg.noise_window)
        f = self.R_w / S_diag  # the noise share r_i / S_ii of the innovation variance
        den = T @ f + dk * self._r_den
        e2 = e * e
        lim = np.full((n, 6), np.inf)  # 9 S_ii with the estimate of the time: clip level
        for _ in range(n + 1):
            num = T @ (f * f * np.minimum(e2, lim)) + dk * self._r_num
            R_prev = np.vstack([self.R, np.maximum(num[:-1] / den[:-1], cfg.noise_floor)])
            new_lim = 9.0 * S_diag * (R_prev / self.R_w)
            differs = np.any(np.minimum(e2, new_lim) != np.minimum(e2, lim), axis=1)
            if not differs.any():
                break
            j = int(np.argmax(differs))
            lim[j] = new_lim[j]
        return R_prev, num, den

    @property
    def alarm_time(self) -> float | None:
        """Stamp of the first change alarm since the last clear (None: none)."""
        return self.monitor.alarm_time

    def clear_alarm(self) -> None:
        """Acknowledge a change: clear the CUSUM (the estimate is kept)."""
        self.monitor.clear()

    # --- diagnostics ----------------------------------------------------------------------

    def condition_number(self) -> float:
        """Condition number of the information matrix P⁻¹ scaled to unit diagonal (O(p³))."""
        d = np.sqrt(np.maximum(np.diagonal(self.P), 1e-300))
        C = self.P / np.outer(d, d)  # unit-diagonal P: its inverse is D Ω D, same spectrum
        ev = np.linalg.eigvalsh(0.5 * (C + C.T))
        return float(ev.max() / max(ev.min(), 1e-300))

    def is_spd(self) -> bool:
        """True when P is symmetric positive definite (Cholesky succeeds)."""
        try:
            np.linalg.cholesky(self.P)
        except np.linalg.LinAlgError:
            return False
        return bool(np.allclose(self.P, self.P.T))

    def diagnostics(self, condition: bool = True) -> Diagnostics:
        """Current diagnostics; ``condition`` computes the condition number (O(p³))."""
        noise_std = np.sqrt(self.R)
        excitation = np.sqrt(self._term2.max(axis=1, initial=0.0)) / noise_std
        return Diagnostics(
            samples=self.n, innovation_rms=np.sqrt(self._e2), noise_std=noise_std,
            excitation=excitation, excited=excitation >= self.config.min_excitation,
            covariance_trace=scaled_trace(self.P, self.scale),
            condition_number=self.condition_number() if condition else float("nan"),
            cusum=self.monitor.cusum.statistic.copy(), alarm=self.monitor.alarm,
            alarm_channels=self.monitor.channels(), outliers=self.gate.rejected)
