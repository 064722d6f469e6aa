"""Sensor models: turn a ground-truth :class:`Trajectory` into the messages a vehicle logs.

The trajectory is in Fossen's frames (FRD body, NED world) at the integration step; the
output is one :class:`~dampest_ros.core.signals.measurements.Series` per topic of the topic
contract, in ROS frames (FLU body ``base_link``, ENU world ``odom``), at each sensor's own rate:

- ``truth/odom``: OdometrySeries, ``odom`` → ``base_link``; ENU position, FLU→ENU
  attitude, FLU body twist.
- ``imu/data``: ImuSeries, ``imu_link``; AHRS attitude, gyro rate, specific force.
- ``dvl/twist``: TwistSeries, ``dvl_link``; bottom-lock body velocity, with dropouts.
- ``pressure``: PressureSeries, ``pressure_link``; absolute pressure (Pa).
- ``thrusters/state``: JointSeries, ``base_link``; rotor speed (rad/s), logged thrust (N).

By default the sensors sit at the body origin with axes aligned to the body, so their frames
differ from ``base_link`` only by name; a :class:`~dampest_ros.core.physics.mounting.Mounting` (the
vehicle file's ``sensors:`` section) puts them elsewhere: the DVL then measures the velocity
of its own point in its own axes, the IMU the rates and specific force of its point in its
axes and the attitude of its axes, the pressure sensor the depth of its point, and each
message carries the mounting's frame_id. Every FRD/NED → FLU/ENU conversion goes through
:mod:`dampest_ros.core.physics.frames`.

Between integration steps the models interpolate the truth: ν by the cubic Hermite polynomial
through (ν, ν̇) at the two neighbouring steps (its derivative is the IMU's ν̇), the NED
position by the cubic Hermite polynomial through (p, R ν₁) and the attitude by normalised
linear interpolation of quaternions (nlerp). The thruster logs are not interpolated: the
trajectory holds step means over [t_k, t_k + dt], and the message stamped s reports their exact
mean over the window [s − 1/thruster_rate, s] (first stamp t[0] + 1/thruster_rate).

Noise comes from independent random streams, one per noise source, spawned from
``np.random.default_rng(seed)`` in the fixed order of ``NOISE_STREAMS``: changing one sensor's
settings never changes another sensor's noise.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.frames import (
    body_vec,
    continuous,
    matrix_to_quat,
    quat_frd_ned_to_flu_enu,
    quat_mul,
    quat_to_matrix,
    small_rotation,
    world_vec,
    wxyz_to_xyzw,
)
from dampest_ros.core.physics.mounting import (
    DEFAULT_FRAME_IDS,
    Mounting,
    SensorMount,
    depth_offset,
    lever_acceleration,
    lever_velocity,
    rotate,
)
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.signals.measurements import (
    ImuSeries,
    JointSeries,
    OdometrySeries,
    PressureSeries,
    Recording,
    TwistSeries,
    WrenchSeries,
)
from dampest_ros.core.simulation.interpolate import hermite, locate, nlerp
from dampest_ros.core.simulation.trajectory import Trajectory

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Variance (m²/s² or rad²/s²) put on covariance entries a sensor does not measure (the DVL's
#: angular rates). Large rather than −1 so that a consumer that inverts the covariance simply
#: gives those entries no weight.
UNUSED_VARIANCE = 1.0e6

#: Frame ids of the sensor messages (those of the IMU, DVL and pressure sensor: defaults of a
#: :class:`~dampest_ros.core.physics.mounting.Mounting`).
FRAME_IDS: dict[str, str] = {
    "truth/odom": "odom",
    "imu/data": DEFAULT_FRAME_IDS["imu"],
    "dvl/twist": DEFAULT_FRAME_IDS["dvl"],
    "pressure": DEFAULT_FRAME_IDS["pressure"],
    "thrusters/state": "base_link",
    "truth/hydro_wrench": "base_link",
}

#: One random stream per noise source, spawned in this order (append only: reordering would
#: change every seeded recording).
NOISE_STREAMS = (
    "gyro_noise",
    "gyro_walk",
    "accel_noise",
    "accel_walk",
    "orientation",
    "dvl_noise",
    "dvl_dropout",
    "pressure",
    "rpm",
)

# Tolerance, in sample periods, for the last sample to count as lying on the end time.
_GRID_TOL = 1e-6

_RATES = ("imu_rate", "dvl_rate", "pressure_rate", "thruster_rate", "truth_rate")


@dataclass(frozen=True)
class SensorConfig:
    """Rates and noise levels of the simulated sensors (SI units; defaults are realistic).

    Attributes
    ----------
    imu_rate : float
        IMU/AHRS sample rate (Hz), > 0.
    gyro_noise : float
        Gyro white-noise standard deviation per sample (rad/s).
    gyro_bias_walk : float
        Gyro bias random walk (rad/s/√s): the bias changes by N(0, σ² Δt) per sample.
    accel_noise : float
        Accelerometer white-noise standard deviation per sample (m/s²).
    accel_bias_walk : float
        Accelerometer bias random walk (m/s²/√s).
    orientation_noise : float
        AHRS attitude noise, standard deviation of each small-angle component (rad).
    dvl_rate : float
        DVL ping rate (Hz); 5–8 Hz for small DVLs.
    dvl_noise : float
        DVL velocity white-noise standard deviation per axis (m/s).
    dvl_dropout_rate : float
        Rate of bottom-lock losses while locked (1/s, Poisson); 0 disables dropouts.
    dvl_dropout_mean : float
        Mean length of a dropout (s, exponential).
    pressure_rate : float
        Pressure sensor rate (Hz).
    pressure_noise : float
        Pressure white-noise standard deviation (Pa).
    atmospheric_pressure : float
        Pressure at the surface (Pa).
    thruster_rate : float
        Rate of the thruster state log (Hz).
    rpm_noise : float
        White-noise standard deviation of the reported rotor speed (rad/s).
    truth_rate : float
        Rate of the ground-truth odometry (Hz).
    """

    imu_rate: float = 200.0
    gyro_noise: float = 0.002
    gyro_bias_walk: float = 1e-5
    accel_noise: float = 0.02
    accel_bias_walk: float = 1e-4
    orientation_noise: float = 0.002
    dvl_rate: float = 8.0
    dvl_noise: float = 0.005
    dvl_dropout_rate: float = 0.01
    dvl_dropout_mean: float = 2.0
    pressure_rate: float = 20.0
    pressure_noise: float = 20.0
    atmospheric_pressure: float = 101325.0
    thruster_rate: float = 50.0
    rpm_noise: float = 0.2
    truth_rate: float = 50.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ConfigError(f.name, f"must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ConfigError(f.name, f"must be finite, got {value!r}")
            if f.name in _RATES and value <= 0:
                raise ConfigError(f.name, f"must be > 0 Hz, got {value!r}")
            if value < 0:
                raise ConfigError(f.name, f"must be ≥ 0, got {value!r}")
            object.__setattr__(self, f.name, float(value))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SensorConfig:
        """Build from a mapping of the attribute names above (missing keys keep defaults).

        Raises
        ------
        ConfigError
            (a ValueError) naming an unknown key or an invalid value.
        """
        known = {f.name for f in fields(cls)}
        for key in d:
            if key not in known:
                raise ConfigError(str(key), f"unknown sensor setting; known: {sorted(known)}")
        return cls(**dict(d))


@dataclass(frozen=True)
class SensorBias:
    """Constant hidden sensor biases (the 'effects'), in each sensor's FRD axes (the body's
    for an aligned sensor).

    Attributes
    ----------
    gyro : tuple of 3 float
        Gyro bias (rad/s).
    accel : tuple of 3 float
        Accelerometer bias (m/s²).
    dvl : tuple of 3 float
        DVL velocity bias (m/s).
    """

    gyro: tuple[float, float, float] = (0.0, 0.0, 0.0)
    accel: tuple[float, float, float] = (0.0, 0.0, 0.0)
    dvl: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for f in fields(self):
            try:
                v = tuple(float(x) for x in getattr(self, f.name))
            except (TypeError, ValueError):
                raise ConfigError(f.name, "must be 3 numbers") from None
            if len(v) != 3 or not all(math.isfinite(x) for x in v):
                raise ConfigError(f.name, f"must be 3 finite numbers, got {v}")
            object.__setattr__(self, f.name, v)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SensorBias:
        """Build from ``{gyro: [..], accel: [..], dvl: [..]}``; unknown keys raise ConfigError."""
        known = {f.name for f in fields(cls)}
        for key in d:
            if key not in known:
                raise ConfigError(str(key), f"unknown sensor bias; known: {sorted(known)}")
        return cls(**dict(d))


def sample_times(t0: float, t1: float, rate: float) -> FloatArray:
    """Sample stamps t0 + k / rate for k = 0, 1, … up to t1 (included when on the grid).

    Parameters
    ----------
    t0, t1 : float
        First and last time of the record (s), t1 ≥ t0.
    rate : float
        Sample rate (Hz), > 0.

    Returns
    -------
    ndarray, shape (M,)
        M = ⌊(t1 − t0) rate⌋ + 1 stamps (s); a sample within 1e-6 periods of t1 counts.
    """
    n = math.floor((t1 - t0) * rate + _GRID_TOL) + 1
    # t_k = t0 + k / rate (not a cumulative sum, so no drift)
    return t0 + np.arange(max(n, 1), dtype=float) / rate


def measure(
    traj: Trajectory,
    rho: float,
    gravity: float,
    config: SensorConfig = SensorConfig(),
    bias: SensorBias = SensorBias(),
    seed: int = 0,
    mounting: Mounting | None = None,
) -> Recording:
    """Simulate all sensors along a ground-truth trajectory.

    Parameters
    ----------
    traj : Trajectory
        Ground truth at the integration step (FRD body, NED world), N ≥ 1 samples.
    rho : float
        Water density (kg/m³), for the pressure sensor.
    gravity : float
        g (m/s²), for the pressure sensor and the accelerometer.
    config : SensorConfig
        Rates and noise levels.
    bias : SensorBias
        Constant hidden biases (FRD).
    seed : int
        Seed of the noise; the same seed gives identical output.
    mounting : Mounting, optional
        Where the IMU, DVL and pressure sensor sit (default: at the origin, aligned).

    Returns
    -------
    dict of str to Series
        ``truth/odom`` (OdometrySeries), ``imu/data`` (ImuSeries), ``dvl/twist``
        (TwistSeries), ``pressure`` (PressureSeries) and ``thrusters/state`` (JointSeries),
        all in ROS frames, sampled at ``t[0] + k / rate`` up to ``t[-1]``.

    Notes
    -----
    With R the body→NED rotation, ν = [v, ω] and g_n = [0, 0, g] (NED), and for each
    sensor its position r and axes R_bs (the mounting; r = 0, R_bs = I by default):

    - gyro: R_bsᵀ ω + b_g + b_g,walk(t) + white noise;
    - accelerometer (specific force of its point):
      R_bsᵀ (v̇ + ω × v − Rᵀ g_n + ω̇ × r + ω × (ω × r)) + b_a + b_a,walk(t) + white noise,
      i.e. [0, 0, −g] FRD = [0, 0, +g] FLU at rest and level;
    - AHRS attitude of the IMU's axes: (q ⊗ q_bs) ⊗ exp(δθ / 2), δθ ~ N(0, σ² I) a small
      rotation in the sensor frame;
    - DVL (bottom lock): R_bsᵀ (v + ω × r) + b_dvl + white noise, with messages missing
      inside dropouts
      (an alternating renewal process: locked for Exp(1 / dvl_dropout_rate) s, then lost for
      Exp(dvl_dropout_mean) s, starting locked at t[0]; the expected lost fraction is
      λ m / (1 + λ m)); the angular variances are ``UNUSED_VARIANCE``;
    - pressure: p_atm + ρ g z + white noise, z the NED depth of its point, z_o + (R r)_z;
    - thrusters: velocity 2π n + white noise (rad/s, n in rev/s), effort = logged thrust (N),
      both the mean over the window of one message period before the stamp.

    Random-walk biases start at zero at t[0]. Covariances hold the white-noise variances.
    """
    _check_trajectory(traj)
    for name, value in (("rho", rho), ("gravity", gravity)):
        if not math.isfinite(value) or value <= 0:
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    mounting = mounting or Mounting()
    children = np.random.default_rng(seed).spawn(len(NOISE_STREAMS))
    rngs = dict(zip(NOISE_STREAMS, children, strict=True))

    t = np.asarray(traj.t, dtype=float)
    q = continuous(np.asarray(traj.quaternion, dtype=float))
    nu = np.asarray(traj.nu, dtype=float)
    # ṗ = R(q) v: NED velocity of the body origin, the slope of the position interpolant
    p_dot = np.einsum("nij,nj->ni", quat_to_matrix(q), nu[:, :3])
    truth = _Truth(t, np.asarray(traj.position, dtype=float), p_dot, q, nu,
                   np.asarray(traj.nu_dot, dtype=float))
    return {
        "truth/odom": _odometry(truth, config),
        "imu/data": _imu(truth, gravity, config, bias, rngs, mounting.imu),
        "dvl/twist": _dvl(truth, config, bias, rngs, mounting.dvl),
        "pressure": _pressure(truth, rho, gravity, config, rngs, mounting.pressure),
        "thrusters/state": _thrusters(traj, config, rngs),
        **({"truth/hydro_wrench": hydro_series(
            sample_times(float(t[0]), float(t[-1]), config.truth_rate), t, traj.hydro)}
           if traj.hydro is not None else {}),
    }


@dataclass(frozen=True)
class _Truth:
    """The trajectory arrays the sensor models interpolate (FRD/NED, quaternions wxyz)."""

    t: FloatArray
    position: FloatArray
    p_dot: FloatArray
    q: FloatArray
    nu: FloatArray
    nu_dot: FloatArray

    def times(self, rate: float) -> FloatArray:
        return sample_times(float(self.t[0]), float(self.t[-1]), rate)


# --- sensor models -------------------------------------------------------------------------


def _random_walk(rng: np.random.Generator, n: int, sigma: float, rate: float) -> FloatArray:
    """Random-walk bias (n, 3) starting at 0: b_{k+1} = b_k + σ √Δt ξ_k, ξ ~ N(0, I)."""
    steps = rng.standard_normal((n, 3)) * (sigma * math.sqrt(1.0 / rate))
    steps[0] = 0.0
    # b_k = Σ_{j ≤ k} increments
    return np.cumsum(steps, axis=0)


def _white(rng: np.random.Generator, shape: tuple[int, ...], sigma: float) -> FloatArray:
    """Gaussian white noise N(0, σ²) of the given shape (always drawn, so streams stay aligned)."""
    return rng.standard_normal(shape) * sigma


def _imu(truth: _Truth, gravity: float, config: SensorConfig, bias: SensorBias,
         rngs: dict[str, np.random.Generator], mount: SensorMount) -> ImuSeries:
    stamp = truth.times(config.imu_rate)
    n = len(stamp)
    k = locate(truth.t, stamp)
    nu, nu_dot = hermite(k, truth.nu, truth.nu_dot)
    q = nlerp(k, truth.q)
    v, w, v_dot = nu[:, :3], nu[:, 3:], nu_dot[:, :3]
    # Rᵀ [0, 0, g] = g × (third row of R): gravity in the body frame
    g_body = gravity * quat_to_matrix(q)[:, 2, :]
    # f = v̇ + ω × v − Rᵀ [0, 0, g]: specific force at the body origin (FRD)
    specific_force = v_dot + np.cross(w, v) - g_body
    w, specific_force, q = imu_reading(mount, w, nu_dot[:, 3:], specific_force, q)
    gyro = (w + np.asarray(bias.gyro)
            + _random_walk(rngs["gyro_walk"], n, config.gyro_bias_walk, config.imu_rate)
            + _white(rngs["gyro_noise"], (n, 3), config.gyro_noise))
    accel = (specific_force + np.asarray(bias.accel)
             + _random_walk(rngs["accel_walk"], n, config.accel_bias_walk, config.imu_rate)
             + _white(rngs["accel_noise"], (n, 3), config.accel_noise))
    dtheta = _white(rngs["orientation"], (n, 3), config.orientation_noise)
    # q_meas = q_flu_enu ⊗ exp(δθ / 2): perturbation about the sensor (FLU) axes
    q_meas = quat_mul(quat_frd_ned_to_flu_enu(q), small_rotation(dtheta))
    q_meas *= np.where(q_meas[:, :1] < 0.0, -1.0, 1.0)
    return ImuSeries(
        stamp=stamp,
        frame_id=mount.frame_id,
        orientation=wxyz_to_xyzw(q_meas),
        angular_velocity=body_vec(gyro),
        linear_acceleration=body_vec(accel),
        orientation_covariance=diag3(config.orientation_noise**2),
        angular_velocity_covariance=diag3(config.gyro_noise**2),
        linear_acceleration_covariance=diag3(config.accel_noise**2),
    )


def imu_reading(mount: SensorMount, omega: FloatArray, omega_dot: FloatArray, f: FloatArray,
                q: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """What a mounted IMU senses, noise-free, from the body's motion.

    Parameters
    ----------
    mount : SensorMount
    omega, omega_dot : ndarray, shape (n, 3)
        Body rates (rad/s) and their derivative (rad/s²), FRD.
    f : ndarray, shape (n, 3)
        Specific force of the body origin (m/s², FRD).
    q : ndarray, shape (n, 4)
        Attitude quaternions [w, x, y, z], body (FRD) → NED.

    Returns
    -------
    omega_s, f_s : ndarray, shape (n, 3)
        R_bsᵀ ω and R_bsᵀ (f + ω̇ × r + ω × (ω × r)), the IMU's axes (FRD).
    q_s : ndarray, shape (n, 4)
        q ⊗ q_bs: the IMU's axes → NED.
    """
    if not mount.centred:
        # f_p = f + ω̇ × r + ω × (ω × r): the specific force of the IMU's point
        f = f + lever_acceleration(omega, omega_dot, mount.lever)
    if mount.aligned:
        return omega, f, q
    R_sb = mount.rotation.T
    # ω_s = R_bsᵀ ω, f_s = R_bsᵀ f_p; q_ns = q_nb ⊗ q_bs
    return (rotate(R_sb, omega), rotate(R_sb, f),
            quat_mul(q, np.broadcast_to(matrix_to_quat(mount.rotation), q.shape)))


def dvl_reading(mount: SensorMount, nu: FloatArray) -> FloatArray:
    """v_s = R_bsᵀ (v + ω × r), shape (n, 3): the velocity over ground of a mounted DVL's
    point in its axes (m/s, FRD), noise-free, from ν (n, 6) (FRD)."""
    return rotate(mount.rotation.T, nu[:, :3] + lever_velocity(nu[:, 3:], mount.lever))


def sensor_depth(mount: SensorMount, z: FloatArray, q: FloatArray) -> FloatArray:
    """z_s = z + (R r)_z, shape (n,): the NED depth (m) of a mounted pressure sensor from
    the origin's depth z (n,) and the attitude q (n, 4) [w, x, y, z], body → NED."""
    return z + depth_offset(mount, quat_to_matrix(q)) if not mount.centred else z


