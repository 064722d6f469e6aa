"""What watches the recursive least squares: the residual correlation that widens θ's
uncertainty (:class:`CorrelationFactor`), the change detector and the outlier gate.

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

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.rigid_body import FORCE_NAMES, ConfigError

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def cusum_channels(rows: tuple[str, ...]) -> list[str]:
    """The CUSUM channel names of rows named ``rows``: ``bias`` then ``gain`` per row."""
    return [f"{f} bias" for f in rows] + [f"{f} gain" for f in rows]


def ew_mean(m0: FloatArray, x: FloatArray, a: FloatArray) -> FloatArray:
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
    rows : int
        m, rows per sample (6 DOFs of a vehicle, n joints of an arm).
    """

    def __init__(self, block: int, prior: float = 1.0, rows: int = 6) -> None:
        self.block, self.prior, self.rows = int(block), float(prior), int(rows)
        self.reset()

    def reset(self) -> None:
        """Forget the blocks."""
        self._sum = np.zeros(self.rows)  # Σ u of the open block
        self._sq = np.zeros(self.rows)  # Σ u² of the open block
        self._n = 0
        self.blocks = 0
        self._num = np.zeros(self.rows)  # Σ_b B_b²
        self._den = np.zeros(self.rows)  # Σ u² over the complete blocks

    def update(self, u: FloatArray) -> None:
        """Add the residuals u (n, m) of n consecutive samples."""
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
        """κ per row, shape (m,)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            # κ̂ = Σ_b B_b² / Σ_n u_n²
            ratio = np.where(self._den > 0, self._num / self._den, self.prior)
        return np.maximum(self.prior, ratio)


class InnovationMonitor:
    """Change detector on normalised innovations: block means → robust standardisation →
    AR(1) whitening → two-sided :class:`Cusum`.

    Channels (2 m): ``bias`` z_i and ``gain`` z_i · sign(ŷ_i) for the m rows (the six DOFs of
    a vehicle, the joints of an arm), z_i = ε_i/√S_ii.
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
    rows : tuple of str
        The m rows' names (default the vehicle's forces X..N); the channels are named
        ``<row> bias`` and ``<row> gain``.
    """

    def __init__(self, block: int = 50, drift: float = 1.0, threshold: float = 15.0,
                 window: float = 120.0, warmup: int = 20,
                 rows: tuple[str, ...] = FORCE_NAMES) -> None:
        self.block, self.window, self.warmup = int(block), float(window), int(warmup)
        self.names = cusum_channels(rows)
        self.m = len(rows)
        self.cusum = Cusum(2 * self.m, drift, threshold)
        self.reset()

    def reset(self) -> None:
        """Forget the statistics and the alarms."""
        self.cusum.reset()
        self._sum = np.zeros(2 * self.m)
        self._n = 0
        self.blocks = 0
        self._mu = np.zeros(2 * self.m)
        self._var = np.zeros(2 * self.m)
        self._c1 = np.zeros(2 * self.m)
        self._prev = np.zeros(2 * self.m)
        self.alarm_time: float | None = None

    def update(self, z: FloatArray, sign: FloatArray, t: float | None = None) -> BoolArray:
        """Add one sample's normalised innovations z (m,) and signs of ŷ (m,); returns the
        channels that went into alarm at this sample."""
        self._sum[:self.m] += z
        self._sum[self.m:] += z * sign
        self._n += 1
        if self._n < self.block:
            return np.zeros(2 * self.m, dtype=bool)
        return self._close_block(t)

    def update_many(self, z: FloatArray, sign: FloatArray, t: FloatArray | None = None,
                    stop_at_alarm: bool = False) -> tuple[int, bool]:
        """:meth:`update` for n samples in order, z and sign (n, m), t (n,); with
        ``stop_at_alarm`` it stops after the first sample that raised an alarm. Returns the
        number of samples taken and whether the last of them raised an alarm."""
        n, i = len(z), 0
        while i < n:
            k = min(n - i, self.block - self._n)
            self._sum[:self.m] += z[i:i + k].sum(axis=0)
            self._sum[self.m:] += (z[i:i + k] * sign[i:i + k]).sum(axis=0)
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
            return np.zeros(2 * self.m, dtype=bool)
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
        """True once any channel alarmed (until :meth:`reset`)."""
        return bool(self.cusum.alarm.any())

    def channels(self) -> list[str]:
        """Names of the channels in alarm with the sign of the shift, e.g. ``X gain+``."""
        c = self.cusum
        return [f"{self.names[i]}{'+' if c.alarm_sign[i] > 0 else '-'}"
                for i in np.flatnonzero(c.alarm)]


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
    rows : int
        m, rows per sample.
    """

    def __init__(self, threshold: float, warmup: int, window: float, rows: int = 6) -> None:
        self.threshold, self.warmup, self.window = float(threshold), int(warmup), float(window)
        self.rows = int(rows)
        self.reset()

    def reset(self) -> None:
        """Forget the variances and the count."""
        self.v = np.zeros(self.rows)
        self.n = 0
        self.rejected = 0

    def __call__(self, Phi: FloatArray, y: FloatArray, theta: FloatArray, P: FloatArray,
                 c: FloatArray) -> BoolArray:
        """Which of n consecutive raw samples to reject, shape (n,); updates V and the count.

        Parameters
        ----------
        Phi : ndarray, shape (n, m, p)
            Raw regressors.
        y : ndarray, shape (n, m)
            Raw targets (N, N·m).
        theta : ndarray, shape (p,)
        P : ndarray, shape (p, p)
            The estimate and its covariance before these samples (weighting-noise units).
        c : ndarray, shape (m,)
            Estimated over weighting noise variance per row, r̂_i / r_i.

        Notes
        -----
        All n samples are judged against θ, P and V as they were before them (O(n · m p²)).
        """
        n = len(y)
        e = y - np.einsum("nip,p->ni", Phi, theta)
        sc = np.sqrt(c)
        S = np.einsum("nip,pq,njq->nij", Phi, P, Phi) * np.outer(sc, sc)
        S[:, np.arange(self.rows), np.arange(self.rows)] += self.v + 1e-300
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
        self.v = ew_mean(self.v, e2, a)
        self.n += n
        return reject
