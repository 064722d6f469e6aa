"""What the online preprocessing takes and gives: the topic roles, its settings
(:class:`OnlineConfig`) and its samples (:class:`OnlineSample`, stacked by :func:`to_samples`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.signals.preprocess import DataError
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]

TOPIC_ROLES = ("imu", "dvl", "pressure", "thrusters")
DEFAULT_TOPICS = {"imu": "imu/data", "dvl": "dvl/twist", "pressure": "pressure",
                  "thrusters": "thrusters/state"}


def topic_roles(wrench: bool) -> tuple[str, ...]:
    """The message roles in tie order: τ from thruster telemetry (``thrusters``) or, with
    ``wrench``, from a body-wrench topic (``wrench``) in its place."""
    return (*TOPIC_ROLES[:3], "wrench" if wrench else "thrusters")


@dataclass(frozen=True)
class OnlineConfig:
    """Settings of :class:`OnlinePreprocessor` (defaults suit a 200 Hz IMU, 5–8 Hz DVL).

    Attributes
    ----------
    rate : float
        Output sample rate (Hz).
    accel_noise : float
        Accelerometer (plus AHRS-induced gravity) noise per IMU message (m/s²).
    accel_bias_walk : float
        Accelerometer bias random walk (m/s²/√s).
    gyro_noise : float
        Gyro noise per message (rad/s).
    angular_jerk : float
        Power spectral density q of the white angular jerk of the [ω, ω̇] model
        ((rad/s³)²/Hz); sets the filter bandwidth (q = 1: about 11 Hz at 200 Hz).
    dvl_noise : float
        DVL noise (m/s) when the message carries no usable covariance.
    dvl_gate : float
        Mahalanobis gate (χ², 3 DOF) for DVL messages; 0 disables it.
    max_dvl_gap : float
        Samples more than this (s) after the last DVL fix are not usable.
    max_imu_gap : float
        An IMU gap longer than this (s) restarts the inertial filters.
    settle : float
        Samples within this (s) after a start, restart or DVL recovery are not usable.
    stale_after : float
        DVL, pressure and thruster messages older than this (s) behind the IMU are rejected.
    clock_jump : float
        A stamp this much (s) behind its topic's last stamp is a clock jump: reset.
    thrust_window : float
        Message period of the thruster telemetry (s), each message the mean over the period
        before its stamp: puts the sample grid on the window centres and tells a gap (a
        stamp step over 2.5 periods: no sample from those messages); 0: from the stamps.
    atmospheric_pressure : float
        Pa.
    """

    rate: float = 50.0
    accel_noise: float = 0.03
    accel_bias_walk: float = 1e-4
    gyro_noise: float = 0.002
    angular_jerk: float = 1.0
    dvl_noise: float = 0.01
    dvl_gate: float = 25.0
    max_dvl_gap: float = 1.0
    max_imu_gap: float = 0.1
    settle: float = 1.0
    stale_after: float = 1.0
    clock_jump: float = 1.0
    thrust_window: float = 0.0
    atmospheric_pressure: float = 101325.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise ConfigError(f.name, f"must be a finite number, got {v!r}")
            if v < 0:
                raise ConfigError(f.name, f"must be ≥ 0, got {v}")
        for name in ("rate", "gyro_noise", "accel_noise", "angular_jerk", "dvl_noise",
                     "max_imu_gap", "stale_after", "clock_jump"):
            if getattr(self, name) <= 0:
                raise ConfigError(name, "must be > 0")

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> OnlineConfig:
        """From a mapping; unknown keys raise ConfigError naming them."""
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ConfigError("online", f"unknown key(s) {sorted(unknown)}")
        return cls(**{k: float(v) for k, v in d.items()})


@dataclass
class OnlineSample:
    """One synchronised sample (FRD/NED, SI units).

    Attributes
    ----------
    t : float
        Stamp (s), shared by all fields.
    nu, nu_dot, tau : ndarray, shape (6,)
        Velocity (m/s, rad/s), its derivative, generalised thruster force (N, N·m).
    euler : ndarray, shape (3,)
        Roll, pitch, yaw (rad).
    depth : float
        m (NaN without pressure).
    usable : bool
        False during DVL dropouts, before the first fix and while settling.
    """

    t: float
    nu: FloatArray
    nu_dot: FloatArray
    tau: FloatArray
    euler: FloatArray
    depth: float
    usable: bool


def to_samples(samples: list[OnlineSample], rate: float, usable_only: bool = True) -> Samples:
    """Stack online samples into :class:`Samples`; a gap or an unusable stretch starts a new
    segment (so that the batch path sees the same data as the RLS)."""
    keep = [s for s in samples if s.usable or not usable_only]
    if not keep:
        raise DataError("no usable samples")
    t = np.array([s.t for s in keep])
    new_seg = np.r_[False, np.diff(t) > 1.5 / rate]
    return Samples(t, np.array([s.nu for s in keep]), np.array([s.nu_dot for s in keep]),
                   np.array([s.tau for s in keep]), np.array([s.euler for s in keep]),
                   np.array([s.depth for s in keep]), np.cumsum(new_seg).astype(np.int64))
