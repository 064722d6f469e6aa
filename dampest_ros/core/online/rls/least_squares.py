"""The recursive least-squares estimator (:class:`RecursiveLeastSquares`): the update of
:mod:`dampest_ros.core.online.rls.update` with its settings, the monitors of
:mod:`dampest_ros.core.online.rls.monitors`, the uncertainty of θ and the diagnostics.

Uncertainty (:attr:`RecursiveLeastSquares.std`): P is the covariance of θ when the residuals
are white with the weighting variances R. They are neither: the noise level is estimated
(c_i = r̂_i / r_i per DOF), and the residuals stay correlated over seconds (low-pass filtered
noise, slow sensor-bias drift, model error), so that κ_i consecutive samples carry the
information of one independent sample (:class:`CorrelationFactor`, the ratio of the
long-run variance of the residuals to their variance). With the information split into the
prior's Ω₀ = P₀⁻¹ and the data's P⁻¹ − Ω₀, whose score covariance is scaled by κ_i c_i, the
sandwich covariance is P (Ω₀ + κ_i c_i (P⁻¹ − Ω₀)) P = P Ω₀ P + κ_i c_i (P − P Ω₀ P): the
prior covariance at the start, P when the residuals are white with variance r_i.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.online.rls.monitors import (
    CorrelationFactor,
    InnovationMonitor,
    OutlierGate,
    ew_mean,
)
from dampest_ros.core.online.rls.update import (
    BLOCK,
    FORGETTING_MODES,
    block_update,
    scaled_trace,
    step,
)
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, ConfigError

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Default outlier gate, a squared Mahalanobis distance of 1e4 (100 standard deviations): gross
#: errors only, beyond the heavy tails of real innovations (see :mod:`.monitors`).
OUTLIER_GATE = 1e4


@functools.lru_cache(maxsize=64)
def _decay(n: int, d: float) -> tuple[FloatArray, FloatArray]:
    """For x_j = d x_{j−1} + u_j over n steps: T (n, n) with T_jk = d^{j−k} (k ≤ j) and the
    factors d^{j+1} (n, 1) of the initial value, so that x = T u + d^{j+1} x₀."""
    lag = np.subtract.outer(np.arange(n), np.arange(n))
    T = np.where(lag >= 0, d ** np.maximum(lag, 0), 0.0)
    return T, d ** np.arange(1, n + 1, dtype=float)[:, None]


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
    noise_var : tuple of m float
        Initial per-row noise variances r_i (N², N²m²); m rows per sample (default 6, the
        vehicle's DOFs).
    row_names : tuple of str, optional
        Names of the m rows (an arm's joints), for the change alarm's channels and the
        unexcited rows; default (None) the vehicle's: forces X..N and DOFs u..r (m = 6).
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
    row_names: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        if not 0.9 <= self.forgetting_factor <= 1.0:
            raise ConfigError("forgetting_factor",
                              f"must be in [0.9, 1.0], got {self.forgetting_factor}")
        if self.forgetting_mode not in FORGETTING_MODES:
            raise ConfigError("forgetting_mode", f"must be one of {FORGETTING_MODES}, got "
                                                 f"{self.forgetting_mode!r}")
        if len(self.noise_var) != self.rows or min(self.noise_var) <= 0:
            raise ConfigError("noise_var", f"need {self.rows} variances > 0 (one per row), "
                                           f"got {self.noise_var}")
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

    @property
    def rows(self) -> int:
        """m, rows per sample."""
        return 6 if self.row_names is None else len(self.row_names)

    @property
    def dof_names(self) -> tuple[str, ...]:
        """What :attr:`Diagnostics.unexcited` names the rows by: DOFs u..r or row_names."""
        return tuple(DOF_NAMES) if self.row_names is None else self.row_names

    @property
    def force_names(self) -> tuple[str, ...]:
        """What the change alarm's channels name the rows by: forces X..N or row_names."""
        return tuple(FORCE_NAMES) if self.row_names is None else self.row_names