def diag3(variance: float) -> FloatArray:
    """Row-major 3×3 covariance σ² I, shape (9,)."""
    return (np.eye(3) * variance).ravel()


def _dropout_keep(t0: float, stamp: FloatArray, rate: float, mean: float,
                  rng: np.random.Generator) -> BoolArray:
    """True for stamps outside DVL dropouts (locked/lost alternating renewal process)."""
    keep = np.ones(len(stamp), dtype=bool)
    if rate <= 0.0 or mean <= 0.0 or len(stamp) == 0:
        return keep
    span = float(stamp[-1] - t0)
    edges = np.zeros(0)
    cycles = int(2.0 * span * rate) + 16  # expected cycles ≤ span·rate; draw more per batch
    while edges.size == 0 or edges[-1] <= span:
        locked = rng.exponential(1.0 / rate, cycles)
        lost = rng.exponential(mean, cycles)
        start = edges[-1] if edges.size else 0.0
        # phase ends: locked₁, lost₁, locked₂, … accumulated from t0
        edges = np.concatenate([edges, start + np.cumsum(np.column_stack([locked, lost]).ravel())])
    # even phase index → locked, odd → in a dropout
    phase = np.searchsorted(edges, stamp - t0, side="right")
    return np.asarray(phase % 2 == 0)


