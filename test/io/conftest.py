"""Shared fixtures for the io tests: random series of every type and an independent reference
conversion of a series row to a rosbags message object (built field by field here, so that the
tests do not check dampest_ros.io.cdr against itself)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields
from fractions import Fraction
from typing import Any

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from dampest_ros.core.signals.measurements import (
    AccelSeries,
    ImuSeries,
    JointSeries,
    OdometrySeries,
    PressureSeries,
    Series,
    TwistSeries,
    WrenchSeries,
)

MakeSeries = Callable[..., Series]


@pytest.fixture(scope="session")
def typestore() -> Any:
    return get_typestore(Stores.ROS2_JAZZY)


def _unit_quat(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def random_series(cls: type[Series], n: int, rng: np.random.Generator, *, rate: float = 50.0,
                  t0: float = 0.0, frame_id: str = "base_link", joints: int = 8) -> Series:
    """A series of ``n`` messages with random values and stamps t0 + k/rate (exact ns)."""
    stamp = (round(t0 * 1e9) + np.arange(n) * round(1e9 / rate)) / 1e9
    v3 = lambda: rng.normal(size=(n, 3))  # noqa: E731
    if cls is ImuSeries:
        return ImuSeries(stamp, frame_id, _unit_quat(rng, n), v3(), v3(),
                         rng.normal(size=9), rng.normal(size=9), rng.normal(size=9))
    if cls in (TwistSeries, AccelSeries):
        return cls(stamp, frame_id, v3(), v3(), rng.normal(size=36))  # type: ignore[call-arg]
    if cls is PressureSeries:
        return PressureSeries(stamp, frame_id, 101325.0 + 1e4 * rng.random(n), 12.5)
    if cls is WrenchSeries:
        return WrenchSeries(stamp, frame_id, v3(), v3())
    if cls is OdometrySeries:
        return OdometrySeries(stamp, "odom", frame_id, v3(), _unit_quat(rng, n), v3(), v3())
    if cls is JointSeries:
        return JointSeries(stamp, frame_id, tuple(f"thruster{k + 1}" for k in range(joints)),
                           rng.normal(size=(n, joints)), rng.normal(size=(n, joints)))
    raise TypeError(cls)


@pytest.fixture
def make_series() -> MakeSeries:
    rng = np.random.default_rng(12345)
    return lambda cls, n, **kw: random_series(cls, n, rng, **kw)


@pytest.fixture
def recording(make_series: MakeSeries) -> dict[str, Series]:
    """A few seconds of every topic of the contract, at different rates."""
    return {
        "truth/odom": make_series(OdometrySeries, 100, rate=50.0, frame_id="base_link"),
        "imu/data": make_series(ImuSeries, 400, rate=200.0, frame_id="imu_link"),
        "dvl/twist": make_series(TwistSeries, 20, rate=10.0, frame_id="dvl_link"),
        "pressure": make_series(PressureSeries, 40, rate=20.0, frame_id="pressure_link"),
        "thrusters/state": make_series(JointSeries, 100, rate=50.0, frame_id=""),
        "dampest/velocity": make_series(TwistSeries, 100, rate=50.0),
        "dampest/acceleration": make_series(AccelSeries, 100, rate=50.0),
        "dampest/wrench": make_series(WrenchSeries, 100, rate=50.0),
    }


@pytest.fixture
def to_ros(typestore: Any) -> Callable[[Series, int], Any]:
    """Message i of a series as a rosbags message object."""
    T = typestore.types

    def vec(a: np.ndarray, kind: str = "Vector3") -> Any:
        return T[f"geometry_msgs/msg/{kind}"](*map(float, a))

    def convert(s: Series, i: int) -> Any:
        ns = round(Fraction(float(s.stamp[i])) * 10**9)
        stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        header = T["std_msgs/msg/Header"](stamp=stamp, frame_id=s.frame_id)
        if isinstance(s, ImuSeries):
            return T["sensor_msgs/msg/Imu"](
                header, vec(s.orientation[i], "Quaternion"), s.orientation_covariance,
                vec(s.angular_velocity[i]), s.angular_velocity_covariance,
                vec(s.linear_acceleration[i]), s.linear_acceleration_covariance)
        if isinstance(s, TwistSeries):
            twist = T["geometry_msgs/msg/Twist"](vec(s.linear[i]), vec(s.angular[i]))
            return T["geometry_msgs/msg/TwistWithCovarianceStamped"](
                header, T["geometry_msgs/msg/TwistWithCovariance"](twist, s.covariance))
        if isinstance(s, AccelSeries):
            accel = T["geometry_msgs/msg/Accel"](vec(s.linear[i]), vec(s.angular[i]))
            return T["geometry_msgs/msg/AccelWithCovarianceStamped"](
                header, T["geometry_msgs/msg/AccelWithCovariance"](accel, s.covariance))
        if isinstance(s, PressureSeries):
            return T["sensor_msgs/msg/FluidPressure"](header, float(s.fluid_pressure[i]),
                                                      float(s.variance))
        if isinstance(s, WrenchSeries):
            return T["geometry_msgs/msg/WrenchStamped"](
                header, T["geometry_msgs/msg/Wrench"](vec(s.force[i]), vec(s.torque[i])))
        if isinstance(s, OdometrySeries):
            pose = T["geometry_msgs/msg/Pose"](vec(s.position[i], "Point"),
                                               vec(s.orientation[i], "Quaternion"))
            twist = T["geometry_msgs/msg/Twist"](vec(s.linear[i]), vec(s.angular[i]))
            return T["nav_msgs/msg/Odometry"](
                header, s.child_frame_id,
                T["geometry_msgs/msg/PoseWithCovariance"](pose, np.zeros(36)),
                T["geometry_msgs/msg/TwistWithCovariance"](twist, np.zeros(36)))
        if isinstance(s, JointSeries):
            return T["sensor_msgs/msg/JointState"](header, list(s.names), np.zeros(0),
                                                   s.velocity[i].copy(), s.effort[i].copy())
        raise TypeError(type(s))

    return convert


def assert_series_equal(a: Series, b: Series) -> None:
    """Same class, same values bit for bit (float64 arrays of the same shape)."""
    assert type(a) is type(b)
    for f in fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == np.float64 and x.shape == np.shape(y), f.name
            np.testing.assert_array_equal(x, y, err_msg=f.name, strict=True)
        else:
            assert x == y, f.name


def as_tree(msg: Any) -> Any:
    """A message (rosbags dataclass or mcap_ros2 slots object) as nested dicts and lists."""
    fields = getattr(msg, "__dataclass_fields__", None) or getattr(type(msg), "__slots__", None)
    if fields is not None and not isinstance(msg, (str, bytes)):
        return {f: as_tree(getattr(msg, f)) for f in fields if not f.startswith("__")}
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    if isinstance(msg, (list, tuple)):
        return [as_tree(m) for m in msg]
    return msg


@pytest.fixture
def tree() -> Callable[[Any], Any]:
    return as_tree


@pytest.fixture
def assert_same() -> Callable[[Series, Series], None]:
    return assert_series_equal