@dataclass
class Diagnostics:
    """Health of the estimator (see :meth:`RecursiveLeastSquares.diagnostics`).

    Attributes
    ----------
    samples : int
    innovation_rms : ndarray, shape (m,)
        EW RMS of the innovations per DOF (row) (N, N·m).
    noise_std : ndarray, shape (m,)
        √r_i (N, N·m).
    excitation : ndarray, shape (m,)
        Per DOF i, the largest RMS of a term's force θ_j Φ_ij over the samples the estimate
        remembers (an exponential window of 1 / (1 − λ) samples; all of them at λ = 1), over
        the noise standard deviation. Per term, not the sum Φθ: terms that a misfit sets
        against each other (X_u < 0 with X_uu > 0) cancel in the sum however hard the DOF is
        flown; and over the estimate's memory, not the last ``stats_window`` samples.
    excited : ndarray of bool, shape (m,)
    covariance_trace : float
        Σ_j P_jj / s_j².
    condition_number : float
        Of the information matrix P⁻¹ scaled to unit diagonal (NaN if not computed).
    cusum : ndarray, shape (2 m,)
        Statistics, ``bias`` channels X..N then ``gain`` channels X..N (or of the rows).
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
    names: tuple[str, ...] = tuple(DOF_NAMES)

    @property
    def unexcited(self) -> list[str]:
        """Names (u..r, or the rows' names) of the DOFs that are not excited."""
        return [self.names[i] for i in range(len(self.excited)) if not self.excited[i]]


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
        m = cfg.rows
        self._phi2 = np.zeros((m, self.n_params))  # Σ Φ² per row and parameter
        self._term2 = np.zeros((m, self.n_params))  # mean of (θ_j Φ_ij)² over the memory
        self.n = 0
        self._e2 = self.R.copy()  # EW mean of ε², seeded with the prior noise
        # weighted EW estimate of r; the prior counts as 1 % of one informative sample
        self._r_num = 0.01 * self.R
        self._r_den = np.full(m, 0.01)
        self.correlation = CorrelationFactor(cfg.correlation_block, cfg.correlation_prior, m)
        self.monitor = InnovationMonitor(cfg.cusum_block, cfg.cusum_drift, cfg.cusum_threshold,
                                         cfg.cusum_window, cfg.cusum_warmup, cfg.force_names)
        self.gate = OutlierGate(cfg.outlier_gate, cfg.gate_warmup, cfg.gate_window, m)
        self.last_innovation = np.zeros(m)
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
        """The DOF (row 0..m−1) each parameter acts on most in the data so far, shape (p,)."""
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
        Phi : ndarray, shape (n, m, p)
        y : ndarray, shape (n, m)
            Raw target (N, N·m).
        """
        return self.gate(np.asarray(Phi, dtype=float), np.asarray(y, dtype=float), self.theta,
                         self.P, self.R / self.R_w)

    def update(self, Phi: FloatArray, y: FloatArray, t: float | None = None) -> FloatArray:
        """Process one sample; returns the innovation y − Φθ (m,) (before the update).

        Parameters
        ----------
        Phi : ndarray, shape (m, p)
        y : ndarray, shape (m,)
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
            return np.full(len(y), np.nan)
        cfg = self.config
        if self.frozen:
            e = y - Phi @ self.theta
            S = Phi @ self.P @ Phi.T + np.diag(self.R_w)
        else:
            r = step(self.theta, self.P, Phi, y, self.lam, self.R_w, mode=cfg.forgetting_mode,
                      trace_max=self.trace_max, scale=self.scale,
                      rho=cfg.directional_rho if cfg.directional_rho > 0 else None)
            if not np.isfinite(r.theta.sum() + r.P.trace()):
                self.skipped += 1  # defensive: never store a non-finite state
                return np.full(len(y), np.nan)
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
        """:meth:`update` over N samples in order; returns the innovations (N, m).

        Parameters
        ----------
        Phi : ndarray, shape (N, m, p)
        y : ndarray, shape (N, m)
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
        out = np.empty(y.shape)
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
        """How many of the next samples (n, m, p) one block can take exactly: finite ones,
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
        """Samples (n, m, p) as one block; returns how many were taken (fewer when a change
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
            R_prev = np.broadcast_to(self.R, y.shape)
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
        self._term2 = ew_mean(self._term2.ravel(), term[:m] ** 2, 1.0 / np.minimum(
            self.n - m + 1 + np.arange(m), self.memory)).reshape(self._term2.shape)
        self._e2 = ew_mean(self._e2, e[:m] ** 2, a)
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
        (n, m) and the weighted sums Σ f² ε², Σ f after each (n, m).

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
        lim = np.full(e.shape, np.inf)  # 9 S_ii with the estimate of the time: clip level
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
        """Stamp of the first change alarm since the last reset (None: none)."""
        return self.monitor.alarm_time

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
            alarm_channels=self.monitor.channels(), outliers=self.gate.rejected,
            names=self.config.dof_names)
