"""From sensor topics to synchronised samples of ν, ν̇ and τ (offline, zero-phase).

Pipeline, all vectorised over whole segments:

1. Frames: IMU, DVL and thruster data (or a body-wrench topic) from ROS (FLU/ENU) to
   Fossen (FRD/NED); then each sensor from the vehicle's mounting
   (:mod:`dampest_ros.core.physics.mounting`) to the body origin and axes: the IMU's
   attitude, rates and specific force (its lever-arm terms with ω̇ differentiated from the
   gyro as in step 4), the DVL velocity (lever arm with the gyro at the DVL stamps), the
   pressure depth through the attitude. Messages whose
   frame_id is not the configured one are counted (one note per topic). The attitude may
   come from an Odometry or PoseStamped and the velocity from an Odometry instead
   (:mod:`.sources`: the body's own frame, no mounting); a velocity held between updates is
   kept at its updates only.
2. DVL gaps longer than ``max_gap`` split the data into segments (nothing is invented inside
   a long gap); DVL samples that disagree with the inertially fused velocity are dropped.
3. On a common grid at ``rate`` Hz per segment: attitude, gyro and specific force from the
   IMU, thrust through the allocation matrix into τ, or τ straight from a body-wrench topic
   (geometry_msgs/WrenchStamped, FLU), optionally shifted by a known delay. A wrench message,
   like thruster telemetry, is taken as the mean over its message period before its stamp,
   and τ is the signal with these means (:func:`from_window_means`), not their interpolation.
4. Linear velocity by a zero-phase complementary filter in the non-rotating NED frame: the
   DVL below ``crossover`` Hz and the integrated IMU acceleration R f + g above it
   (Butterworth pairs with |H_lp|² + |H_hp|² = 1, so the fusion is exact where both agree),
   then rotated back to the body. Angular acceleration by differentiating ω. Without an
   accelerometer: the velocity alone (a cubic spline through its samples), ν̇ by
   differentiating it like ω, and no DVL outlier test; without a gyro: ω from the
   zero-phase derivative of the attitude's quaternion.
5. The same light zero-phase low-pass (``cutoff``) on ν, ν̇ and τ, so all three see the
   same filter. Segment ends are trimmed of filter transients.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy import fft as sp_fft
from scipy.interpolate import CubicSpline, make_interp_spline

from dampest_ros.core.physics import frames
from dampest_ros.core.physics.mounting import (
    Mounting,
    SensorMount,
    depth_offset,
    dvl_to_body,
    frame_id_note,
    imu_to_body,
    rotate,
    specific_force_at_origin,
)
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.physics.thrusters import Thrusters
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.measurements import (
    ImuSeries,
    JointSeries,
    PressureSeries,
    Recording,
    Series,
    WrenchSeries,
)
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.signals.sources import (
    ATTITUDE_TYPES,
    VELOCITY_TYPES,
    Sources,
    as_imu,
    held_note,
    held_updates,
    velocity_of,
)

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
        applies its own, stronger, parallel filter (:mod:`dampest_ros.core.identification.batch`).
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


def _need(s: Series, topic: str, kind: type[Series] | tuple[type[Series], ...],
          minimum: int = 10) -> Any:
    """``s`` checked to be a ``kind`` (or one of them) with at least ``minimum`` messages."""
    if not isinstance(s, kind):
        kinds = kind if isinstance(kind, tuple) else (kind,)
        raise DataError(f"topic {topic!r} is {type(s).__name__}, expected "
                        f"{' or '.join(k.__name__ for k in kinds)}")
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
               order: int = 4) -> FloatArray:
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
    order : int

    Returns
    -------
    ndarray, shape like x
    """
    (y,) = zero_phase_many(x, rate, cutoff, (derivative,), order)
    return y