def _dvl(truth: _Truth, config: SensorConfig, bias: SensorBias,
         rngs: dict[str, np.random.Generator], mount: SensorMount) -> TwistSeries:
    stamp = truth.times(config.dvl_rate)
    n = len(stamp)
    nu, _ = hermite(locate(truth.t, stamp), truth.nu, truth.nu_dot)
    # v_dvl = v_s + b_dvl + noise
    v = dvl_reading(mount, nu) + np.asarray(bias.dvl) + _white(rngs["dvl_noise"], (n, 3),
                                                                config.dvl_noise)
    keep = _dropout_keep(float(truth.t[0]), stamp, config.dvl_dropout_rate,
                         config.dvl_dropout_mean, rngs["dvl_dropout"])
    cov = np.diag([config.dvl_noise**2] * 3 + [UNUSED_VARIANCE] * 3).ravel()
    return TwistSeries(
        stamp=stamp[keep],
        frame_id=mount.frame_id,
        linear=body_vec(v[keep]),
        angular=np.zeros((int(keep.sum()), 3)),
        covariance=cov,
    )


def _pressure(truth: _Truth, rho: float, gravity: float, config: SensorConfig,
              rngs: dict[str, np.random.Generator], mount: SensorMount) -> PressureSeries:
    stamp = truth.times(config.pressure_rate)
    k = locate(truth.t, stamp)
    position, _ = hermite(k, truth.position, truth.p_dot)
    noise = _white(rngs["pressure"], (len(stamp),), config.pressure_noise)
    # p = p_atm + ρ g z + noise
    pressure = config.atmospheric_pressure + rho * gravity * sensor_depth(
        mount, position[:, 2], nlerp(k, truth.q)) + noise
    return PressureSeries(stamp=stamp, frame_id=mount.frame_id,
                          fluid_pressure=pressure, variance=config.pressure_noise**2)


