"""Online arm identification: the vehicle's recursive least squares
(:class:`dampest_ros.core.online.rls.least_squares.RecursiveLeastSquares`, with its forgetting,
noise estimate and CUSUM change alarm) on the arm's base parameters and joint friction.

Joint samples arrive in any pieces. They are filtered exactly as offline
(:func:`dampest_ros.core.arm.identify.filter_joints`) in windows that reach ``margin`` =
10 / cutoff seconds past the samples they emit, so the stream's rows equal the offline
ones and the estimate lags the data by that margin plus one hop. Each decimated sample is
one RLS update with the six joints as its six rows; a joint's row is zeroed where its
friction does not follow the Coulomb model (:func:`dampest_ros.core.arm.identify.usable_rows`).
Jittered stamps are resampled onto a uniform grid in each window (as offline); at a gap
(:func:`dampest_ros.core.arm.identify.gaps`: lost messages, a pause) the samples before it
whose window is not complete are dropped and the stream starts afresh after it.

Samples no arm produces are rejected before the filter (:func:`implausible`) and counted
(:attr:`ArmEstimator.rejected_implausible`), as the vehicle estimator's outlier gate rejects
implausible raw samples before its low-pass: a 1e200 N m effort is finite, but through the
zero-phase filter it would spread over seconds of rows and take θ to ~1e195 with NaN σ. A
rejected sample is a lost message: a gap, after which the stream starts afresh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.arm.base import BaseParameters
from dampest_ros.core.arm.identify import IdentifyConfig, filter_joints, usable_rows
from dampest_ros.core.arm.model import ArmModel
from dampest_ros.core.arm.regressor import regressor
from dampest_ros.core.online.rls.least_squares import RecursiveLeastSquares, RLSConfig
from dampest_ros.core.physics.identity import Identity
from dampest_ros.core.physics.rigid_body import FORCE_NAMES
from dampest_ros.core.signals.resample import gaps

FloatArray = NDArray[np.float64]

#: A sample is implausible when an effort exceeds this many times its joint's effort limit,
#: or a position lies outside the joint's limits widened by this many times their range.
IMPLAUSIBLE_FACTOR = 10.0


def implausible(arm: ArmModel, position: FloatArray, effort: FloatArray) -> NDArray[np.bool_]:
    """Which samples no arm of this model produces, shape (N,): an effort over
    :data:`IMPLAUSIBLE_FACTOR` × the joint's effort limit, or a position outside its limits
    widened by that many times their range (joints whose limits are not positive and finite
    are not judged).

    Parameters
    ----------
    arm : ArmModel
    position, effort : ndarray, shape (N, n)
        rad, N m.
    """
    q, tau = np.asarray(position, dtype=float), np.asarray(effort, dtype=float)
    limit = np.where(np.isfinite(arm.effort_limit) & (arm.effort_limit > 0),
                     IMPLAUSIBLE_FACTOR * arm.effort_limit, np.inf)
    span = arm.upper - arm.lower
    judged = np.isfinite(span) & (span > 0)
    low = np.where(judged, arm.lower - IMPLAUSIBLE_FACTOR * span, -np.inf)
    high = np.where(judged, arm.upper + IMPLAUSIBLE_FACTOR * span, np.inf)
    bad = (np.abs(tau) > limit) | (q < low) | (q > high)
    return np.asarray(bad.any(axis=1))


@dataclass(frozen=True)
class ArmEstimate:
    """The online estimate of an arm's base parameters, as nodes serve and save it.

    Attributes
    ----------
    joint_names : tuple of str, length n
        The arm's joints, in the order of the rows.
    parameter_names : list of str, length b
        Base parameter k is named by the full parameter it keeps (``elbow_joint.m``);
        :attr:`mapping` line k says what it combines.
    theta, theta_std : ndarray, shape (b,)
        Estimate and standard deviation (SI units of the kept parameter).
    identified : ndarray of bool, shape (b,)
        Determined by the data: online, the data have at least halved the prior's standard
        deviation; offline, every base parameter of a regular least-squares fit.
    mapping : list of str, length b
        ``bk = kept + c · folded + ...`` (:meth:`BaseParameters.mapping`).
    version : int
        Bumped by the holder at every publication.
    identity : Identity or None
        The arm it belongs to (:func:`~dampest_ros.core.arm.model.arm_model_identity`); None
        for files written before models carried one.
    """

    joint_names: tuple[str, ...]
    parameter_names: list[str]
    theta: FloatArray
    theta_std: FloatArray
    identified: NDArray[np.bool_]
    mapping: list[str]
    version: int = 1
    identity: Identity | None = None


class ArmEstimator:
    """Streaming base-parameter estimator of an arm.

    Parameters
    ----------
    arm : ArmModel
    base : BaseParameters
    theta0 : ndarray, shape (b,)
        Prior base parameters (nominal, or an offline fit).
    std0 : ndarray, shape (b,)
        Prior standard deviations.
    config : IdentifyConfig
        Filter, decimation and row selection (as offline).
    rls : RLSConfig, optional
        Forgetting, noise and CUSUM settings of the vehicle's RLS (the arm needs 6 joints:
        its six rows). Default: λ = 0.9995 (memory 40 s at 50 Hz), joints weighted by
        their estimated noise, and on a change alarm the covariance reset to a scaled
        trace of 10 b (b the number of base parameters), which drops what was learnt
        before the change: a 1 kg payload is re-identified to ~1 % within 15 s.
    hop : float
        Seconds of samples emitted per filtering pass.
    identity : Identity, optional
        The arm's, carried by every :meth:`estimate`.
    """

    def __init__(self, arm: ArmModel, base: BaseParameters, theta0: FloatArray,
                 std0: FloatArray, config: IdentifyConfig, rls: RLSConfig | None = None,
                 hop: float = 1.0, identity: Identity | None = None) -> None:
        if arm.n != 6:
            raise ValueError(f"the RLS core takes six rows per sample; this arm has {arm.n} "
                             "joints")
        self.arm, self.base, self.config, self.hop = arm, base, config, float(hop)
        self.identity = identity
        rls = rls or RLSConfig(forgetting_factor=0.9995, adapt_weights=True,
                               noise_var=(0.01,) * 6, trace_max=10.0 * base.size)
        self.rls = RecursiveLeastSquares(np.asarray(theta0, dtype=float),
                                         np.asarray(std0, dtype=float) ** 2, rls)
        self.std0 = np.asarray(std0, dtype=float)
        self.gaps = 0  # gaps in the samples: the stream restarted after each
        self.rejected_implausible = 0  # samples no arm produces (:func:`implausible`)
        self.clear()
        self.alarms: list[float] = []  # times of the change alarms (s)
        self.alarm_joints: list[list[str]] = []  # per alarm: e.g. ['elbow_joint gain+']

    def clear(self) -> None:
        """Drop the buffered samples (their windows are never completed); the estimate
        stays."""
        self._t = np.zeros(0)
        self._q = np.zeros((0, self.arm.n))
        self._tau = np.zeros((0, self.arm.n))
        self.emitted = -np.inf  # samples before this time (s) have been used

    def reset(self) -> None:
        """Back to the prior: estimate, covariance, detector, buffer and alarms."""
        self.rls.reset()
        self.clear()
        self.alarms.clear()
        self.alarm_joints.clear()

    def estimate(self, version: int = 1) -> ArmEstimate:
        """The current estimate with its names and mapping."""
        return ArmEstimate(tuple(self.arm.names),
                           [self.base.names[i] for i in self.base.independent],
                           self.theta.copy(), self.std.copy(),
                           np.asarray(self.std <= 0.5 * self.std0), self.base.mapping(),
                           int(version), self.identity)

    @property
    def theta(self) -> FloatArray:
        """Current base parameters, shape (b,)."""
        return self.rls.theta

    @property
    def std(self) -> FloatArray:
        """Their standard deviations, shape (b,)."""
        return self.rls.std

    def add(self, t: FloatArray, position: FloatArray, effort: FloatArray) -> int:
        """Take new joint samples (in time order, one rate) and update with every sample
        whose filter window is complete.

        Parameters
        ----------
        t : ndarray, shape (N,)
            s.
        position, effort : ndarray, shape (N, n)
            rad, N m.

        Returns
        -------
        int
            RLS updates made. Implausible samples are left out and counted in
            :attr:`rejected_implausible`.
        """
        keep = ~implausible(self.arm, position, effort)
        self.rejected_implausible += int(np.count_nonzero(~keep))
        self._t = np.concatenate([self._t, np.asarray(t, dtype=float)[keep]])
        self._q = np.concatenate([self._q, np.asarray(position, dtype=float)[keep]])
        self._tau = np.concatenate([self._tau, np.asarray(effort, dtype=float)[keep]])
        if len(self._t) < 2:
            return 0
        period = float(np.median(np.diff(self._t[-101:])))
        rate = 1.0 / period
        # a gap (filter_joints resamples jitter, not gaps): restart after the last one
        off = gaps(self._t, period)
        if len(off):
            self.gaps += len(off)
            start_at = int(off[-1]) + 1
            self._t, self._q, self._tau = (x[start_at:] for x in (self._t, self._q, self._tau))
            self.emitted = -np.inf
            if len(self._t) < 2:
                return 0
        margin = 10.0 / self.config.cutoff
        done = 0
        start = max(self.emitted, self._t[0] + margin)
        while self._t[-1] - start >= self.hop + margin:
            stop = start + self.hop
            # the window: margin before and after the emitted stretch (filter_joints drops
            # 3 / cutoff s at its ends itself, inside the margin)
            sel = (self._t >= start - margin) & (self._t < stop + margin)
            data = filter_joints(self._t[sel], self._q[sel], self._tau[sel], self.config)
            rows = (data.t >= start) & (data.t < stop)
            use = usable_rows(data.t, data.qd, self.config)[rows]  # reversals in the window
            if rows.any():
                done += self._update(data.t[rows], data.q[rows], data.qd[rows],
                                     data.qdd[rows], data.tau[rows], use)
            start = stop
        self.emitted = start
        # keep what the next window needs
        keep = self._t >= start - margin - 2.0 / rate
        self._t, self._q, self._tau = self._t[keep], self._q[keep], self._tau[keep]
        return done

    def _update(self, t: FloatArray, q: FloatArray, qd: FloatArray, qdd: FloatArray,
                tau: FloatArray, use: NDArray[np.bool_]) -> int:
        Yb = self.base.columns(regressor(self.arm, q, qd, qdd, self.config.coulomb_width))
        Yb = Yb * use[:, :, None]  # a zero row carries no information
        self.rls.update_many(Yb, tau * use, t)
        if self.rls.monitor.alarm:
            # the RLS has reset its covariance (boost_on_alarm); the detector learns the new
            # innovation statistics afresh, so that re-convergence does not alarm again
            self.alarms.append(float(self.rls.monitor.alarm_time or t[-1]))
            # channel "X bias+" of the vehicle's RLS is row 0 here: the first joint
            self.alarm_joints.append([
                f"{self.arm.names[FORCE_NAMES.index(c[0])]}{c[1:]}"
                for c in self.rls.monitor.channels()])
            self.rls.monitor.reset()
        return len(t)
