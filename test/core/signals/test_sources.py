"""Velocity and attitude sources (dampest_ros.core.signals.sources) and the body rates of
an attitude (dampest_ros.core.physics.frames.body_rates)."""

from __future__ import annotations

import numpy as np

from dampest_ros.core.physics import frames
from dampest_ros.core.physics.mounting import Mounting, SensorMount
from dampest_ros.core.signals.measurements import (
    ImuSeries,
    OdometrySeries,
    PoseSeries,
    TwistSeries,
)
from dampest_ros.core.signals.preprocess import zero_phase
from dampest_ros.core.signals.sources import Sources, as_imu, held_updates


def test_held_velocity_is_used_at_the_first_message_of_each_run() -> None:
    rng = np.random.default_rng(3)
    updates = rng.standard_normal((20, 3))
    runs = rng.integers(5, 12, size=20)  # 50 Hz republishing a ~6 Hz DVL
    v = np.repeat(updates, runs, axis=0)
    first = held_updates(v)
    assert first is not None
    np.testing.assert_array_equal(np.flatnonzero(first), np.r_[0, np.cumsum(runs)[:-1]])
    np.testing.assert_array_equal(v[first], updates)
    assert held_updates(rng.standard_normal((200, 3))) is None  # a noisy sensor never repeats


def test_body_rates_of_a_known_rotation() -> None:
    # R(t) = exp(t [ω]×) applied on the right: a constant body rate ω, any start attitude
    rate, omega = 200.0, np.array([0.3, -0.2, 0.5])
    t = np.arange(2000) / rate
    q0 = frames.matrix_to_quat(frames.matrix_from_euler(np.array([0.1, -0.4, 2.0])))
    q = frames.quat_mul(np.repeat(q0[None], len(t), axis=0),
                        frames.small_rotation(t[:, None] * omega))
    q_dot = zero_phase(q, rate, 10.0, derivative=True)
    inner = slice(200, -200)  # away from the mirrored ends
    np.testing.assert_allclose(frames.body_rates(q, q_dot)[inner],
                               np.broadcast_to(omega, (len(t), 3))[inner], atol=1e-6)


def test_sources_say_what_is_missing_and_drop_the_mounting_of_body_frames() -> None:
    n = 10
    odom = OdometrySeries(np.arange(n, dtype=float), "odom", "base_link", np.zeros((n, 3)),
                          np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)), np.ones((n, 3)),
                          np.zeros((n, 3)))
    imu = as_imu(odom)
    assert isinstance(imu, ImuSeries) and imu.frame_id == "base_link"
    s = Sources.of(imu, OdometrySeries, OdometrySeries)
    assert not s.gyro and not s.accel
    lines = s.notes("nav/odom", "nav/odom")
    assert [line.split(" (")[0] for line in lines] == ["no accelerometer in nav/odom",
                                                      "no gyro in nav/odom"]
    mount = Mounting(SensorMount("imu_link", (0.1, 0.0, 0.0), declared=True),
                     SensorMount("dvl_link", (0.3, 0.0, 0.1), declared=True))
    body = s.mounting(mount)
    assert body.imu.centred and body.dvl.centred and not body.imu.declared
    kept = Sources(ImuSeries, TwistSeries, True, True)
    assert kept.mounting(mount) == mount and kept.notes("imu/data", "dvl/twist") == []
    pose = PoseSeries(odom.stamp, "map", odom.position, odom.orientation)
    assert not np.any(as_imu(pose).angular_velocity)
