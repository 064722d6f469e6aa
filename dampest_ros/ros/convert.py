"""Messages ↔ arrays. ROS side FLU/ENU, as the messages carry them; frame changes to
FRD/NED happen in dampest_ros.core (frames), never here."""

from __future__ import annotations

import struct

import numpy as np
from geometry_msgs.msg import (
    AccelWithCovarianceStamped,
    TwistWithCovarianceStamped,
    Vector3,
    WrenchStamped,
)
from nav_msgs.msg import Odometry
from numpy.typing import NDArray
from sensor_msgs.msg import FluidPressure, Imu, JointState

from dampest_ros.core.measurements import (
    ImuSeries,
    JointSeries,
    OdometrySeries,
    PressureSeries,
    Series,
    TwistSeries,
)
from dampest_ros.ros.common import to_time

FloatArray = NDArray[np.float64]


def vec3(v: FloatArray) -> Vector3:
    """geometry_msgs/Vector3 from a 3-vector."""
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def xyz(v: Vector3) -> FloatArray:
    """A 3-vector from geometry_msgs/Vector3 (or Point)."""
    return np.array([v.x, v.y, v.z])


def series_messages(topic: str, s: Series) -> list[tuple[float, object]]:
    """(stamp, message) for every row of a simulated series (the sim node publishes them)."""
    out: list[tuple[float, object]] = []
    for i in range(len(s)):
        t = float(s.stamp[i])
        out.append((t, _message(s, i, t)))
    return out


def _message(s: Series, i: int, t: float) -> object:
    if isinstance(s, ImuSeries):
        m = Imu()
        q = s.orientation[i]
        m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w = map(float, q)
        m.angular_velocity = vec3(s.angular_velocity[i])
        m.linear_acceleration = vec3(s.linear_acceleration[i])
        m.orientation_covariance = s.orientation_covariance.astype(float)
        m.angular_velocity_covariance = s.angular_velocity_covariance.astype(float)
        m.linear_acceleration_covariance = s.linear_acceleration_covariance.astype(float)
    elif isinstance(s, TwistSeries):
        m = TwistWithCovarianceStamped()
        m.twist.twist.linear = vec3(s.linear[i])
        m.twist.twist.angular = vec3(s.angular[i])
        m.twist.covariance = s.covariance.astype(float)
    elif isinstance(s, PressureSeries):
        m = FluidPressure(fluid_pressure=float(s.fluid_pressure[i]), variance=float(s.variance))
    elif isinstance(s, JointSeries):
        m = JointState(name=list(s.names), velocity=s.velocity[i].tolist(),
                       effort=s.effort[i].tolist())
    elif isinstance(s, OdometrySeries):
        m = Odometry(child_frame_id=s.child_frame_id)
        m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z = \
            map(float, s.position[i])
        o = m.pose.pose.orientation
        o.x, o.y, o.z, o.w = map(float, s.orientation[i])
        m.twist.twist.linear = vec3(s.linear[i])
        m.twist.twist.angular = vec3(s.angular[i])
    else:
        raise TypeError(f"no message for {type(s).__name__}")
    m.header.stamp = to_time(t)
    m.header.frame_id = s.frame_id
    return m


def twist6(m: TwistWithCovarianceStamped) -> FloatArray:
    """[linear, angular] of a TwistWithCovarianceStamped (FLU)."""
    tw = m.twist.twist
    return np.concatenate([xyz(tw.linear), xyz(tw.angular)])


def wrench6(m: WrenchStamped) -> FloatArray:
    """[force, torque] of a WrenchStamped (FLU)."""
    return np.concatenate([xyz(m.wrench.force), xyz(m.wrench.torque)])


def twist_msg(v: FloatArray, var: float = 0.0) -> TwistWithCovarianceStamped:
    """TwistWithCovarianceStamped from [linear, angular] (FLU); diagonal variance ``var``."""
    m = TwistWithCovarianceStamped()
    m.twist.twist.linear = vec3(v[:3])
    m.twist.twist.angular = vec3(v[3:])
    m.twist.covariance = (np.eye(6) * var).ravel()
    return m


def accel_msg(a: FloatArray, var: float = 0.0) -> AccelWithCovarianceStamped:
    """AccelWithCovarianceStamped from [linear, angular] (FLU)."""
    m = AccelWithCovarianceStamped()
    m.accel.accel.linear = vec3(a[:3])
    m.accel.accel.angular = vec3(a[3:])
    m.accel.covariance = (np.eye(6) * var).ravel()
    return m


def wrench_msg(w: FloatArray) -> WrenchStamped:
    """WrenchStamped from [force, torque] (FLU)."""
    m = WrenchStamped()
    m.wrench.force = vec3(w[:3])
    m.wrench.torque = vec3(w[3:])
    return m


#: Plain CDR encapsulation (little, big endian) → byte order of struct and numpy.
_CDR_ORDER = {b"\x00\x01": "<", b"\x00\x00": ">"}
_STAMP = {o: struct.Struct(f"{o}iII") for o in _CDR_ORDER.values()}


def stamped_floats(data: bytes, count: int) -> tuple[int, FloatArray]:
    """Header stamp and the first float64 fields of a serialized message that is a
    std_msgs/Header followed by float64 fields, read in place from its CDR bytes (a raw
    subscription's message; ~1 µs instead of ~23 µs for rclpy's deserialisation).

    TwistWithCovarianceStamped and AccelWithCovarianceStamped: [linear, angular] (6), then
    the covariance (36); WrenchStamped: [force, torque] (6); QuaternionStamped: [x, y, z, w]
    (4); sensor_msgs/Imu: orientation (4), its covariance (9), angular velocity (3), its
    covariance (9), linear acceleration (3), its covariance (9); FluidPressure: pressure,
    variance.

    Parameters
    ----------
    data : bytes
        Plain CDR (XCDR1, as every ROS 2 middleware sends these types): the 4-byte
        encapsulation header, int32 sec, uint32 nanosec, the frame_id string (uint32 length
        with its NUL, the bytes), then the float64 fields aligned to 8 bytes.
    count : int
        Number of float64 fields to read.

    Returns
    -------
    stamp : int
        sec · 10⁹ + nanosec (ns).
    values : ndarray, shape (count,)
        Read-only view of ``data``.

    Raises
    ------
    ValueError
        Another encapsulation, or a message too short for ``count`` fields.
    """
    order = _CDR_ORDER.get(bytes(data[:2]))
    if order is None:
        raise ValueError(f"not plain CDR (encapsulation {bytes(data[:2]).hex()})")
    sec, nanosec, size = _STAMP[order].unpack_from(data, 4)
    start = 4 + ((12 + size + 7) & ~7)  # alignment counts from the byte after the header
    if len(data) < start + 8 * count:
        raise ValueError(f"{len(data)} bytes: too short for {count} float64 after the header")
    return sec * 1_000_000_000 + nanosec, np.frombuffer(data, f"{order}f8", count, start)
