"""From sensor topics to synchronised samples of ν, ν̇ and τ (offline, zero-phase).

Pipeline, all vectorised over whole segments:

1. Frames: IMU, DVL and thruster data from ROS (FLU/ENU) to Fossen (FRD/NED).
2. DVL gaps longer than ``max_gap`` split the data into segments (nothing is invented inside
   a long gap); DVL samples that disagree with the inertially fused velocity are dropped.
3. On a common grid at ``rate`` Hz per segment: attitude, gyro and specific force from the
   IMU, thrust through the allocation matrix into τ (optionally shifted by a known delay).
4. Linear velocity by a zero-phase complementary filter in the non-rotating NED frame: the
   DVL below ``crossover`` Hz and the integrated IMU acceleration R f + g above it
   (Butterworth pairs with |H_lp|² + |H_hp|² = 1, so the fusion is exact where both agree),
   then rotated back to the body. Angular acceleration by differentiating ω.
5. The same light zero-phase low-pass (``cutoff``) on ν, ν̇ and τ; ν and ν̇ also get the
   moving average that window-averaged thrust telemetry has, so all three see the same
   filter. Segment ends are trimmed of filter transients.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import fft as sp_fft
from scipy import integrate, signal

from dampest_ros.core import frames
from dampest_ros.core.measurements import (
    ImuSeries,
    JointSeries,
    PressureSeries,
    Recording,
    Series,
    TwistSeries,
)
from dampest_ros.core.rigid_body import ConfigError
from dampest_ros.core.samples import Samples
from dampest_ros.core.thrusters import Thrusters

FloatArray = NDArray[np.float64]


class DataError(ValueError):
    """The data cannot be used as asked (missing topic, too short, no overlap…)."""


@dataclass(frozen=True)
class PreprocessConfig:
    """Settings of :func:`preprocess` (defaults suit 200 Hz IMU, 5–8 Hz DVL).

    Attributes
    ----------
    rate : float
        Output sample rate (Hz); the grid is phase-locked to the centres of the thruster
        telemetry windows.
    inertial_rate : float
        Rate (Hz, a multiple of ``rate``) of the grid on which IMU and DVL are fused and
        differentiated; about the IMU rate.
    cutoff : float
        Light zero-phase low-pass on ν, ν̇ and τ (Hz) against sensor noise; the regression
        applies its own, stronger, parallel filter (:mod:`dampest_ros.core.batch`).
    crossover : float
        DVL/IMU fusion crossover (Hz).
    max_gap : float
        DVL gaps longer than this (s) split segments.
    trim : float
        Seconds dropped at both ends of each segment (filter transients).
    min_segment : float
        Segments shorter than this (s, after trimming) are dropped.
    stretch : float
        Long segments are processed this many seconds at a time (with overlap), so memory
        does not grow with the length of the log.
    outlier_sigma : float
        DVL samples farther than this many robust σ from a running median are dropped.
    delay : float
        Known delay (s) of the vehicle's response after the logged thrust; τ is shifted.
    atmospheric_pressure : float
        Pa, for depth from absolute pressure.
    """

    rate: float = 50.0
    inertial_rate: float = 200.0
    cutoff: float = 10.0
    crossover: float = 0.3
    max_gap: float = 1.0
    trim: float = 2.0
    min_segment: float = 5.0
    stretch: float = 300.0
    outlier_sigma: float = 6.0
    delay: float = 0.0
    atmospheric_pressure: float = 101325.0

    def __post_init__(self) -> None:
        if not 0 < self.cutoff < 0.5 * self.rate:
            raise ConfigError("cutoff", f"must be in (0, rate/2), got {self.cutoff}")
        if not 0 < self.crossover < self.cutoff:
            raise ConfigError("crossover", f"must be in (0, cutoff), got {self.crossover}")
        for name in ("max_gap", "trim", "min_segment", "outlier_sigma"):
            if getattr(self, name) < 0:
                raise ConfigError(name, "must be ≥ 0")

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PreprocessConfig:
        """From a mapping; unknown keys raise ConfigError naming them."""
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ConfigError("preprocess", f"unknown key(s) {sorted(unknown)}")
        return cls(**{k: float(v) for k, v in d.items()})


def _need(rec: Recording, topic: str, kind: type[Series], minimum: int = 10) -> Any:
    if topic not in rec:
        raise DataError(f"topic {topic!r} missing; the data has {sorted(rec)}")
    s = rec[topic]
    if not isinstance(s, kind):
        raise DataError(f"topic {topic!r} is {type(s).__name__}, expected {kind.__name__}")
    if len(s) < minimum:
        raise DataError(f"topic {topic!r} has only {len(s)} messages")
    return s


def _clean(s: Series, *cols: FloatArray) -> NDArray[np.bool_]:
    """Rows with finite values and strictly increasing stamps."""
    ok = np.isfinite(s.stamp)
    for c in cols:
        ok &= np.all(np.isfinite(c.reshape(len(s), -1)), axis=1)
    inc = np.ones(len(s), dtype=bool)
    inc[1:] = np.diff(s.stamp) > 0
    return np.asarray(ok & inc)


def zero_phase(x: FloatArray, rate: float, cutoff: float, derivative: bool = False,
               window: float = 0.0, order: int = 4) -> FloatArray:
    """Zero-phase Butterworth-magnitude low-pass, optionally differentiated, along axis 0.

    Applies H(f) = 1 / (1 + (f/f_c)^{2·order}) (the gain of a Butterworth filter run forwards
    and backwards) in the frequency domain, times i2πf for the derivative, so that a signal
    and its derivative are filtered identically and the derivative is exact for what the
    filter passes (a finite difference loses 16 % at 8 Hz and 50 Hz sampling). Each end is
    mirrored over 10 periods of the cutoff, so the ends do not wrap around and the result
    does not depend on how long the array is beyond that.

    Parameters
    ----------
    x : ndarray, shape (N, ...)
    rate : float
        Sample rate (Hz).
    cutoff : float
        −6 dB frequency f_c (Hz).
    derivative : bool
        Return the filtered time derivative (units of x per second).
    window : float
        Also apply a centred moving average of this length (s): H · sinc(f w). Used to give
        every signal the averaging that window-averaged telemetry (thrust) already has.
    order : int

    Returns
    -------
    ndarray, shape like x
    """
    n = x.shape[0]
    # mirror P samples at each end (P ≫ the filter's impulse response, or all of x), then
    # bridge the two mirrors linearly up to a fast FFT length: the data only ever see their
    # own mirror images, whatever the length, so chunked and whole filtering agree
    P = min(n - 1, int(np.ceil(10.0 * rate / cutoff))) if n > 1 else 0
    size = sp_fft.next_fast_len(n + 2 * P + 2, real=True)
    left, right = x[P:0:-1], x[-2:-P - 2:-1]
    gap = size - n - 2 * P
    w = (np.arange(1, gap + 1) / (gap + 1)).reshape((-1,) + (1,) * (x.ndim - 1))
    bridge = (1 - w) * (right[-1:] if P else x[-1:]) + w * (left[:1] if P else x[:1])
    ext = np.concatenate([x, right, bridge, left], axis=0)
    f = np.fft.rfftfreq(size, d=1.0 / rate)
    # H(f) = 1 / (1 + (f/f_c)^{2 order})
    H = 1.0 / (1.0 + (f / cutoff) ** (2 * order)) * np.sinc(f * window)
    if derivative:
        H = H * (2j * np.pi * f)
    shape = (len(f),) + (1,) * (x.ndim - 1)
    y = sp_fft.irfft(sp_fft.rfft(ext, axis=0) * H.reshape(shape), n=size, axis=0)
    return np.asarray(y[:n], dtype=float)


def _interp(t: FloatArray, tp: FloatArray, x: FloatArray) -> FloatArray:
    """Linear interpolation of every column of x (N, k) at t."""
    x2 = x.reshape(len(tp), -1)
    out = np.empty((len(t), x2.shape[1]))
    for j in range(x2.shape[1]):
        out[:, j] = np.interp(t, tp, x2[:, j])
    return out.reshape((len(t), *x.shape[1:]))


def fuse_velocity(t: FloatArray, R: FloatArray, f: FloatArray, t_dvl: FloatArray,
                  v_dvl: FloatArray, gravity: float, crossover: float
                  ) -> tuple[FloatArray, FloatArray]:
    """Zero-phase complementary fusion of DVL velocity and IMU specific force.

    Done in the non-rotating NED frame, where d/dt (R v) = R f + [0, 0, g]: the DVL below
    ``crossover`` and the integrated IMU acceleration above it.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Uniform grid (s).
    R : ndarray, shape (N, 3, 3)
        Body (FRD) → NED rotations on the grid.
    f : ndarray, shape (N, 3)
        Specific force on the grid (FRD, m/s²).
    t_dvl, v_dvl : ndarray, shapes (M,), (M, 3)
        DVL stamps and body velocities (FRD, m/s).
    gravity : float
    crossover : float
        Hz.

    Returns
    -------
    v, v_dot : ndarray, shape (N, 3)
        Body-frame velocity over ground and its derivative in the NED frame rotated to the
        body (R ᵀ d/dt(R v)).
    """
    rate = 1.0 / float(t[1] - t[0])
    a_ned = np.einsum("nij,nj->ni", R, f)
    a_ned[:, 2] += gravity
    v_dvl_ned = np.einsum("nij,nj->ni", R, _interp(t, t_dvl, v_dvl))
    v_imu_ned = integrate.cumulative_trapezoid(a_ned, dx=1.0 / rate, axis=0, initial=0.0)
    # v_ned = LP(R v_dvl) + (1 − LP)(∫ (R f + g e_z) dt): complementary at every frequency;
    # its derivative is the same with the DVL differentiated and the IMU acceleration as is
    v_ned = v_imu_ned + zero_phase(v_dvl_ned - v_imu_ned, rate, crossover)
    a_fused = a_ned + zero_phase(v_dvl_ned - v_imu_ned, rate, crossover, derivative=True)
    return (np.einsum("nji,nj->ni", R, v_ned), np.einsum("nji,nj->ni", R, a_fused))


def dvl_inliers(t: FloatArray, v_dvl: FloatArray, t_ref: FloatArray, v_ref: FloatArray,
                sigma: float, floor: float = 0.01) -> NDArray[np.bool_]:
    """DVL samples within ``sigma`` robust standard deviations of a reference velocity.

    The reference is the fused estimate, which follows fast manoeuvres through the IMU, so
    only samples that disagree with the inertial motion are rejected.

    Parameters
    ----------
    t, v_dvl : ndarray, shapes (M,), (M, 3)
    t_ref, v_ref : ndarray, shapes (N,), (N, 3)
    sigma : float
    floor : float
        Smallest robust σ (m/s), so that noise-free data keep every sample.
    """
    if sigma <= 0:
        return np.ones(len(t), dtype=bool)
    dev = np.abs(v_dvl - _interp(t, t_ref, v_ref))
    # robust σ = 1.4826 · median absolute deviation
    scale = np.maximum(1.4826 * np.median(dev, axis=0), floor)
    return np.asarray(np.all(dev <= sigma * scale, axis=1))


def segments_from_gaps(t: FloatArray, max_gap: float) -> list[tuple[float, float]]:
    """Time spans of a stamp series split wherever two stamps are more than max_gap apart."""
    if len(t) == 0:
        return []
    cut = np.flatnonzero(np.diff(t) > max_gap)
    starts = np.r_[t[0], t[cut + 1]]
    ends = np.r_[t[cut], t[-1]]
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def thruster_wrench(joints: JointSeries, thrusters: Thrusters) -> FloatArray:
    """τ (N, 6) from logged thrusts (JointState effort, N) through the allocation matrix."""
    try:
        order = [joints.names.index(n) for n in thrusters.names]
    except ValueError:
        raise DataError(f"thruster names {list(joints.names)} do not match the vehicle's "
                        f"{list(thrusters.names)}") from None
    # τ = T_alloc f
    return np.asarray(joints.effort[:, order] @ thrusters.allocation.T, dtype=float)


def preprocess(rec: Recording, thrusters: Thrusters, gravity: float, rho: float,
               config: PreprocessConfig | None = None,
               topics: dict[str, str] | None = None,
               report: dict[str, float] | None = None) -> Samples:
    """Synchronise and filter sensor topics into samples of ν, ν̇, τ.

    Parameters
    ----------
    rec : Recording
        Topic → series, ROS frames (as read from a bag).
    thrusters : Thrusters
        Allocation (names must match the JointState names).
    gravity, rho : float
        g (m/s²) and water density (kg/m³).
    config : PreprocessConfig, optional
    topics : dict, optional
        Role → topic name for ``imu``, ``dvl``, ``pressure``, ``thrusters``.
    report : dict, optional
        Filled with counts: ``rejected_nonfinite_or_unordered``, ``dvl_outliers``,
        ``segments``, ``dropped_seconds`` (data in gaps and too-short segments).

    Returns
    -------
    Samples
        FRD/NED, uniformly sampled segments.
    """
    cfg = config or PreprocessConfig()
    names = {"imu": "imu/data", "dvl": "dvl/twist", "pressure": "pressure",
             "thrusters": "thrusters/state", **(topics or {})}
    imu: ImuSeries = _need(rec, names["imu"], ImuSeries)
    dvl: TwistSeries = _need(rec, names["dvl"], TwistSeries)
    thr: JointSeries = _need(rec, names["thrusters"], JointSeries)
    pres = rec.get(names["pressure"])

    masks = [_clean(imu, imu.orientation, imu.angular_velocity, imu.linear_acceleration),
             _clean(dvl, dvl.linear), _clean(thr, thr.effort)]
    # copies only where rows must go (a long IMU log is the largest thing in memory)
    imu = imu if masks[0].all() else imu.select(masks[0])  # type: ignore[assignment]
    dvl = dvl if masks[1].all() else dvl.select(masks[1])  # type: ignore[assignment]
    thr = thr if masks[2].all() else thr.select(masks[2])  # type: ignore[assignment]

    # --- frames: ROS (FLU/ENU) → Fossen (FRD/NED); the IMU per stretch, below -----------
    t_dvl, v_dvl = dvl.stamp, frames.body_vec(dvl.linear)
    n_outliers = 0
    tau_thr = thruster_wrench(thr, thrusters)
    window = float(np.median(np.diff(thr.stamp)))
    phase = float(((thr.stamp[0] - window / 2) * cfg.rate) % 1.0)
    ratio = max(1, round(cfg.inertial_rate / cfg.rate))

    lo = max(imu.stamp[0], t_dvl[0], thr.stamp[0])
    hi = min(imu.stamp[-1], t_dvl[-1], thr.stamp[-1])
    if hi - lo < cfg.min_segment + 2 * cfg.trim:
        raise DataError(f"the topics overlap for only {max(hi - lo, 0.0):.1f} s")

    rate_f = cfg.rate * ratio
    pressure = pres if isinstance(pres, PressureSeries) and len(pres) > 1 else None

    def window_(t: FloatArray, core: slice) -> tuple[FloatArray, ...]:
        """ν, ν̇, R, τ, depth on the output grid t (one stretch of a segment with margins);
        DVL outliers are counted within the core."""
        nonlocal n_outliers
        tf = t[0] + np.arange((len(t) - 1) * ratio + 1) / rate_f
        i0, i1 = np.searchsorted(imu.stamp, [tf[0], tf[-1]])
        k = slice(max(int(i0) - 1, 0), int(i1) + 1)
        ts = imu.stamp[k]
        # attitude: normalised linear interpolation of sign-aligned quaternions
        q = imu.orientation[k][:, [3, 0, 1, 2]]
        flip = np.cumsum(np.r_[0, np.einsum("ij,ij->i", q[1:], q[:-1]) < 0]) % 2 == 1
        q[flip] *= -1.0
        R = frames.rotation(frames.quat_to_matrix(_interp(tf, ts, q)))
        om = _interp(tf, ts, frames.body_vec(imu.angular_velocity[k]))
        f = _interp(tf, ts, frames.body_vec(imu.linear_acceleration[k]))
        inside = (t_dvl >= t[0] - 1.0) & (t_dvl <= t[-1] + 1.0)
        td, vd = t_dvl[inside], v_dvl[inside]
        v, v_ned_dot = fuse_velocity(tf, R, f, td, vd, gravity, cfg.crossover)
        keep = dvl_inliers(td, vd, tf, v, cfg.outlier_sigma)
        in_core = (td >= t[core.start]) & (td < t[core.stop - 1] + 0.5 / cfg.rate)
        n_outliers += int((~keep & in_core).sum())
        if not keep.all():
            v, v_ned_dot = fuse_velocity(tf, R, f, td[keep], vd[keep], gravity, cfg.crossover)
        # body-frame derivative: v̇ = Rᵀ d/dt(R v) − ω × v
        v_dot = v_ned_dot - np.cross(om, v)
        # the same zero-phase low-pass on everything the regression sees; ν and ν̇ also get
        # the moving average that the window-averaged thrust telemetry already has. The
        # angular derivative is taken on the fine grid, where it is accurate.
        nu = zero_phase(np.concatenate([v, om], axis=1), rate_f, cfg.cutoff, window=window)
        nu_dot = np.concatenate([zero_phase(v_dot, rate_f, cfg.cutoff, window=window),
                                 zero_phase(om, rate_f, cfg.cutoff, derivative=True,
                                            window=window)], axis=1)
        # thruster telemetry is the mean over the message period before its stamp
        tau = zero_phase(_interp(t - cfg.delay, thr.stamp - window / 2, tau_thr), cfg.rate,
                         cfg.cutoff)
        depth = ((_interp(t, pressure.stamp, pressure.fluid_pressure[:, None])[:, 0]
                  - cfg.atmospheric_pressure) / (rho * gravity)) if pressure is not None \
            else np.full(len(t), np.nan)
        return nu[::ratio], nu_dot[::ratio], R[::ratio], tau, depth

    # stretches of `stretch` seconds computed with `margin` seconds on each side (more than
    # the slowest filter's memory, the fusion crossover): memory stays flat with bag length
    # and the result equals processing the whole segment at once
    stretch = max(1, round(cfg.stretch * cfg.rate))
    margin = round(10.0 / cfg.crossover * cfg.rate)
    parts: list[Samples] = []
    for k, (a, b) in enumerate(segments_from_gaps(t_dvl, cfg.max_gap)):
        a, b = max(a, lo), min(b, hi)
        if b - a < cfg.min_segment + 2 * cfg.trim:
            continue
        # output grid: phase-locked to the centres of the thrust telemetry windows
        t = (np.arange(np.ceil(a * cfg.rate - phase), np.floor(b * cfg.rate - phase) + 1)
             + phase) / cfg.rate
        n_trim = round(cfg.trim * cfg.rate)
        for i0 in range(n_trim, len(t) - n_trim, stretch):
            i1 = min(i0 + stretch, len(t) - n_trim)
            e0, e1 = max(0, i0 - margin), min(len(t), i1 + margin)
            core = slice(i0 - e0, i1 - e0)
            nu, nu_dot, R, tau, depth = window_(t[e0:e1], core)
            parts.append(Samples(t[i0:i1], nu[core], nu_dot[core], tau[core],
                                 frames.euler_from_matrix(R[core]), depth[core],
                                 np.full(i1 - i0, k, dtype=np.int64)))
    if report is not None:
        kept = sum(len(p) for p in parts) / cfg.rate
        report.update(rejected_nonfinite_or_unordered=float(sum(int((~m).sum()) for m in masks)),
                      dvl_outliers=float(n_outliers),
                      segments=float(len({int(p.segment[0]) for p in parts})),
                      dropped_seconds=float(max(hi - lo - kept, 0.0)))
    if not parts:
        raise DataError(f"no gap-free stretch of at least {cfg.min_segment + 2 * cfg.trim:.0f} s"
                        " (DVL gaps split the data)")
    joined = Samples.concatenate(parts)
    # stretches of one segment stay one segment: number by the gap-split index k
    joined.segment = np.unique(np.concatenate([p.segment for p in parts]),
                               return_inverse=True)[1].astype(np.int64)
    return joined


def estimate_delay(samples: Samples, M: FloatArray, max_lag: float = 1.0) -> float:
    """Delay (s) of the response after τ, from the cross-correlation of Δτ and M Δν̇.

    Differencing whitens both signals so that the peak is sharp; the lag is refined by a
    parabola through the peak and its neighbours. Positive: the vehicle responds later.
    """
    rate = samples.rate
    n_lag = int(max_lag * rate)
    acc = samples.nu_dot @ M.T
    score = np.zeros(2 * n_lag + 1)
    for sl in samples.segments():
        dt_ = np.diff(samples.tau[sl], axis=0)
        da = np.diff(acc[sl], axis=0)
        n = len(dt_)
        if n <= 2 * n_lag:
            continue
        for i in range(6):
            x, y = dt_[:, i] - dt_[:, i].mean(), da[:, i] - da[:, i].mean()
            c = signal.correlate(y, x, mode="full", method="fft")[n - 1 - n_lag:n + n_lag]
            score += c / (np.linalg.norm(x) * np.linalg.norm(y) + 1e-12)
    k = int(np.argmax(score))
    frac = 0.0
    if 0 < k < len(score) - 1:
        y0, y1, y2 = score[k - 1], score[k], score[k + 1]
        den = y0 - 2 * y1 + y2
        frac = 0.5 * (y0 - y2) / den if den != 0 else 0.0
    return float((k - n_lag + frac) / rate)
