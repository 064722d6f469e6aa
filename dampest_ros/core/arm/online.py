"""Online arm identification: the vehicle's recursive least squares
(:class:`dampest_ros.core.online.rls.least_squares.RecursiveLeastSquares`, with its forgetting,
noise estimate and CUSUM change alarm) on the arm's base parameters and joint friction.

Joint samples arrive in any pieces. They are filtered exactly as offline
(:func:`dampest_ros.core.arm.identify.filter_joints`) in windows that reach ``margin`` =
10 / cutoff seconds past the samples they emit, so the stream's rows equal the offline
ones and the estimate lags the data by that margin plus one hop. Each decimated sample is
one RLS update with the arm's n joints as its n rows; a joint's row is zeroed where its
friction does not follow the Coulomb model (:func:`dampest_ros.core.arm.identify.usable_rows`).
Jittered stamps are resampled onto a uniform grid in each window (as offline); at a gap
(:func:`dampest_ros.core.arm.identify.gaps`: lost messages, a pause) the samples before it
whose window is not complete are dropped and the stream starts afresh after it.

Samples no arm produces are rejected before the filter (:func:`implausible`) and counted
(:attr:`ArmEstimator.rejected_implausible`), as the vehicle estimator's outlier gate rejects
implausible raw samples before its low-pass: a 1e200 N m effort is finite, but through the
zero-phase filter it would spread over seconds of rows and take θ to ~1e195 with NaN σ. A
rejected sample is a lost message: a gap, after which the stream starts afresh.

The default prior (:func:`prior_std`) is the nominal θ with a standard deviation that no
parameter's nominal value sets alone: a torque-sensor offset or a friction term whose nominal
is 0 had σ = 0.01 (|θ| + 0.01) and stayed pinned at 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.arm.base import BaseParameters, random_states
from dampest_ros.core.arm.identify import IdentifyConfig, filter_joints, usable_rows
from dampest_ros.core.arm.model import ArmModel
from dampest_ros.core.arm.regressor import regressor
from dampest_ros.core.online.rls.least_squares import RecursiveLeastSquares, RLSConfig
from dampest_ros.core.physics.identity import Identity
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


#: Share of a joint's torque range that one prior standard deviation of a base parameter may
#: move that joint's torque by (:func:`prior_std`).
PRIOR_TORQUE_SHARE = 0.1

#: Share of a joint's torque range taken as its noise standard deviation before the data
#: say (:func:`initial_noise_var`; a torque sensor's noise grows with its range).
NOISE_TORQUE_SHARE = 0.01


def _base_columns(arm: ArmModel, base: BaseParameters, samples: int, seed: int
                  ) -> FloatArray:
    """The base regressor on random states (:func:`~dampest_ros.core.arm.base.random_states`:
    unit-scale velocities and accelerations), shape (samples, n, b)."""
    return base.columns(regressor(arm, *random_states(arm.n, samples, seed)))


def torque_range(arm: ArmModel, base: BaseParameters, theta: FloatArray, samples: int = 400,
                 seed: int = 0) -> FloatArray:
    """Each joint's torque range (N m), shape (n,): its effort limit (what its sensor reads
    up to), or where the URDF gives none, the RMS of its nominal torque Y θ on random
    states."""
    nominal = np.sqrt(np.mean((_base_columns(arm, base, samples, seed)
                               @ np.asarray(theta, dtype=float)) ** 2, axis=0))
    limit = np.asarray(arm.effort_limit, dtype=float)
    return np.where(np.isfinite(limit) & (limit > 0), limit, nominal)


def prior_std(arm: ArmModel, base: BaseParameters, theta: FloatArray, factor: float = 1.0,
              share: float = PRIOR_TORQUE_SHARE, samples: int = 400, seed: int = 0
              ) -> FloatArray:
    """Prior standard deviations of base parameters: ``factor`` × |θ| plus the change of
    θ_k that moves some joint's torque by ``share`` of its range.

    Column k of the base regressor moves joint i's torque by r_ik per unit of θ_k (RMS over
    random states), so the second part is s_k = share × min_i range_i / r_ik
    (:func:`torque_range`): an offset of a 150 N m joint gets 15 N m, and so does its Coulomb
    friction, whatever their nominal values (0 for an offset, and for friction a URDF does
    not state).

    Parameters
    ----------
    arm : ArmModel
    base : BaseParameters
    theta : ndarray, shape (b,)
        Nominal base parameters.
    factor : float
        Relative part (σ per |θ|).
    share : float
        Share of a joint's torque range.
    samples, seed : int
        Random states of the RMS.

    Returns
    -------
    ndarray, shape (b,)
        Units of each base parameter (every base column moves some joint's torque, so the
        second part is finite and > 0 where that joint's range is).
    """
    theta = np.asarray(theta, dtype=float)
    rms = np.sqrt(np.mean(_base_columns(arm, base, samples, seed) ** 2, axis=0))  # (n, b)
    torque = torque_range(arm, base, theta, samples, seed)
    with np.errstate(divide="ignore", invalid="ignore"):
        move = np.where(rms > 0, share * torque[:, None] / rms, np.inf)
    return factor * np.abs(theta) + move.min(axis=0)


def initial_noise_var(arm: ArmModel, base: BaseParameters, theta: FloatArray
                      ) -> tuple[float, ...]:
    """The RLS's noise variances before the data say, per joint (N² m²): the square of
    :data:`NOISE_TORQUE_SHARE` × its :func:`torque_range`. One value for every joint (0.01
    N² m², as before) weighted a 150 N m and a 28 N m joint alike, and with adaptive weights
    a designed UR5 trajectory's estimate ended 17 σ from the batch fit after 60 s."""
    return tuple(float(v) for v in (NOISE_TORQUE_SHARE * torque_range(arm, base, theta)) ** 2)


def default_rls(arm: ArmModel, base: BaseParameters, theta: FloatArray,
                forgetting_factor: float = 0.9995, adapt_weights: bool = True) -> RLSConfig:
    """The arm's RLS settings: λ = 0.9995 (memory 40 s at 50 Hz), the noise variances of
    :func:`initial_noise_var` (re-estimated from the innovations, and with ``adapt_weights``
    weighting the joints), and on a change alarm the covariance reset to a scaled trace of
    10 b (b the number of base parameters), which drops what was learnt before the change.

    Parameters
    ----------
    arm : ArmModel
    base : BaseParameters
    theta : ndarray, shape (b,)
        Nominal base parameters (:func:`torque_range` of a joint without an effort limit).
    forgetting_factor : float
    adapt_weights : bool

    Returns
    -------
    RLSConfig
    """
    return RLSConfig(forgetting_factor=forgetting_factor, adapt_weights=adapt_weights,
                     noise_var=initial_noise_var(arm, base, theta), trace_max=10.0 * base.size,
                     row_names=tuple(arm.names))


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
    coulomb_width : float
        The dry-friction form the Coulomb parameters belong to: 0 for Fc·sign(q̇), w > 0 for
        Fc·tanh(q̇ / w) (rad/s; :func:`~dampest_ros.core.arm.regressor.joint_columns`).
    """

    joint_names: tuple[str, ...]
    parameter_names: list[str]
    theta: FloatArray
    theta_std: FloatArray
    identified: NDArray[np.bool_]
    mapping: list[str]
    version: int = 1
    identity: Identity | None = None
    coulomb_width: float = 0.0


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
        Forgetting, noise and CUSUM settings of the vehicle's RLS with a row per joint
        (``row_names`` the joints). Default: :func:`default_rls`.
    hop : float
        Seconds of samples emitted per filtering pass.
    identity : Identity, optional
        The arm's, carried by every :meth:`estimate`.
    """

    def __init__(self, arm: ArmModel, base: BaseParameters, theta0: FloatArray,
                 std0: FloatArray, config: IdentifyConfig, rls: RLSConfig | None = None,
                 hop: float = 1.0, identity: Identity | None = None) -> None:
        self.arm, self.base, self.config, self.hop = arm, base, config, float(hop)
        self.identity = identity
        rls = rls or default_rls(arm, base, theta0)
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
                           int(version), self.identity, self.config.coulomb_width)

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
            self.alarm_joints.append(self.rls.monitor.channels())
            self.rls.monitor.reset()
        return len(t)