def zero_phase_many(x: FloatArray, rate: float, cutoff: float, derivatives: tuple[bool, ...],
                    order: int = 4) -> list[FloatArray]:
    """:func:`zero_phase` of x once per entry of ``derivatives`` (False: the filtered signal,
    True: its derivative) from one forward transform of x; each equals what
    :func:`zero_phase` gives.

    Parameters
    ----------
    x : ndarray, shape (N, ...)
    rate, cutoff, order
        As :func:`zero_phase`.
    derivatives : tuple of bool

    Returns
    -------
    list of ndarray, shape like x
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
    H = 1.0 / (1.0 + (f / cutoff) ** (2 * order))
    shape = (len(f),) + (1,) * (x.ndim - 1)
    X = sp_fft.rfft(ext, axis=0)
    out = []
    for k, derivative in enumerate(derivatives):
        # times i2πf for the derivative (in place, on a copy of X but for the last)
        Hd = H * (2j * np.pi * f) if derivative else H
        Y = X if k == len(derivatives) - 1 else X.copy()
        Y *= Hd.reshape(shape)
        y = sp_fft.irfft(Y, n=size, axis=0, overwrite_x=True)
        out.append(np.asarray(y[:n], dtype=float))
    return out


def _interp(t: FloatArray, tp: FloatArray, x: FloatArray) -> FloatArray:
    """Linear interpolation of every column of x (N, k) at t."""
    x2 = x.reshape(len(tp), -1)
    out = np.empty((len(t), x2.shape[1]))
    for j in range(x2.shape[1]):
        out[:, j] = np.interp(t, tp, x2[:, j])
    return out.reshape((len(t), *x.shape[1:]))


def from_window_means(t: FloatArray, stamps: FloatArray, means: FloatArray,
                      average: float = 0.0) -> FloatArray:
    """The signal at ``t`` whose mean over each message period (s_{k−1}, s_k] is the message
    (histopolation): the derivative of the quintic spline through its running integral
    F(s_k) = Σ_{j≤k} (s_j − s_{j−1}) x̄_j.

    Window-averaged telemetry (thrust: the mean over the message period before its stamp)
    interpolated linearly between window centres is low-passed twice, by the window and by
    the interpolation: a sinusoid keeps 97.3 % at 0.75 Hz, 89.4 % at 1.5 Hz, 73.0 % at 2.5 Hz
    of 10 Hz telemetry. Where ν does not see the same loss, a lightly damped mode's damping
    comes out low by it (K_p of a 0.75 Hz roll mode 5 % low, 30 σ), and giving ν the same
    filter cannot help the terms nonlinear in ν. This reconstruction keeps 100.0 %, 99.996 %
    and 99.86 % there, with no phase shift.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Times (s) to evaluate at.
    stamps : ndarray, shape (M,)
        Message stamps (s), increasing; the first message only starts the integral.
    means : ndarray, shape (M, k)
        Each message's mean over the period since the previous stamp.
    average : float, optional
        If > 0 (s), the signal's mean over [t − average/2, t + average/2] instead of its value
        at t (the spline's difference over the window): the boxcar that the other signals of
        a sample get. Over a message period it is that message.

    Returns
    -------
    ndarray, shape (n, k)
    """
    steps = np.diff(stamps).reshape((-1,) + (1,) * (means.ndim - 1))
    integral = np.concatenate([np.zeros((1, *means.shape[1:])),
                               np.cumsum(steps * means[1:], axis=0)])
    # quintic (fewer messages: the highest degree they allow)
    spline = make_interp_spline(stamps, integral, k=min(5, len(stamps) - 1), axis=0)
    if average > 0:
        return np.asarray((spline(t + average / 2) - spline(t - average / 2)) / average,
                          dtype=float)
    return np.asarray(spline(t, 1), dtype=float)


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
    # ∫ by the trapezoid rule from 0 (scipy.integrate.cumulative_trapezoid's arithmetic; that
    # module imports scipy.optimize, ~0.5 s)
    v_imu_ned = np.concatenate([np.zeros((1, 3)),
                                np.cumsum(1.0 / rate * (a_ned[1:] + a_ned[:-1]) / 2.0, axis=0)])
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


def body_wrench(series: JointSeries | WrenchSeries, thrusters: Thrusters | None) -> FloatArray:
    """τ (N, 6) FRD of a τ topic: thruster telemetry through the allocation matrix
    (:func:`thruster_wrench`), or a body wrench (WrenchStamped, FLU) converted to FRD.

    Raises
    ------
    DataError
        Thruster telemetry without the vehicle's thrusters.
    """
    if isinstance(series, WrenchSeries):
        return frames.body_twist(np.concatenate([series.force, series.torque], axis=1))
    return thruster_wrench(series, _need_thrusters(thrusters))


def _need_thrusters(thrusters: Thrusters | None) -> Thrusters:
    """``thrusters``, or DataError if the vehicle has none."""
    if thrusters is None:
        raise DataError("τ from thruster telemetry needs the vehicle's thrusters; the vehicle "
                        "has none (give a body-wrench topic, role 'wrench', instead)")
    return thrusters


def _tau_columns(series: JointSeries | WrenchSeries) -> tuple[FloatArray, ...]:
    """The value arrays of a τ topic that must be finite."""
    if isinstance(series, WrenchSeries):
        return series.force, series.torque
    return (series.effort,)


class SeriesSource(Protocol):
    """Where :func:`preprocess` gets its data: whole topics or time windows of them.

    A Recording in memory is wrapped in :class:`MemorySource`; ``dampest_ros.io.bag`` offers
    a source that reads windows straight from a bag, so a long log is never held whole.
    """

    def topics(self) -> list[str]:
        """Topic names available."""
        ...

    def series(self, topic: str, start: float | None = None,
               stop: float | None = None) -> Series:
        """Messages of ``topic`` stamped in [start, stop) (s); the whole topic by default."""
        ...


class MemorySource:
    """A :class:`SeriesSource` over a Recording already in memory."""

    def __init__(self, rec: Recording) -> None:
        self.rec = rec

    def topics(self) -> list[str]:
        """Topic names available."""
        return list(self.rec)

    def series(self, topic: str, start: float | None = None,
               stop: float | None = None) -> Series:
        """Messages of ``topic`` stamped in [start, stop) (s); the whole topic by default."""
        s = self.rec[topic]
        if start is None and stop is None:
            return s
        lo, hi = np.searchsorted(s.stamp, [-np.inf if start is None else start,
                                           np.inf if stop is None else stop])
        return s.select(np.arange(int(lo), int(hi)))


def preprocess(rec: Recording | SeriesSource, vehicle: Vehicle,
               config: PreprocessConfig | None = None, topics: dict[str, str] | None = None,
               *, report: dict[str, float] | None = None,
               notes: list[str] | None = None,
               substitutions: list[str] | None = None) -> Samples:
    """Synchronise and filter sensor topics into samples of ν, ν̇, τ.

    Parameters
    ----------
    rec : Recording or SeriesSource
        Topic → series, ROS frames (as read from a bag), or a source that reads windows.
    vehicle : Vehicle
        Gives the thrusters (allocation; names must match the JointState names; may be None
        with a ``wrench`` topic), g (m/s²) and the water density (kg/m³) of its body, and the
        mounting of its IMU, DVL and pressure sensor.
    config : PreprocessConfig, optional
    topics : dict, optional
        Role → topic name for ``imu``, ``dvl``, ``pressure``, ``thrusters`` and, optionally,
        ``wrench``: a body-wrench topic (WrenchStamped, FLU) that gives τ instead of the
        thruster telemetry (then the thrusters are not read). The ``imu`` topic may instead
        be an Odometry or PoseStamped (attitude), the ``dvl`` topic an Odometry (velocity),
        see :mod:`.sources`.
    report : dict, optional
        Filled with counts: ``rejected_nonfinite_or_unordered``, ``dvl_outliers``,
        ``segments``, ``dropped_seconds`` (data in gaps and too-short segments) and, per
        sensor topic with messages of another frame_id than the mounting's,
        ``frame_id_mismatch <topic>``.
    notes : list of str, optional
        Appended: one line per sensor topic whose messages carry another frame_id than the
        mounting gives, for the user, with their count: all of the DVL and pressure topics,
        the IMU's within the processed stretches (it is read a window at a time).
    substitutions : list of str, optional
        Appended: one line per signal the topics lack and what replaces it (no
        accelerometer, no gyro, a velocity held between updates; :mod:`.sources`).

    Returns
    -------
    Samples
        FRD/NED, uniformly sampled segments.
    """
    cfg = config or PreprocessConfig()
    src: SeriesSource = MemorySource(rec) if isinstance(rec, dict) else rec
    names = _resolve_topics(src, topics, vehicle.thrusters)
    tally = _Tally()
    velocity: Series = _need(src.series(names.dvl), names.dvl, VELOCITY_TYPES)
    sources = _sources(src, names, velocity)
    mounting = sources.mounting(vehicle.mounting)
    subs = sources.notes(names.imu, names.dvl)
    t_dvl, v_dvl, pressure = _read_dvl_and_pressure(src, velocity, names, mounting, tally, subs)
    window, phase, first = _telemetry_timing(src, names, t_dvl, cfg.rate)
    lo, hi = max(t_dvl[0], first), _covered_until(src, names, t_dvl[-1])
    if hi - lo < cfg.min_segment + 2 * cfg.trim:
        raise DataError(f"the topics overlap for only {max(hi - lo, 0.0):.1f} s")
    inputs = _Inputs(src, names, vehicle, cfg, t_dvl, v_dvl, pressure, window,
                     max(1, round(cfg.inertial_rate / cfg.rate)), sources, mounting)
    out, n_segments = _assemble(inputs, _output_grids(t_dvl, lo, hi, phase, cfg), tally)
    _tell(tally, names, mounting, n_segments,
          max(hi - lo - len(out) / cfg.rate, 0.0), report, notes)
    if substitutions is not None:
        substitutions.extend(subs)
    if len(out) == 0:
        raise DataError(f"no gap-free stretch of at least {cfg.min_segment + 2 * cfg.trim:.0f} s"
                        " (DVL gaps split the data)")
    return out


@dataclass(frozen=True)
class _Topics:
    """The topics :func:`preprocess` reads, by role, and where τ comes from."""

    imu: str
    dvl: str
    pressure: str
    has_pressure: bool
    #: the τ topic: a body-wrench topic (WrenchSeries), else thruster telemetry (JointSeries)
    tau: str
    tau_kind: type[Series]

    def frame_ids(self, mount: Mounting) -> dict[str, str]:
        """Sensor topic → the frame_id its messages should carry."""
        return {self.imu: mount.imu.frame_id, self.dvl: mount.dvl.frame_id,
                self.pressure: mount.pressure.frame_id}


def _resolve_topics(src: SeriesSource, topics: dict[str, str] | None,
                    thrusters: Thrusters | None) -> _Topics:
    """The topic of every role (defaults overridden by ``topics``), checked to be in ``src``.

    Raises
    ------
    DataError
        τ from thruster telemetry without thrusters, or the IMU, DVL or τ topic missing.
    """
    # relative names, as sources list them: "/nav/odom" is the bag's "nav/odom"
    names = {role: topic.lstrip("/") for role, topic in
             {"imu": "imu/data", "dvl": "dvl/twist", "pressure": "pressure",
              "thrusters": "thrusters/state", **(topics or {})}.items()}
    tau = names.get("wrench") or names["thrusters"]
    tau_kind: type[Series] = WrenchSeries if names.get("wrench") else JointSeries
    if tau_kind is JointSeries:
        _need_thrusters(thrusters)
    have = src.topics()
    for topic in (names["imu"], names["dvl"], tau):
        if topic not in have:
            raise DataError(f"topic {topic!r} missing; the data has {sorted(have)}")
    return _Topics(names["imu"], names["dvl"], names["pressure"], names["pressure"] in have,
                   tau, tau_kind)


@dataclass
class _Tally:
    """What :func:`preprocess` counts on the way, for its report and notes."""

    #: messages with non-finite values or stamps out of order (dropped)
    rejected: int = 0
    #: DVL samples that disagree with the inertial velocity (dropped)
    outliers: int = 0
    #: messages per (topic, frame_id) whose frame_id is not the configured one
    foreign: dict[tuple[str, str], int] = field(default_factory=dict)

    def frame_id(self, topic: str, series: Series, mount: SensorMount, count: int) -> None:
        """Count ``count`` messages of ``topic`` if the vehicle file declares another
        frame_id for its sensor (:meth:`SensorMount.foreign`)."""
        if count and mount.foreign(series.frame_id):
            key = (topic, series.frame_id)
            self.foreign[key] = self.foreign.get(key, 0) + count


#: Seconds of the attitude topic, from the first velocity message on, whose gyro and
#: accelerometer fields say whether the topic has them (:meth:`Sources.of`).
SOURCE_HEAD = 30.0


def _sources(src: SeriesSource, names: _Topics, velocity: Series) -> Sources:
    """What the attitude topic (role ``imu``, its first :data:`SOURCE_HEAD` seconds from the
    first velocity message) and the velocity topic carry."""
    head: Series = _need(src.series(names.imu, None, float(velocity.stamp[0]) + SOURCE_HEAD),
                         names.imu, ATTITUDE_TYPES, minimum=2)
    return Sources.of(as_imu(head), type(head), type(velocity))


def _read_dvl_and_pressure(src: SeriesSource, dvl: Series, names: _Topics, mount: Mounting,
                           tally: _Tally, subs: list[str]
                           ) -> tuple[FloatArray, FloatArray, PressureSeries | None]:
    """The small topics, read whole (the large ones, IMU and τ, are read per stretch).

    Drops DVL messages that are non-finite or out of order and counts them; counts foreign
    frame_ids of the DVL and pressure topics. A velocity held between updates
    (:func:`~.sources.held_updates`) is kept at its updates only, and said in ``subs``.

    Parameters
    ----------
    dvl : TwistSeries or OdometrySeries
        The velocity topic's messages.
    subs : list of str
        Appended: the held-velocity line.

    Returns
    -------
    t_dvl : ndarray, shape (M,)
        DVL stamps (s), strictly increasing.
    v_dvl : ndarray, shape (M, 3)
        DVL velocity in the DVL's own axes (FRD, m/s); moved to the body origin per stretch,
        with the gyro.
    pressure : PressureSeries or None
        None without a pressure topic or with fewer than two messages.
    """
    pres = src.series(names.pressure) if names.has_pressure else None
    dvl_ok = _clean(dvl, velocity_of(dvl))
    tally.rejected += int((~dvl_ok).sum())
    dvl = dvl if dvl_ok.all() else dvl.select(dvl_ok)
    tally.frame_id(names.dvl, dvl, mount.dvl, len(dvl))
    updates = held_updates(velocity_of(dvl))
    if updates is not None:
        subs.append(held_note(names.dvl, int(updates.sum()), len(dvl),
                              float(dvl.stamp[-1] - dvl.stamp[0])))
        dvl = dvl.select(updates)
    if pres is not None:
        tally.frame_id(names.pressure, pres, mount.pressure, len(pres))
    pressure = pres if isinstance(pres, PressureSeries) and len(pres) > 1 else None
    return dvl.stamp, frames.body_vec(velocity_of(dvl)), pressure


def _telemetry_timing(src: SeriesSource, names: _Topics, t_dvl: FloatArray, rate: float
                      ) -> tuple[float, float, float]:
    """Message period, output-grid phase and first stamp of the τ topic, from its messages
    up to 10 s after the first DVL stamp.

    Parameters
    ----------
    t_dvl : ndarray, shape (M,)
        DVL stamps (s).
    rate : float
        Output sample rate (Hz).

    Returns
    -------
    window : float
        Median message period (s): the window each τ message is the mean over.
    phase : float
        Fraction of an output step, in [0, 1), that puts the grid on the window centres.
    first : float
        Stamp of the first τ message (s).
    """
    head = _need(src.series(names.tau, None, t_dvl[0] + 10.0), names.tau, names.tau_kind,
                 minimum=2)
    window = float(np.median(np.diff(head.stamp)))
    phase = float(((head.stamp[0] - window / 2) * rate) % 1.0)
    return window, phase, head.stamp[0]


def _covered_until(src: SeriesSource, names: _Topics, end: float) -> float:
    """The last time (s) up to ``end`` that the IMU and τ messages both reach: a DVL message
    stamped after the last IMU or τ message (jittered stamps) would otherwise end the grid
    where no stretch can be computed, and the stretch holding it would be left out whole."""
    pad = 2.0
    for topic in (names.imu, names.tau):
        stamps = src.series(topic, end - pad, end + pad).stamp
        if len(stamps):
            end = min(end, float(stamps.max()))
    return end


def _output_grids(t_dvl: FloatArray, lo: float, hi: float, phase: float,
                  cfg: PreprocessConfig) -> list[tuple[int, FloatArray]]:
    """Output time grids of the segments that DVL gaps leave, within [lo, hi].

    Segments shorter than ``min_segment + 2 trim`` are left out.

    Returns
    -------
    list of (k, t)
        Index of the segment among all gap-split ones, and its grid (s), shape (n,), at
        ``cfg.rate`` phase-locked to the centres of the thrust telemetry windows.
    """
    grids: list[tuple[int, FloatArray]] = []
    for k, (a, b) in enumerate(segments_from_gaps(t_dvl, cfg.max_gap)):
        a, b = max(a, lo), min(b, hi)
        if b - a >= cfg.min_segment + 2 * cfg.trim:
            grids.append((k, (np.arange(np.ceil(a * cfg.rate - phase),
                                        np.floor(b * cfg.rate - phase) + 1) + phase) / cfg.rate))
    return grids


@dataclass(frozen=True)
class _Inputs:
    """What every stretch of :func:`preprocess` reads."""

    src: SeriesSource
    names: _Topics
    vehicle: Vehicle
    cfg: PreprocessConfig
    #: DVL stamps (M,) (s) and velocities (M, 3) in the DVL's axes (FRD, m/s)
    t_dvl: FloatArray
    v_dvl: FloatArray
    pressure: PressureSeries | None
    #: τ telemetry message period (s)
    window: float
    #: inertial grid steps per output step
    ratio: int
    #: what the attitude and velocity topics carry
    sources: Sources
    #: the vehicle's mounting, the body's own frame for an Odometry or PoseStamped source
    mounting: Mounting


def _assemble(inputs: _Inputs, grids: list[tuple[int, FloatArray]], tally: _Tally
              ) -> tuple[Samples, int]:
    """Samples of all segments, computed a stretch at a time, trimmed at the segment ends.

    Stretches of ``stretch`` seconds are computed with ``margin`` seconds on each side (more
    than the slowest filter's memory, the fusion crossover): memory stays flat with bag
    length and the result equals processing the whole segment at once. Stretches without
    IMU or τ data are left out.

    Returns
    -------
    samples : Samples
    n_segments : int
        Segments with samples (the stretches of one segment stay one segment).
    """
    cfg = inputs.cfg
    stretch = max(1, round(cfg.stretch * cfg.rate))
    margin = round(10.0 / cfg.crossover * cfg.rate)
    n_trim = round(cfg.trim * cfg.rate)
    # the output is written in place (no list of parts joined at the end: half the memory)
    size = sum(max(len(t) - 2 * n_trim, 0) for _, t in grids)
    out = Samples(np.empty(size), np.empty((size, 6)), np.empty((size, 6)),
                  np.empty((size, 6)), np.empty((size, 3)), np.empty(size),
                  np.empty(size, dtype=np.int64))
    n = 0
    kept_segments: list[int] = []
    for k, t in grids:
        for i0 in range(n_trim, len(t) - n_trim, stretch):
            i1 = min(i0 + stretch, len(t) - n_trim)
            e0, e1 = max(0, i0 - margin), min(len(t), i1 + margin)
            core = slice(i0 - e0, i1 - e0)
            result = _stretch(inputs, t[e0:e1], core, tally)
            if result is None:
                continue
            nu, nu_dot, R, tau, depth = result
            m = slice(n, n + i1 - i0)
            out.t[m], out.nu[m], out.nu_dot[m], out.tau[m] = t[i0:i1], nu[core], nu_dot[core], \
                tau[core]
            out.euler[m], out.depth[m] = frames.euler_from_matrix(R[core]), depth[core]
            if not kept_segments or kept_segments[-1] != k:
                kept_segments.append(k)
            out.segment[m] = len(kept_segments) - 1
            n += i1 - i0
    return (out.take(slice(0, n)) if n < size else out), len(kept_segments)


def _stretch(inputs: _Inputs, t: FloatArray, core: slice, tally: _Tally
             ) -> tuple[FloatArray, ...] | None:
    """ν, ν̇, R, τ and depth on one stretch of a segment's output grid, with its margins.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Output grid (s) of the stretch and its margins.
    core : slice
        The stretch within ``t``, without the margins: rejections are counted there.

    Returns
    -------
    nu, nu_dot, tau : ndarray, shape (n, 6)
        Body velocity (m/s, rad/s), its derivative (m/s², rad/s²), τ (N, N·m); FRD.
    R : ndarray, shape (n, 3, 3)
        Body (FRD) → NED.
    depth : ndarray, shape (n,)
        Depth of the body origin (m); NaN without pressure data.
    None
        Where the IMU or τ data do not cover ``t``.
    """
    cfg, mount, ratio, has = inputs.cfg, inputs.mounting, inputs.ratio, inputs.sources
    t_core = (t[core.start], t[core.stop - 1])
    read = _read_stretch(inputs, t, t_core, tally)
    if read is None:
        return None
    imu, thr = read
    rate_f = cfg.rate * ratio
    tf = t[0] + np.arange((len(t) - 1) * ratio + 1) / rate_f
    R, om, f = _imu_at_origin(imu, mount.imu, tf, rate_f, cfg.cutoff, has.gyro)
    rates = (imu.stamp, rotate(mount.imu.rotation, frames.body_vec(imu.angular_velocity))) \
        if has.gyro else (tf, om)
    td, vd = _dvl_at_origin(rates, mount, inputs.t_dvl, inputs.v_dvl, t)
    v_dot: FloatArray | None = None
    if has.accel:
        v, v_dot, outliers = _fuse_without_outliers(tf, R, f, om, td, vd,
                                                    inputs.vehicle.body.gravity, cfg, t_core)
        tally.outliers += outliers
    else:  # no accelerometer: the velocity alone, differentiated with ω in _filtered_motion
        v = CubicSpline(td, vd, axis=0)(tf)
    nu, nu_dot = _filtered_motion(v, v_dot, om, rate_f, cfg.cutoff)
    # τ telemetry is the mean over the message period before its stamp: τ itself, at t
    tau = zero_phase(from_window_means(t - cfg.delay, thr.stamp,
                                       body_wrench(thr, inputs.vehicle.thrusters)),
                     cfg.rate, cfg.cutoff)
    depth = _depth(inputs.pressure, mount.pressure, t, R[::ratio], cfg.atmospheric_pressure,
                   inputs.vehicle.body.rho, inputs.vehicle.body.gravity)
    return nu[::ratio], nu_dot[::ratio], R[::ratio], tau, depth


def _read_stretch(inputs: _Inputs, t: FloatArray, t_core: tuple[float, float], tally: _Tally
                  ) -> tuple[ImuSeries, JointSeries | WrenchSeries] | None:
    """The IMU and τ messages around a stretch's grid, without non-finite or unordered ones.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Output grid (s) of the stretch and its margins; read with 1 s more on each side.
    t_core : (float, float)
        First and last time (s) of the stretch without its margins: the messages dropped
        there and the IMU's messages of a foreign frame_id are counted.

    Returns
    -------
    imu : ImuSeries
    tau : JointSeries or WrenchSeries
        The τ topic's messages.
    None
        Where either does not cover ``t`` (τ messages: their windows).
    """
    pad = 1.0
    names = inputs.names
    imu = as_imu(_need(inputs.src.series(names.imu, t[0] - pad, t[-1] + pad), names.imu,
                       ATTITUDE_TYPES, minimum=0))
    thr: JointSeries | WrenchSeries = _need(inputs.src.series(names.tau, t[0] - pad,
                                                              t[-1] + pad),
                                            names.tau, names.tau_kind, minimum=0)
    imu_ok = _clean(imu, imu.orientation, imu.angular_velocity, imu.linear_acceleration)
    thr_ok = _clean(thr, *_tau_columns(thr))
    imu_core, thr_core = ((s.stamp >= t_core[0]) & (s.stamp <= t_core[1]) for s in (imu, thr))
    tally.rejected += int((~imu_ok & imu_core).sum()) + int((~thr_ok & thr_core).sum())
    tally.frame_id(names.imu, imu, inputs.mounting.imu, int(imu_core.sum()))
    imu = imu if imu_ok.all() else imu.select(imu_ok)  # type: ignore[assignment]
    thr = thr if thr_ok.all() else thr.select(thr_ok)  # type: ignore[assignment]
    if len(imu) < 2 or len(thr) < 2 or imu.stamp[0] > t[0] or imu.stamp[-1] < t[-1] \
            or thr.stamp[0] - inputs.window > t[0] or thr.stamp[-1] < t[-1]:
        return None
    return imu, thr


def _imu_at_origin(imu: ImuSeries, mount: SensorMount, tf: FloatArray, rate: float,
                   cutoff: float, gyro: bool = True
                   ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Attitude, angular velocity and specific force at the body origin on the grid ``tf``.

    Parameters
    ----------
    imu : ImuSeries
        ROS frames, covering ``tf``.
    mount : SensorMount
        The IMU's.
    tf : ndarray, shape (N,)
        Uniform inertial grid (s).
    rate : float
        Its rate (Hz).
    cutoff : float
        Low-pass (Hz) of the ω̇ in the lever-arm terms, as ν̇ gets, and of the attitude's
        derivative without a gyro.
    gyro : bool
        Whether the IMU has a gyro; without one, ω is the body rate of the attitude
        (:func:`_attitude_rates`).

    Returns
    -------
    R : ndarray, shape (N, 3, 3)
        Body (FRD) → NED.
    omega : ndarray, shape (N, 3)
        Body angular velocity (FRD, rad/s).
    f : ndarray, shape (N, 3)
        Specific force at the body origin (FRD, m/s²).
    """
    ts = imu.stamp
    # attitude: normalised linear interpolation of sign-aligned quaternions
    q = frames.continuous(imu.orientation[:, [3, 0, 1, 2]])
    R, om, f = imu_to_body(mount, frames.rotation(frames.quat_to_matrix(_interp(tf, ts, q))),
                           _interp(tf, ts, frames.body_vec(imu.angular_velocity)),
                           _interp(tf, ts, frames.body_vec(imu.linear_acceleration)))
    if not gyro:
        om = _attitude_rates(R, rate, cutoff)
    if not mount.centred:
        # the IMU's lever arm, with ω̇ differentiated from the gyro like ν̇
        f = specific_force_at_origin(mount, f, om, zero_phase(om, rate, cutoff,
                                                              derivative=True))
    return R, om, f


def _attitude_rates(R: FloatArray, rate: float, cutoff: float) -> FloatArray:
    """Body angular velocity from the attitude alone (no gyro), by the zero-phase derivative
    of its quaternion (:func:`zero_phase`, as every derivative here).

    Parameters
    ----------
    R : ndarray, shape (N, 3, 3)
        Body (FRD) → NED on a uniform grid.
    rate, cutoff : float
        The grid's rate and the low-pass of the derivative (Hz).

    Returns
    -------
    ndarray, shape (N, 3)
        ω (FRD, rad/s).
    """
    q = frames.continuous(frames.matrix_to_quat(R))
    # ω = 2 vec(q* ⊗ q̇), q̇ differentiated zero-phase
    return frames.body_rates(q, zero_phase(q, rate, cutoff, derivative=True))


def _dvl_at_origin(rates: tuple[FloatArray, FloatArray], mount: Mounting, t_dvl: FloatArray,
                   v_dvl: FloatArray, t: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The DVL samples within 1 s of the grid ``t`` (s), moved to the body origin and axes:
    v = R_bs v_s − ω × r, with the body rates at the DVL stamps.

    Parameters
    ----------
    rates : (ndarray, ndarray), shapes (K,), (K, 3)
        Stamps (s) and body angular velocities (FRD, rad/s) to interpolate: the gyro's,
        or the attitude's on the inertial grid without one.
    t_dvl, v_dvl : ndarray, shapes (M,), (M, 3)
        DVL stamps (s) and velocities in the DVL's axes (FRD, m/s).

    Returns
    -------
    td, vd : ndarray, shapes (K,), (K, 3)
        Stamps (s) and body velocities over ground at the origin (FRD, m/s).
    """
    inside = (t_dvl >= t[0] - 1.0) & (t_dvl <= t[-1] + 1.0)
    td = t_dvl[inside]
    omega = np.zeros((len(td), 3)) if mount.dvl.centred else _interp(td, *rates)
    return td, dvl_to_body(mount.dvl, v_dvl[inside], omega)


def _fuse_without_outliers(tf: FloatArray, R: FloatArray, f: FloatArray, omega: FloatArray,
                           td: FloatArray, vd: FloatArray, gravity: float,
                           cfg: PreprocessConfig, t_core: tuple[float, float]
                           ) -> tuple[FloatArray, FloatArray, int]:
    """:func:`fuse_velocity`, again without the DVL samples that :func:`dvl_inliers`
    rejects, and the body-frame derivative of the velocity.

    Parameters
    ----------
    tf, R, f : ndarray, shapes (N,), (N, 3, 3), (N, 3)
        As :func:`fuse_velocity`.
    omega : ndarray, shape (N, 3)
        Body angular velocity (FRD, rad/s).
    td, vd : ndarray, shapes (K,), (K, 3)
        DVL stamps (s) and body velocities (FRD, m/s).
    gravity : float
        m/s².
    t_core : (float, float)
        Span (s) in which rejected DVL samples are counted.

    Returns
    -------
    v, v_dot : ndarray, shape (N, 3)
        Body velocity over ground (m/s) and its body-frame derivative (m/s²).
    outliers : int
        DVL samples rejected within ``t_core``.
    """
    v, v_ned_dot = fuse_velocity(tf, R, f, td, vd, gravity, cfg.crossover)
    keep = dvl_inliers(td, vd, tf, v, cfg.outlier_sigma)
    in_core = (td >= t_core[0]) & (td < t_core[1] + 0.5 / cfg.rate)
    if not keep.all():
        v, v_ned_dot = fuse_velocity(tf, R, f, td[keep], vd[keep], gravity, cfg.crossover)
    # body-frame derivative: v̇ = Rᵀ d/dt(R v) − ω × v
    return v, v_ned_dot - np.cross(omega, v), int((~keep & in_core).sum())


def _filtered_motion(v: FloatArray, v_dot: FloatArray | None, omega: FloatArray, rate: float,
                     cutoff: float) -> tuple[FloatArray, FloatArray]:
    """ν and ν̇ through the light zero-phase low-pass that τ also gets; ω̇ (and v̇ when not
    given: no accelerometer) by differentiating on this (fine) grid, where it is accurate.

    Parameters
    ----------
    v, omega : ndarray, shape (N, 3)
        Body velocity (m/s) and angular velocity (rad/s); FRD.
    v_dot : ndarray, shape (N, 3), or None
        Body-frame derivative of v (m/s²); None: differentiate v.
    rate : float
        Their sample rate (Hz).
    cutoff : float
        Hz.

    Returns
    -------
    nu, nu_dot : ndarray, shape (N, 6)
    """
    if v_dot is None:
        nu, nu_dot = zero_phase_many(np.concatenate([v, omega], axis=1), rate, cutoff,
                                     (False, True))
        return nu, nu_dot
    nu = zero_phase(np.concatenate([v, omega], axis=1), rate, cutoff)
    nu_dot = np.concatenate([zero_phase(v_dot, rate, cutoff),
                             zero_phase(omega, rate, cutoff, derivative=True)],
                            axis=1)
    return nu, nu_dot


def _depth(pressure: PressureSeries | None, mount: SensorMount, t: FloatArray, R: FloatArray,
           atmospheric: float, rho: float, gravity: float) -> FloatArray:
    """Depth of the body origin on the grid ``t`` (s), from absolute pressure.

    Parameters
    ----------
    pressure : PressureSeries or None
        Pa; None gives NaN.
    mount : SensorMount
        The pressure sensor's.
    R : ndarray, shape (n, 3, 3)
        Body (FRD) → NED on ``t``.
    atmospheric, rho, gravity : float
        Pa, kg/m³, m/s².

    Returns
    -------
    ndarray, shape (n,)
        m.
    """
    if pressure is None:
        return np.full(len(t), np.nan)
    depth = (_interp(t, pressure.stamp, pressure.fluid_pressure[:, None])[:, 0]
             - atmospheric) / (rho * gravity)
    if not mount.centred:
        # z_o = z_s − (R r_p)_z: the origin's depth from the sensor's
        depth = depth - depth_offset(mount, R)
    return depth


def _tell(tally: _Tally, names: _Topics, mount: Mounting, n_segments: int, dropped: float,
          report: dict[str, float] | None, notes: list[str] | None) -> None:
    """Fill ``report`` with the counts and append to ``notes`` one line per topic and foreign
    frame_id (each if given).

    Parameters
    ----------
    n_segments : int
        Segments in the output.
    dropped : float
        Seconds of the topics' overlap not in the output (s).
    """
    for (topic, found), count in sorted(tally.foreign.items()):
        expected = names.frame_ids(mount)[topic]
        if notes is not None:
            notes.append(frame_id_note(topic, count, found, expected))
        if report is not None:
            report[f"frame_id_mismatch {topic}"] = report.get(
                f"frame_id_mismatch {topic}", 0.0) + count
    if report is not None:
        report.update(rejected_nonfinite_or_unordered=float(tally.rejected),
                      dvl_outliers=float(tally.outliers), segments=float(n_segments),
                      dropped_seconds=float(dropped))
