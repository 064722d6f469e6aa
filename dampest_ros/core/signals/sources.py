"""Velocity and attitude sources besides a raw IMU/DVL pair, and what they lack.

A real vehicle's log often holds a state estimator's navigation state instead of the raw
sensors. The offline preprocessing (:mod:`.preprocess`) takes, in ROS frames:

- **attitude** (role ``imu``): sensor_msgs/Imu (:class:`ImuSeries`); nav_msgs/Odometry
  (:class:`OdometrySeries`: the pose's orientation, the twist's angular velocity, no
  accelerometer); geometry_msgs/PoseStamped (:class:`PoseSeries`: orientation only);
- **velocity** (role ``dvl``): a DVL's TwistWithCovarianceStamped or TwistStamped
  (:class:`TwistSeries`, in the DVL's axes), or nav_msgs/Odometry (the twist in the child
  frame: the body velocity at the body origin).

Odometry and PoseStamped describe the body (``base_link``) itself, so the vehicle file's IMU
and DVL mounting does not apply to them. What a source does not carry, or carries all zero
(an empty field), is substituted, each substitution named in one line (:func:`notes`):
no accelerometer, ν̇ from the zero-phase derivative of the velocity; no gyro, the body rates
from the attitude's quaternion derivative. A velocity that a state estimator republishes
between DVL updates (runs of identical values) is used at its updates only
(:func:`held_updates`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.physics.mounting import Mounting, SensorMount
from dampest_ros.core.signals.measurements import (
    ImuSeries,
    OdometrySeries,
    PoseSeries,
    Series,
    TwistSeries,
)

FloatArray = NDArray[np.float64]

#: Series a topic of the ``imu`` role may hold (attitude, and gyro and accelerometer if any).
ATTITUDE_TYPES: tuple[type[Series], ...] = (ImuSeries, OdometrySeries, PoseSeries)
#: Series a topic of the ``dvl`` role may hold (body velocity).
VELOCITY_TYPES: tuple[type[Series], ...] = (TwistSeries, OdometrySeries)
#: Fraction of a velocity topic's messages that repeat the previous value exactly above which
#: the value is taken as held between updates (a sensor with noise never repeats itself).
HELD_FRACTION = 0.5
#: The frame of a body attitude or velocity (Odometry's child frame, PoseStamped's body).
BODY_FRAME = "base_link"

_NAMES = {ImuSeries: "Imu", OdometrySeries: "Odometry", PoseSeries: "PoseStamped",
          TwistSeries: "DVL"}


def as_imu(s: Series) -> ImuSeries:
    """An attitude source as an ImuSeries (ROS frames): fields it lacks all zero.

    Parameters
    ----------
    s : ImuSeries, OdometrySeries or PoseSeries
        One of :data:`ATTITUDE_TYPES`.

    Returns
    -------
    ImuSeries
        orientation (N, 4) xyzw, angular_velocity (N, 3) rad/s FLU (Odometry's twist
        angular, zero for a pose), linear_acceleration (N, 3) zero but for an Imu.
    """
    if isinstance(s, ImuSeries):
        return s
    assert isinstance(s, OdometrySeries | PoseSeries)
    zeros = np.zeros((len(s), 3))
    rate = s.angular if isinstance(s, OdometrySeries) else zeros
    return ImuSeries(s.stamp, BODY_FRAME, s.orientation, rate, zeros)


def velocity_of(s: Series) -> FloatArray:
    """Linear velocity (N, 3) (m/s, FLU) of a velocity source, one of :data:`VELOCITY_TYPES`:
    a DVL's in its own axes, an Odometry's in its child frame."""
    assert isinstance(s, TwistSeries | OdometrySeries)
    return s.linear


def held_updates(v: FloatArray) -> NDArray[np.bool_] | None:
    """The update instants of a velocity held between updates, or None if it is not held.

    Parameters
    ----------
    v : ndarray, shape (M, 3)
        Velocities in message order.

    Returns
    -------
    ndarray of bool, shape (M,), or None
        True at the first message of each run of identical values; None when fewer than
        :data:`HELD_FRACTION` of the messages repeat their predecessor.
    """
    first = np.ones(len(v), dtype=bool)
    # a message starts a run when any component differs from the previous message's
    first[1:] = np.any(np.diff(v, axis=0) != 0, axis=1)
    return first if len(v) > 1 and (~first).mean() > HELD_FRACTION else None


@dataclass(frozen=True)
class Sources:
    """What the attitude and velocity topics carry, and so what is substituted.

    Attributes
    ----------
    attitude : type
        Series class of the attitude topic (role ``imu``).
    velocity : type
        Series class of the velocity topic (role ``dvl``).
    gyro, accel : bool
        The attitude topic carries a filled angular velocity / linear acceleration (not all
        zero).
    """

    attitude: type[Series]
    velocity: type[Series]
    gyro: bool
    accel: bool

    @classmethod
    def of(cls, head: ImuSeries, attitude: type[Series], velocity: type[Series]) -> Sources:
        """From the first messages of the attitude topic (:func:`as_imu`), decoded as
        ``attitude``, and the velocity topic's class."""
        return cls(attitude, velocity, bool(np.any(head.angular_velocity != 0)),
                   bool(np.any(head.linear_acceleration != 0)))

    def mounting(self, mount: Mounting) -> Mounting:
        """``mount`` with the IMU or DVL at the body origin and axes where the topic gives
        the body's own attitude or velocity (Odometry, PoseStamped)."""
        body = SensorMount(BODY_FRAME)
        return Mounting(mount.imu if self.attitude is ImuSeries else body,
                        mount.dvl if self.velocity is TwistSeries else body, mount.pressure)

    def notes(self, imu: str, dvl: str) -> list[str]:
        """One line per substitution, naming the topics (``imu``, ``dvl``: the attitude and
        velocity topics) and what replaces the missing signal."""
        lines = []
        kind = _NAMES[self.attitude]
        if not self.accel:
            accel = "linear_acceleration all zero" if self.attitude is ImuSeries else \
                f"{kind} has none"
            lines.append(f"no accelerometer in {imu} ({accel}): u̇, v̇, ẇ from the zero-phase "
                         f"derivative of the {_NAMES[self.velocity]} velocity in {dvl}")
        if not self.gyro:
            gyro = {ImuSeries: "angular_velocity all zero", OdometrySeries:
                    "twist.twist.angular all zero", PoseSeries: "PoseStamped has none"}
            lines.append(f"no gyro in {imu} ({gyro[self.attitude]}): p, q, r from the "
                         f"zero-phase derivative of the {kind} attitude (body rates of the "
                         "quaternion)")
        return lines


def held_note(topic: str, updates: int, messages: int, span: float) -> str:
    """The line naming a velocity held between updates and the update rate found.

    Parameters
    ----------
    updates, messages : int
        Runs of identical values, and messages.
    span : float
        Seconds from the first to the last message.
    """
    return (f"velocity held between updates in {topic}: {updates} updates in {messages} "
            f"messages, update rate {(updates - 1) / span:.3g} Hz (message rate "
            f"{(messages - 1) / span:.3g} Hz); used at its updates only")
