"""Arm identification from measured joint positions and torques, and its validation.

1. q, q̇ by the zero-phase low-pass of :func:`dampest_ros.core.signals.preprocess.zero_phase` (its
   derivative option), q̈ by differencing the filtered q̇; τ through the same filter, so
   both sides of τ = Y π see the same gain and no delay.
2. The first and last 3 / cutoff seconds dropped (the filter's end effects), decimation to
   ``rate_out`` (the filtered signals hold nothing above the cutoff).
3. The regressor in chunks into per-joint normal equations (rows with |q̇_j| ≥ v_min).
4. OLS, WLS and the physically consistent fit (:mod:`dampest_ros.core.arm.fit`); the
   covariance counts the rows the filtered noise makes dependent.

The noise floor of a joint's torque is estimated from the measurement itself: the power of
τ − τ_filtered, divided by the share of a white noise's power the filter stops.

Real joint streams are not a perfect clock: jitter and gaps follow the one rule of
:mod:`dampest_ros.core.signals.resample` (jittered stamps resampled onto a uniform grid with
the stretch's mean step before filtering; a step over ``GAP_PERIODS`` periods is a gap, across
which nothing is filtered: :func:`filter_stretches` filters each gap-free stretch on its own).
A stamp more than ``GAP_PERIODS`` periods before the one recorded just before it is a clock
jump (the source restarted or reset its clock): the record is split there, the samples after
it form stretches of their own on their own clock, and the jump is named (where, how far
back). Smaller steps back are reordering and are sorted.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.arm.base import BaseParameters
from dampest_ros.core.arm.fit import (
    BaseFit,
    ConsistentFit,
    JointNormals,
    fit_base,
    fit_consistent,
)
from dampest_ros.core.arm.model import ArmModel
from dampest_ros.core.arm.regressor import regressor
from dampest_ros.core.signals.preprocess import zero_phase, zero_phase_many
from dampest_ros.core.signals.resample import (
    GAP_PERIODS,
    increasing_runs,
    on_grid,
    step_gaps,
)

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class IdentifyConfig:
    """Options of arm identification.

    Attributes
    ----------
    cutoff : float
        Low-pass −6 dB frequency (Hz) for q and τ.
    rate_out : float
        Rate the filtered signals are decimated to (Hz); at least 2 × cutoff.
    min_speed : float
        Rows of joint j with |q̇_j| below this (rad/s) are not used.
    coulomb_width : float
        0: sign(q̇); > 0: tanh(q̇ / width) (rad/s).
    chunk : int
        Samples per regressor chunk (2000: the chunk's arrays stay in the CPU caches; the
        regressor of 20 000 took 1.6× as long per sample).
    chunk_seconds : float
        Length of the windows the input is filtered in (s).
    """

    cutoff: float = 10.0
    rate_out: float = 50.0
    min_speed: float = 0.1
    coulomb_width: float = 0.0
    chunk: int = 2_000
    chunk_seconds: float = 60.0


@dataclass(frozen=True)
class Filtered:
    """Zero-phase filtered, decimated joint signals.

    Attributes
    ----------
    t : ndarray, shape (M,)
        Time (s).
    q, qd, qdd : ndarray, shape (M, n)
        rad, rad/s, rad/s².
    tau : ndarray, shape (M, n)
        Filtered torque (N m).
    noise : ndarray, shape (n,)
        Estimated torque noise standard deviation per joint at the input rate (N m); an
        upper bound (dry friction's steps at velocity reversals count as noise here).
    index : ndarray of int, shape (M,)
        Rows of the input the samples are.
    """

    t: FloatArray
    q: FloatArray
    qd: FloatArray
    qdd: FloatArray
    tau: FloatArray
    noise: FloatArray
    index: NDArray[np.int64]


def _stop_share(rate: float, cutoff: float, order: int = 4) -> float:
    """Share of a white noise's power that the zero-phase filter's complement passes:
    mean over [0, rate/2] of (1 − H(f))², H = 1 / (1 + (f/f_c)^{2·order})."""
    f = np.linspace(0.0, rate / 2.0, 20_001)
    H = 1.0 / (1.0 + (f / cutoff) ** (2 * order))
    return float(np.mean((1.0 - H) ** 2))


def _noise_bandwidth(cutoff: float, order: int = 4) -> float:
    """Equivalent noise bandwidth ∫₀^∞ H(f)² df of the zero-phase filter (Hz)."""
    f = np.linspace(0.0, 20.0 * cutoff, 200_001)
    H = 1.0 / (1.0 + (f / cutoff) ** (2 * order))
    return float(np.trapezoid(H * H, f))


class ShortDataError(ValueError):
    """Too few joint samples to filter: fewer than 10, or not more than the four filter
    edges (:func:`_edge`) a stretch needs."""


def _require_samples(t: FloatArray) -> None:
    if len(t) < 10:
        raise ShortDataError(f"{len(t)} samples; identification needs a run of many periods")


def _edge(rate: float, config: IdentifyConfig) -> int:
    """Samples dropped at each end of a filtered stretch (3 / cutoff s, the filter's end
    effects); a stretch needs more than four times as many."""
    return int(np.ceil(3.0 * rate / config.cutoff))


def filter_joints(t: FloatArray, position: FloatArray, effort: FloatArray,
                  config: IdentifyConfig) -> Filtered:
    """Filter, differentiate and decimate measured joint data.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times (s), increasing, without gaps; jitter is resampled away.
    position, effort : ndarray, shape (N, n)
        Measured joint positions (rad) and torques (N m).
    config : IdentifyConfig

    Returns
    -------
    Filtered

    Raises
    ------
    ValueError
        If the samples have a gap (see :func:`filter_stretches`), are too few, or the rates
        do not fit.
    """
    t = np.asarray(t, dtype=float)
    _require_samples(t)
    dt = np.diff(t)
    period = float(np.median(dt))
    bad = step_gaps(dt, period)
    if len(bad):
        raise ValueError(f"joint samples have {len(bad)} gaps (steps over {GAP_PERIODS:g} "
                         f"sample periods, the first after t = {t[bad[0]]:.3f} s); filter "
                         "each gap-free stretch on its own (filter_stretches)")
    n = np.shape(position)[1]
    t, both, index, period = on_grid(t, np.hstack([np.asarray(position, dtype=float),
                                                   np.asarray(effort, dtype=float)]))
    position, effort = both[:, :n], both[:, n:]
    rate = 1.0 / period
    if not 0.0 < config.cutoff < rate / 2.0:
        raise ValueError(f"cutoff {config.cutoff} Hz must be in (0, {rate / 2:g}) Hz, the "
                         f"Nyquist frequency of the {rate:g} Hz samples")
    # the ends see the filter's mirror images: drop 3 / cutoff seconds at each
    edge = _edge(rate, config)
    if len(t) <= 4 * edge:
        raise ShortDataError(f"{len(t) / rate:.3g} s of joint data; at least "
                             f"{4 * edge / rate:.3g} s are needed at a {config.cutoff:g} Hz "
                             "cutoff")
    if not 2.0 * config.cutoff <= config.rate_out <= 1.01 * rate:  # (the input rate is measured)
        raise ValueError(f"output rate {config.rate_out} Hz must be in [2 × cutoff, "
                         f"{rate:g}] Hz")
    keep = np.arange(edge, len(t) - edge, max(1, round(rate / config.rate_out)))
    q, qd, qdd, tau = (np.empty((len(keep), n)) for _ in range(4))
    # in windows of chunk_seconds with a margin of 10 / cutoff s on each side (what
    # zero_phase mirrors at an end): the same result as one pass, a fraction of the memory
    margin = int(np.ceil(10.0 * rate / config.cutoff))
    width = max(int(config.chunk_seconds * rate), margin)
    stopped = np.zeros(n)
    for start in range(0, len(t), width):
        stop = min(start + width, len(t))
        lo, hi = max(start - margin, 0), min(stop + margin, len(t))
        inner = slice(start - lo, stop - lo)
        w_q, w_qd = zero_phase_many(position[lo:hi], rate, config.cutoff, (False, True))
        w_tau = zero_phase(effort[lo:hi], rate, config.cutoff)
        stopped += np.sum((effort[start:stop] - w_tau[inner]) ** 2, axis=0)
        rows = np.flatnonzero((keep >= start) & (keep < stop))
        at = keep[rows] - lo  # inside the window, never at its ends
        q[rows] = w_q[at]
        qd[rows] = w_qd[at]
        # q̈ of the filtered q̇: its central difference (np.gradient's), at the kept rows only
        qdd[rows] = (w_qd[at + 1] - w_qd[at - 1]) / (2.0 * (1.0 / rate))
        tau[rows] = w_tau[at]
    # σ² ≈ mean((τ − τ_f)²) / share of white noise above the cutoff (the trajectory's own
    # content is far below it)
    noise = np.sqrt(stopped / len(t) / _stop_share(rate, config.cutoff))
    return Filtered(t[keep], q, qd, qdd, tau, noise, index[keep])


@dataclass(frozen=True)
class Stretches:
    """How :func:`filter_stretches` split a record.

    Attributes
    ----------
    gaps : int
        Gaps found (steps over :data:`GAP_PERIODS` periods, or back in time).
    used, skipped : int
        Gap-free stretches filtered, and those too short to filter.
    seconds_skipped : float
        Their length (s).
    duplicates : int
        Samples dropped for repeating an earlier stamp.
    clock_jumps : tuple of (int, float, float)
        Per clock jump: the recorded sample it comes before (0-based), the stamp before it
        (s) and how far it goes back (s).
    """

    gaps: int
    used: int
    skipped: int
    seconds_skipped: float
    duplicates: int
    clock_jumps: tuple[tuple[int, float, float], ...] = ()

    def describe(self) -> str:
        """One line for a log or a report ('' when the record had no gap)."""
        if not self.gaps and not self.duplicates:
            return ""
        jumps = "".join(f"; the clock jumps back {back:.6g} s at sample {k} (after t = "
                        f"{t:.6g} s): split there" for k, t, back in self.clock_jumps)
        return (f"{self.gaps} gap{'s' * (self.gaps != 1)}: {self.used} gap-free stretches "
                f"filtered, {self.skipped} too short ({self.seconds_skipped:.3g} s) left out"
                + (f"; {self.duplicates} samples with a repeated stamp dropped"
                   if self.duplicates else "") + jumps)


def clock_jumps(t: FloatArray) -> NDArray[np.int64]:
    """Indices i of recorded samples whose stamp t[i] lies more than
    :data:`GAP_PERIODS` periods (the median forward step) before t[i − 1]: the source's
    clock jumped back."""
    dt = np.diff(np.asarray(t, dtype=float))
    forward = dt[dt > 0]
    if not len(forward):
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(dt < -GAP_PERIODS * float(np.median(forward))) + 1


def filter_stretches(t: FloatArray, position: FloatArray, effort: FloatArray,
                     config: IdentifyConfig) -> tuple[Filtered, Stretches]:
    """:func:`filter_joints` on each gap-free stretch of a record, the results joined.

    The record is split at its clock jumps (:func:`clock_jumps`), each part put in stamp
    order (a repeated stamp keeps its first sample) and split at its gaps. ``index`` of the
    result counts rows of the input as given; ``noise`` is the stretches' RMS noise weighted
    by their length. After a clock jump ``t`` of the result starts again from the earlier
    stamps.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times (s).
    position, effort : ndarray, shape (N, n)
        rad, N m.
    config : IdentifyConfig

    Returns
    -------
    Filtered, Stretches

    Raises
    ------
    ValueError
        If no stretch is long enough, or the rates do not fit.
    """
    t = recorded = np.asarray(t, dtype=float)
    jumps = clock_jumps(t)
    orders = []
    for part in np.split(np.arange(len(t)), jumps):
        order = part[np.argsort(t[part], kind="stable")]
        orders.append(order[np.concatenate([[True], np.diff(t[order]) > 0.0])])
    order = np.concatenate(orders)
    duplicates = len(t) - len(order)
    t, position, effort = t[order], np.asarray(position)[order], np.asarray(effort)[order]
    _require_samples(t)
    dt = np.diff(t)
    period = float(np.median(dt[dt > 0.0]))
    bounds = np.concatenate([[0], step_gaps(dt, period) + 1, [len(t)]])
    parts: list[Filtered] = []
    skipped = 0.0
    for a, b in itertools.pairwise(bounds.tolist()):
        try:
            f = filter_joints(t[a:b], position[a:b], effort[a:b], config)
        except ShortDataError:  # too short to filter: left out
            skipped += t[b - 1] - t[a]
            continue
        parts.append(Filtered(f.t, f.q, f.qd, f.qdd, f.tau, f.noise, order[f.index + a]))
    info = Stretches(len(bounds) - 2, len(parts), len(bounds) - 1 - len(parts), float(skipped),
                     duplicates, tuple((int(k), float(recorded[k - 1]),
                                        float(recorded[k - 1] - recorded[k])) for k in jumps))
    if not parts:
        need = 4 * _edge(1.0 / period, config) * period
        raise ShortDataError(f"no gap-free stretch of joint data is over {need:.3g} s long, "
                             f"the least a {config.cutoff:g} Hz cutoff needs "
                             f"({info.describe()})")
    weights = np.array([len(f.t) for f in parts], dtype=float)
    noise = np.sqrt(np.average([f.noise ** 2 for f in parts], axis=0, weights=weights))
    t_, q, qd, qdd, tau, index = (np.concatenate([getattr(f, k) for f in parts])
                                  for k in ("t", "q", "qd", "qdd", "tau", "index"))
    return Filtered(t_, q, qd, qdd, tau, noise, index), info


def accumulate(arm: ArmModel, data: Filtered, config: IdentifyConfig,
               normals: JointNormals | None = None,
               rows: NDArray[np.bool_] | None = None) -> JointNormals:
    """Per-joint normal equations of filtered data, regressor built in chunks.

    Parameters
    ----------
    arm : ArmModel
    data : Filtered
    config : IdentifyConfig
    normals : JointNormals, optional
        Sums to add to (a second run, a window of a long log).
    rows : ndarray of bool, shape (M, n), optional
        The rows to fit; default :func:`usable_rows` (those the friction model covers).

    Returns
    -------
    JointNormals
    """
    p = 14 * arm.n
    normals = normals or JointNormals.empty(arm.n, p)
    use = usable_rows(data.t, data.qd, config) if rows is None else rows
    for s in range(0, len(data.t), config.chunk):
        k = slice(s, s + config.chunk)
        Y = regressor(arm, data.q[k], data.qd[k], data.qdd[k], config.coulomb_width)
        normals.add(Y, data.tau[k], use[k])
    return normals


def usable_rows(t: FloatArray, qd: FloatArray, config: IdentifyConfig) -> NDArray[np.bool_]:
    """Rows where joint j's friction follows the Coulomb model through the filter: |q̇_j| ≥
    min_speed and no reversal of q̇_j within 2 / cutoff seconds (the filter smears the
    torque's step at a reversal over about that long).

    Parameters
    ----------
    t : ndarray, shape (M,)
        s.
    qd : ndarray, shape (M, n)
        rad/s.
    config : IdentifyConfig

    Returns
    -------
    ndarray of bool, shape (M, n)
    """
    use = np.abs(qd) >= config.min_speed
    window = 2.0 / config.cutoff
    # each run of increasing t on its own (after a clock jump t starts again)
    for run in increasing_runs(t):
        tr = t[run]
        for j in range(qd.shape[1]):  # per joint (n columns), vectorised over samples
            sign = np.signbit(qd[run, j])
            flips = tr[1:][sign[1:] != sign[:-1]]
            if len(flips):
                i = np.clip(np.searchsorted(flips, tr), 1, len(flips)) - 1
                near = np.minimum(np.abs(tr - flips[i]),
                                  np.abs(tr - flips[np.minimum(i + 1, len(flips) - 1)]))
                use[run, j] &= near >= window
    return use


@dataclass(frozen=True)
class ArmIdentification:
    """Result of :func:`identify_arm`.

    Attributes
    ----------
    base : BaseParameters
    ols, wls : BaseFit
    consistent : ConsistentFit
    noise : ndarray, shape (n,)
        Estimated torque noise per joint (N m).
    rows : ndarray of int, shape (n,)
        Rows used per joint.
    """

    base: BaseParameters
    ols: BaseFit
    wls: BaseFit
    consistent: ConsistentFit
    noise: FloatArray
    rows: NDArray[np.int64]


def identify_arm(arm: ArmModel, base: BaseParameters, data: Filtered, nominal: FloatArray,
                 config: IdentifyConfig, rows: NDArray[np.bool_] | None = None
                 ) -> ArmIdentification:
    """OLS, WLS and physically consistent fits of filtered joint data.

    Parameters
    ----------
    arm : ArmModel
    base : BaseParameters
    data : Filtered
    nominal : ndarray, shape (14 n,)
        Nominal full parameters (the physically consistent fit's start and tie-break).
    config : IdentifyConfig
    rows : ndarray of bool, shape (M, n), optional
        The rows to fit (:func:`accumulate`); default those the friction model covers.

    Returns
    -------
    ArmIdentification
    """
    normals = accumulate(arm, data, config, rows=rows)
    # filtered noise has 2 B independent samples per second (B its noise bandwidth)
    per = config.rate_out / (2.0 * _noise_bandwidth(config.cutoff))
    ols = fit_base(normals, base, weighted=False, rows_per_independent=per)
    wls = fit_base(normals, base, weighted=True, rows_per_independent=per)
    return ArmIdentification(base, ols, wls, fit_consistent(normals, base, wls, nominal),
                             data.noise, normals.count)


def predict(arm: ArmModel, base: BaseParameters, theta: FloatArray, q: FloatArray,
            qd: FloatArray, qdd: FloatArray, config: IdentifyConfig) -> FloatArray:
    """Joint torques of base parameters θ along a motion, in chunks.

    Parameters
    ----------
    arm : ArmModel
    base : BaseParameters
    theta : ndarray, shape (b,)
    q, qd, qdd : ndarray, shape (N, n)
    config : IdentifyConfig
        Its chunk size and Coulomb width.

    Returns
    -------
    ndarray, shape (N, n)
        τ (N m).
    """
    out = np.empty_like(np.asarray(q, dtype=float))
    for s in range(0, len(q), config.chunk):
        k = slice(s, s + config.chunk)
        Yb = base.columns(regressor(arm, q[k], qd[k], qdd[k], config.coulomb_width))
        out[k] = Yb @ theta
    return out


def torque_rmse(measured: FloatArray, predicted: FloatArray, qd: FloatArray,
                min_speed: float) -> tuple[FloatArray, FloatArray]:
    """RMS of measured − predicted torque per joint, on all rows and on the rows the
    friction model covers (|q̇_j| ≥ min_speed).

    Parameters
    ----------
    measured, predicted : ndarray, shape (N, n)
        N m.
    qd : ndarray, shape (N, n)
        rad/s.
    min_speed : float
        rad/s.

    Returns
    -------
    all_rows, moving_rows : ndarray, shape (n,)
        N m.
    """
    e2 = (measured - predicted) ** 2
    use = np.abs(qd) >= min_speed
    moving = np.sqrt(np.sum(e2 * use, axis=0) / np.maximum(use.sum(axis=0), 1))
    return np.sqrt(e2.mean(axis=0)), moving