def _thrusters(traj: Trajectory, config: SensorConfig,
               rngs: dict[str, np.random.Generator]) -> JointSeries:
    t = np.asarray(traj.t, dtype=float)
    # each message reports the mean over the window [s − w, s] before its stamp s, from the
    # running integral of the step means (exact for piecewise-constant step means)
    w = 1.0 / config.thruster_rate
    edges = np.r_[t, t[-1] + traj.dt] if len(t) > 1 else np.r_[t, t + w]
    stamp = sample_times(float(edges[0]) + w, float(edges[-1]), config.thruster_rate)

    def window_mean(x: FloatArray) -> FloatArray:
        if x.shape[1] == 0:
            return np.zeros((len(stamp), 0))
        integral = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x * np.diff(edges)[:, None],
                                                                    axis=0)])
        hi = np.stack([np.interp(stamp, edges, c) for c in integral.T], axis=1)
        lo = np.stack([np.interp(stamp - w, edges, c) for c in integral.T], axis=1)
        return np.asarray((hi - lo) / w, dtype=float)

    speed = window_mean(np.asarray(traj.rotor_speed, dtype=float))
    thrust = window_mean(np.asarray(traj.thrust, dtype=float))
    noise = _white(rngs["rpm"], speed.shape, config.rpm_noise)
    return JointSeries(
        stamp=stamp,
        frame_id=FRAME_IDS["thrusters/state"],
        names=tuple(traj.thruster_names),
        # ω_rotor = 2π n + noise (rev/s → rad/s)
        velocity=2.0 * np.pi * speed + noise,
        effort=thrust,
    )


