"""Messages ↔ arrays. ROS side FLU/ENU, as the messages carry them; frame changes to
FRD/NED happen in dampest_ros.core (frames), never here."""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
from geometry_msgs.msg import TwistWithCovarianceStamped, Vector3, WrenchStamped
from nav_msgs.msg import Odometry
from numpy.typing import NDArray
from sensor_msgs.msg import FluidPressure, Imu, JointState

from dampest_ros.core.signals.measurements import (
    ImuSeries,
    JointSeries,
    OdometrySeries,
    PressureSeries,
    Recording,
    Series,
    TwistSeries,
    WrenchSeries,
    stamp_order,
)
from dampest_ros.ros.common import to_time

FloatArray = NDArray[np.float64]


def vec3(v: FloatArray) -> Vector3:
    """geometry_msgs/Vector3 from a 3-vector."""
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def xyz(v: Vector3) -> FloatArray:
    """A 3-vector from geometry_msgs/Vector3 (or Point)."""
    return np.array([v.x, v.y, v.z])


def publications(rec: Recording) -> Iterator[tuple[str, Any]]:
    """(topic, message) for every row of every series of a simulated recording, in stamp
    order (ties in the recording's topic order): what the sim node publishes.

    Each topic has one message object, its constant fields (frame ids, covariances, joint
    names) set once and the rest filled row after row, so a message is valid until the next
    one of its topic is yielded: publish it at once (rclpy serialises on publish).
    """
    fills = [(topic, _filler(s)) for topic, s in rec.items() if len(s)]
    which, row = stamp_order([rec[topic].stamp for topic, _ in fills])
    for k, i in zip(which.tolist(), row.tolist(), strict=True):
        topic, fill = fills[k]
        yield topic, fill(i)


def _filler(s: Series) -> Callable[[int], Any]:
    """A message for series ``s`` and the function that fills it with row i."""
    fill: Callable[[int], None]
    if isinstance(s, ImuSeries):
        m: Any = Imu()
        m.orientation_covariance = s.orientation_covariance.astype(float)
        m.angular_velocity_covariance = s.angular_velocity_covariance.astype(float)
        m.linear_acceleration_covariance = s.linear_acceleration_covariance.astype(float)
        q, w, f = (s.orientation.tolist(), s.angular_velocity.tolist(),
                   s.linear_acceleration.tolist())
        o, av, la = m.orientation, m.angular_velocity, m.linear_acceleration

        def fill(i: int) -> None:
            o.x, o.y, o.z, o.w = q[i]
            av.x, av.y, av.z = w[i]
            la.x, la.y, la.z = f[i]
    elif isinstance(s, TwistSeries):
        m = TwistWithCovarianceStamped()
        m.twist.covariance = s.covariance.astype(float)
        lin, ang = s.linear.tolist(), s.angular.tolist()
        tl, ta = m.twist.twist.linear, m.twist.twist.angular

        def fill(i: int) -> None:
            tl.x, tl.y, tl.z = lin[i]
            ta.x, ta.y, ta.z = ang[i]
    elif isinstance(s, PressureSeries):
        m = FluidPressure(variance=float(s.variance))
        p = s.fluid_pressure.tolist()

        def fill(i: int) -> None:
            m.fluid_pressure = p[i]
    elif isinstance(s, JointSeries):
        m = JointState(name=list(s.names))
        vel, eff = s.velocity.tolist(), s.effort.tolist()

        def fill(i: int) -> None:
            m.velocity, m.effort = vel[i], eff[i]
    elif isinstance(s, OdometrySeries):
        m = Odometry(child_frame_id=s.child_frame_id)
        pos, ori, lin, ang = (s.position.tolist(), s.orientation.tolist(), s.linear.tolist(),
                              s.angular.tolist())
        pp, po = m.pose.pose.position, m.pose.pose.orientation
        tl, ta = m.twist.twist.linear, m.twist.twist.angular

        def fill(i: int) -> None:
            pp.x, pp.y, pp.z = pos[i]
            po.x, po.y, po.z, po.w = ori[i]
            tl.x, tl.y, tl.z = lin[i]
            ta.x, ta.y, ta.z = ang[i]
    elif isinstance(s, WrenchSeries):
        m = WrenchStamped()
        force, torque = s.force.tolist(), s.torque.tolist()
        wf, wt = m.wrench.force, m.wrench.torque

        def fill(i: int) -> None:
            wf.x, wf.y, wf.z = force[i]
            wt.x, wt.y, wt.z = torque[i]
    else:
        raise TypeError(f"no message for {type(s).__name__}")
    m.header.frame_id = s.frame_id
    stamps = s.stamp.tolist()

    def stamped(i: int) -> Any:
        m.header.stamp = to_time(stamps[i])
        fill(i)
        return m
    return stamped


def joint_columns(joints: tuple[str, ...], names: tuple[str, ...]
                  ) -> tuple[NDArray[np.intp] | None, list[str]]:
    """Where each of ``joints`` is in a JointState naming ``names`` (the first of a name
    given twice), and the joints it lacks; the indices are None when it lacks any."""
    missing = [n for n in joints if n not in names]
    return (None if missing else np.array([names.index(n) for n in joints])), missing


def twist6(m: TwistWithCovarianceStamped) -> FloatArray:
    """[linear, angular] of a TwistWithCovarianceStamped (FLU)."""
    tw = m.twist.twist
    return np.concatenate([xyz(tw.linear), xyz(tw.angular)])


def wrench6(m: WrenchStamped) -> FloatArray:
    """[force, torque] of a WrenchStamped (FLU)."""
    return np.concatenate([xyz(m.wrench.force), xyz(m.wrench.torque)])


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


def header_frame_id(data: bytes) -> str:
    """The header.frame_id of a serialized message that starts with a std_msgs/Header
    (plain CDR, as :func:`stamped_floats` reads it).

    Raises
    ------
    ValueError
        Another encapsulation, or a message too short for its frame_id.
    """
    order = _CDR_ORDER.get(bytes(data[:2]))
    if order is None:
        raise ValueError(f"not plain CDR (encapsulation {bytes(data[:2]).hex()})")
    size = _STAMP[order].unpack_from(data, 4)[2]  # the string's length, its NUL included
    if size < 1 or len(data) < 16 + size:
        raise ValueError(f"{len(data)} bytes: too short for a frame_id of {size} bytes")
    return bytes(data[16:15 + size]).decode(errors="replace")
