"""The causal regression that feeds the RLS: the online counterpart of
:func:`dampest_ros.core.identification.batch.iter_regression`.

:class:`LowPass` is the causal "parallel filter": the same Butterworth low-pass (second-order
sections) applied to y and to every column of Φ (O(p) per sample), so that LP(y) = LP(Φ) θ
holds for the nonlinear regressor. :class:`OnlineRegression` turns samples into filtered
(Φ, y) with the regressor and target of the batch path.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.regression import target
from dampest_ros.core.online.sample import OnlineSample
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import ConfigError, RigidBody
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]

#: ``gate(Φ, y)``: which raw regression rows, Φ (n, 6, p) and y (n, 6), to reject, (n,) bool.
Gate = Callable[[FloatArray, FloatArray], NDArray[np.bool_]]


class LowPass:
    """Causal Butterworth low-pass applied in parallel to many channels.

    Cascaded second-order sections (``order`` / 2 of them, as ``scipy.signal.sosfilt``),
    vectorised over channels: O(channels) per sample. The state starts at the steady state
    of the first input (no start-up step). Order 4 has the magnitude |H|² = 1/(1 + (f/f_c)⁸)
    of the batch path's zero-phase filter, so the normal equations weight the frequencies as
    the batch path does (the phase cancels in ΦᵀΦ and Φᵀy, since y and Φ share the filter).

    Parameters
    ----------
    channels : int
    cutoff : float
        −3 dB frequency (Hz).
    rate : float
        Sample rate (Hz); cutoff < rate / 2.
    order : int
        Even filter order (2: one biquad).
    """

    def __init__(self, channels: int, cutoff: float, rate: float, order: int = 4) -> None:
        if not 0 < cutoff < 0.5 * rate:
            raise ConfigError("cutoff", f"must be in (0, rate/2 = {0.5 * rate}), got {cutoff}")
        if order < 2 or order % 2:
            raise ConfigError("order", f"must be even and ≥ 2, got {order}")
        from scipy import signal  # ~0.4 s to import: only where a filter is made

        self._sosfilt = signal.sosfilt
        self.sos = np.asarray(signal.butter(order, cutoff, fs=rate, output="sos"), dtype=float)
        self._zi = np.asarray(signal.sosfilt_zi(self.sos), dtype=float)  # (sections, 2)
        self.state = np.zeros((len(self.sos), 2, channels))
        self.started = False

    def reset(self) -> None:
        """Forget the state; the next input restarts the filter."""
        self.started = False

    def __call__(self, x: FloatArray) -> FloatArray:
        """Filter one sample of every channel (shape (channels,)); returns the output."""
        return self.filter(np.asarray(x, dtype=float).reshape(1, -1))[0]

    def filter(self, X: FloatArray) -> FloatArray:
        """Filter consecutive samples (n, channels), continuing from the current state."""
        if len(X) == 0:
            return X
        if not self.started:
            self.state = self._zi[:, :, None] * X[0]
            self.started = True
        y, self.state = self._sosfilt(self.sos, X, axis=0, zi=self.state)
        return np.asarray(y, dtype=float)


class OnlineRegression:
    """Samples → parallel-filtered (Φ, y) for the RLS, with the batch path's regressor and
    target (:meth:`DampingModel.regressor`, :func:`dampest_ros.core.identification.batch.target`).

    Samples can be given one at a time or in chunks (vectorised, the same result); a stamp
    gap longer than 1.5 sample periods or an unusable sample starts a new segment: the
    low-pass and the memory states restart and the first ``settle`` seconds only settle them.

    Parameters
    ----------
    model : DampingModel
        Term structure being identified.
    body : RigidBody
        Known M and restoring data.
    rate : float
        Sample rate (Hz).
    cutoff : float
        Parallel low-pass (Hz); 0 disables it.
    settle : float
        Seconds after a (re)start whose samples are not returned.
    order : int
        Order of the parallel low-pass (even; 4: the batch path's magnitude).
    """

    def __init__(self, model: DampingModel, body: RigidBody, rate: float = 50.0,
                 cutoff: float = 2.0, settle: float = 1.0, order: int = 4) -> None:
        self.model = model
        self.body = body
        self.rate = float(rate)
        self.cutoff = float(cutoff)
        self.settle = float(settle)
        p = model.n_params
        self.lp = LowPass(6 * (p + 1), cutoff, rate, order) if cutoff > 0 else None
        h = 1.0 / self.rate
        lam = model.memory_rates
        self._mem_a = np.exp(-lam * h)
        # first-order hold, as in dampest_ros.core.physics.damping.filter_memory
        with np.errstate(divide="ignore", invalid="ignore"):
            self._mem_b1 = (lam * h - 1.0 + self._mem_a) / (lam * lam * h)
            self._mem_b0 = (1.0 - self._mem_a) / lam - self._mem_b1
        self.reset()

    def reset(self) -> None:
        """Start a new segment."""
        self._t_prev = -math.inf
        self._t_start = math.nan
        self._z = np.zeros(len(self.model.memory_rates))
        self._x_prev = np.zeros(len(self.model.memory_rates))
        if self.lp is not None:
            self.lp.reset()

    def __call__(self, s: OnlineSample, gate: Gate | None = None
                 ) -> tuple[FloatArray, FloatArray] | None:
        """Filtered (Φ (6, p), y (6,)) of one sample, or None (settling or unusable)."""
        _, Phi, y = self.process([s], gate)
        return (Phi[0], y[0]) if len(y) else None

    def process(self, samples: list[OnlineSample], gate: Gate | None = None
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Filtered regression of consecutive samples.

        Parameters
        ----------
        samples : list of OnlineSample
        gate : callable, optional
            ``gate(Φ, y)`` of raw (unfiltered) rows, Φ (n, 6, p) and y (n, 6), returns which
            to reject, shape (n,) bool (e.g.
            :meth:`~dampest_ros.core.online.rls.least_squares.RecursiveLeastSquares.outliers`). A
            rejected row enters the low-pass as zeros: y = Φθ + e holds for it with any θ, so
            the filtered regression stays exact, and the sample adds nothing else.

        Returns
        -------
        t : ndarray, shape (n,)
        Phi : ndarray, shape (n, 6, p)
        y : ndarray, shape (n, 6)
            For the samples past settling (n ≤ len(samples)).
        """
        p = self.model.n_params
        ts: list[FloatArray] = []
        Phis: list[FloatArray] = []
        ys: list[FloatArray] = []
        run: list[OnlineSample] = []
        for s in samples:
            if not s.usable:
                self._flush(run, ts, Phis, ys, gate)
                run = []
                self.reset()
                continue
            last = run[-1].t if run else self._t_prev
            if s.t - last > 1.5 / self.rate or s.t <= last:
                self._flush(run, ts, Phis, ys, gate)
                run = []
                self.reset()
                self._t_start = s.t
            run.append(s)
        self._flush(run, ts, Phis, ys, gate)
        if not ts:
            return np.zeros(0), np.zeros((0, 6, p)), np.zeros((0, 6))
        return np.concatenate(ts), np.concatenate(Phis), np.concatenate(ys)

    def _flush(self, run: list[OnlineSample], ts: list[FloatArray], Phis: list[FloatArray],
               ys: list[FloatArray], gate: Gate | None) -> None:
        """Regression of one gap-free run that continues the current segment."""
        if not run:
            return
        n = len(run)
        t = np.array([s.t for s in run])
        smp = Samples(t, np.array([s.nu for s in run]), np.array([s.nu_dot for s in run]),
                      np.array([s.tau for s in run]), np.array([s.euler for s in run]),
                      np.array([s.depth for s in run]), np.zeros(n, dtype=np.int64))
        states = None
        if len(self._z):
            x = smp.nu[:, self.model.memory_dofs]
            prev = np.vstack([self._x_prev, x[:-1]])
            # z_n = a z_{n−1} + b0 x_{n−1} + b1 x_n (z = 0 at the segment start)
            u = self._mem_b0 * prev + self._mem_b1 * x
            if not math.isfinite(self._t_prev):
                u[0] = 0.0
            z = np.empty_like(u)
            zc = self._z
            for k in range(n):
                zc = self._mem_a * zc + u[k]
                z[k] = zc
            self._z, self._x_prev = zc, x[-1]
            states = z
        self._t_prev = float(t[-1])
        y = target(smp, self.body)
        Phi = self.model.regressor(smp.nu, states)
        if gate is not None:
            bad = gate(Phi, y)
            y[bad], Phi[bad] = 0.0, 0.0
        if self.lp is not None:
            out = self.lp.filter(np.concatenate([y, Phi.reshape(n, -1)], axis=1))
            y, Phi = out[:, :6], out[:, 6:].reshape(n, 6, -1)
        keep = t - self._t_start >= self.settle
        ts.append(t[keep])
        Phis.append(Phi[keep])
        ys.append(y[keep])