def _odometry(truth: _Truth, config: SensorConfig) -> OdometrySeries:
    stamp = truth.times(config.truth_rate)
    k = locate(truth.t, stamp)
    position, _ = hermite(k, truth.position, truth.p_dot)
    nu, _ = hermite(k, truth.nu, truth.nu_dot)
    return OdometrySeries(
        stamp=stamp,
        frame_id=FRAME_IDS["truth/odom"],
        child_frame_id="base_link",
        position=world_vec(position),
        orientation=wxyz_to_xyzw(quat_frd_ned_to_flu_enu(nlerp(k, truth.q))),
        linear=body_vec(nu[:, :3]),
        angular=body_vec(nu[:, 3:]),
    )


def hydro_series(stamp: FloatArray, t: FloatArray, hydro: FloatArray) -> WrenchSeries:
    """The plant's hydrodynamic wrench as the truth/hydro_wrench topic (FLU).

    Parameters
    ----------
    stamp : ndarray, shape (M,)
        Message times (s).
    t : ndarray, shape (N,)
        Steps of the trajectory (s).
    hydro : ndarray, shape (N, 6)
        Its wrench per step (FRD, N and N·m), linear between steps.
    """
    w = np.column_stack([np.interp(stamp, t, c) for c in np.asarray(hydro, dtype=float).T])
    return WrenchSeries(stamp=stamp, frame_id=FRAME_IDS["truth/hydro_wrench"],
                        force=body_vec(w[:, :3]), torque=body_vec(w[:, 3:]))


def _check_trajectory(traj: Trajectory) -> None:
    """Raise ValueError unless the trajectory's arrays agree in shape and time increases."""
    t = np.asarray(traj.t, dtype=float)
    if t.ndim != 1 or len(t) == 0:
        raise ValueError(f"trajectory.t must be a non-empty 1-D array, got shape {t.shape}")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise ValueError("trajectory.t must be finite and strictly increasing")
    n = len(t)
    for name, width in (("position", 3), ("quaternion", 4), ("nu", 6), ("nu_dot", 6)):
        a = np.asarray(getattr(traj, name))
        if a.shape != (n, width):
            raise ValueError(f"trajectory.{name} must have shape ({n}, {width}), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"trajectory.{name} contains NaN or Inf")
    if np.any(np.linalg.norm(traj.quaternion, axis=1) < 1e-9):
        raise ValueError("trajectory.quaternion contains a zero quaternion")
    m = len(traj.thruster_names)
    for name in ("rotor_speed", "thrust"):
        a = np.asarray(getattr(traj, name))
        if a.shape != (n, m):
            raise ValueError(f"trajectory.{name} must have shape ({n}, {m}) for "
                             f"{m} thruster names, got {a.shape}")
