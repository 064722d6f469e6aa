"""Fixed-layout CDR: byte-for-byte equal to rosbags' serializer, exact round trips."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

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
from dampest_ros.io import cdr

MakeSeries = Callable[..., Series]
AssertSame = Callable[[Series, Series], None]
SERIES_CLASSES = (ImuSeries, TwistSeries, AccelSeries, PressureSeries, WrenchSeries,
                  OdometrySeries, JointSeries)
FRAME_IDS = ["", "a", "ab", "abc", "base_link", "dvl_link_01"]


@pytest.mark.parametrize("frame_id", FRAME_IDS)
@pytest.mark.parametrize("cls", SERIES_CLASSES, ids=lambda c: c.__name__)
def test_encode_equals_rosbags_byte_for_byte(cls: type[Series], frame_id: str,
                                             make_series: MakeSeries, typestore: Any,
                                             to_ros: Callable[[Series, int], Any]) -> None:
    s = make_series(cls, 7, frame_id=frame_id, t0=1.7e9 + 0.123456789)
    msgtype = cdr.message_type(s)
    ours = cdr.encode(s)
    assert len(ours) == 7
    for i, data in enumerate(ours):
        assert data == bytes(typestore.serialize_cdr(to_ros(s, i), msgtype)), i


@pytest.mark.parametrize("joints", [0, 1, 2, 3, 8])
@pytest.mark.parametrize("frame_id", FRAME_IDS)
def test_joint_state_any_count_equals_rosbags(joints: int, frame_id: str,
                                              make_series: MakeSeries, typestore: Any,
                                              to_ros: Callable[[Series, int], Any],
                                              assert_same: AssertSame) -> None:
    s = make_series(JointSeries, 3, frame_id=frame_id, joints=joints)
    ours = cdr.encode(s)
    for i in range(3):
        assert ours[i] == bytes(typestore.serialize_cdr(to_ros(s, i),
                                                        "sensor_msgs/msg/JointState"))
    assert_same(cdr.decode("sensor_msgs/msg/JointState", ours), s)


@pytest.mark.parametrize("cls", SERIES_CLASSES, ids=lambda c: c.__name__)
def test_decode_of_encode_is_exact(cls: type[Series], make_series: MakeSeries,
                                   assert_same: AssertSame) -> None:
    s = make_series(cls, 501, rate=200.0, t0=12.0)
    assert_same(cdr.decode_fixed(cdr.message_type(s), cdr.encode(s)), s)


@pytest.mark.parametrize("cls", SERIES_CLASSES, ids=lambda c: c.__name__)
def test_decode_of_rosbags_messages(cls: type[Series], make_series: MakeSeries,
                                    typestore: Any, to_ros: Callable[[Series, int], Any],
                                    assert_same: AssertSame) -> None:
    s = make_series(cls, 5, t0=3.0)
    msgtype = cdr.message_type(s)
    raw = [bytes(typestore.serialize_cdr(to_ros(s, i), msgtype)) for i in range(5)]
    assert_same(cdr.decode_fixed(msgtype, raw), s)
    # the slow path from message objects gives the same series
    objs = [typestore.deserialize_cdr(r, msgtype) for r in raw]
    assert_same(cdr.decode_messages(msgtype, objs), s)


def test_trailing_padding_from_the_rmw_is_accepted(make_series: MakeSeries,
                                                   assert_same: AssertSame) -> None:
    s = make_series(TwistSeries, 4, frame_id="ab")
    for pad in (1, 2, 3):
        padded = [m + b"\0" * pad for m in cdr.encode(s)]
        assert_same(cdr.decode_fixed(cdr.message_type(s), padded), s)


def test_changing_frame_id_falls_back_and_warns(make_series: MakeSeries) -> None:
    a = make_series(ImuSeries, 3, frame_id="imu_a")
    b = make_series(ImuSeries, 2, frame_id="imu_b")
    msgs = cdr.encode(a) + cdr.encode(b)
    with pytest.raises(cdr.LayoutError):
        cdr.decode_fixed("sensor_msgs/msg/Imu", msgs)
    with pytest.warns(UserWarning, match="imu_a"):
        out = cdr.decode("sensor_msgs/msg/Imu", msgs)
    assert isinstance(out, ImuSeries) and out.frame_id == "imu_a"
    np.testing.assert_array_equal(out.angular_velocity,
                                  np.vstack([a.angular_velocity, b.angular_velocity]))
    np.testing.assert_array_equal(out.stamp, np.concatenate([a.stamp, b.stamp]))


def test_changing_length_of_frame_id_falls_back(make_series: MakeSeries) -> None:
    a = make_series(OdometrySeries, 2, frame_id="base")
    b = make_series(OdometrySeries, 2, frame_id="base_link_long")
    with pytest.warns(UserWarning, match="child_frame_id"):
        out = cdr.decode("nav_msgs/msg/Odometry", cdr.encode(a) + cdr.encode(b))
    assert isinstance(out, OdometrySeries)
    np.testing.assert_array_equal(out.position, np.vstack([a.position, b.position]))


def test_joint_count_that_changes_is_refused(make_series: MakeSeries) -> None:
    msgs = cdr.encode(make_series(JointSeries, 2, joints=2)) + \
        cdr.encode(make_series(JointSeries, 2, joints=3))
    with pytest.raises(ValueError, match="changes length"):
        with pytest.warns(UserWarning):
            cdr.decode("sensor_msgs/msg/JointState", msgs)


def test_shape_error_names_the_field(make_series: MakeSeries) -> None:
    s = make_series(ImuSeries, 4)
    assert isinstance(s, ImuSeries)
    s.orientation_covariance = np.zeros(6)
    with pytest.raises(ValueError, match=r"ImuSeries\.orientation_covariance"):
        cdr.encode(s)
    j = make_series(JointSeries, 4)
    assert isinstance(j, JointSeries)
    j.effort = j.effort[:, 0]
    with pytest.raises(ValueError, match=r"JointSeries\.effort: shape \(4,\)"):
        cdr.encode(j)


def test_empty_series_and_unknown_type() -> None:
    assert cdr.encode(PressureSeries(np.zeros(0))) == []
    out = cdr.decode("sensor_msgs/msg/FluidPressure", [])
    assert isinstance(out, PressureSeries) and len(out) == 0
    with pytest.raises(TypeError, match="std_msgs/msg/String"):
        cdr.decode("std_msgs/msg/String", [b"\0\1\0\0"])


def test_stamps_round_to_the_nearest_ns_and_back() -> None:
    rng = np.random.default_rng(3)
    # sim-clock stamps are exact
    t = np.arange(100_000) / 200.0
    np.testing.assert_array_equal(cdr.stamps_from_ros(*cdr.stamps_to_ros(t)), t)
    # integer nanoseconds survive ns -> s -> ns below 2**22 s
    ns = rng.integers(-(2**22) * 10**9, 2**22 * 10**9, 100_000)
    sec, nsec = cdr.stamps_to_ros(ns / 1e9)
    np.testing.assert_array_equal(sec.astype(np.int64) * 10**9 + nsec, ns)
    # any stamp: within 0.5 ns (plus float spacing), exact at wall-clock magnitude
    t = np.concatenate([rng.uniform(-1e6, 1e6, 100_000), rng.uniform(1.6e9, 1.8e9, 100_000)])
    back = cdr.stamps_from_ros(*cdr.stamps_to_ros(t))
    assert np.all(np.abs(back - t) <= 0.5e-9 + np.spacing(np.abs(t)))
    np.testing.assert_array_equal(back[100_000:], t[100_000:])
    sec, nsec = cdr.stamps_to_ros(np.array([0.9999999999, -0.25, 2.5e-10]))
    assert sec.tolist() == [1, -1, 0] and nsec.tolist() == [0, 750_000_000, 0]
    with pytest.raises(ValueError, match="finite"):
        cdr.stamps_to_ros(np.array([np.nan]))
    with pytest.raises(ValueError, match="int32"):
        cdr.stamps_to_ros(np.array([2.0**31]))
