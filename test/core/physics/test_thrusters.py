"""Thrusters: the first-order lag and the step means a vehicle logs."""

from __future__ import annotations

import math

import numpy as np

from dampest_ros.core.physics.thrusters import lag_toward
from dampest_ros.io.yaml_io import load_vehicle


def test_lag_toward_is_the_exponential_approach() -> None:
    # n(s) = c + (n0 − c) e^{−s/T}: from 10 toward 4 rev/s after one time constant
    n = lag_toward(np.array([10.0, -2.0]), np.array([4.0, 4.0]), math.exp(-1.0))
    np.testing.assert_allclose(n, [4.0 + 6.0 / math.e, 4.0 - 6.0 / math.e], rtol=1e-15)


def test_step_means_of_a_lag() -> None:
    thr = load_vehicle("bluerov2_heavy").need_thrusters("the test")
    tm, h = thr.time_constant, 0.02
    n0 = np.linspace(-30.0, 30.0, 2 * thr.count).reshape(2, thr.count)
    cmd = np.full_like(n0, 12.0)
    mean, thrust = thr.step_means(n0, cmd, h)
    # the exact mean c + (n0 − c)(T/h)(1 − e^{−h/T}), and at rest on the command T(c)
    np.testing.assert_allclose(mean, 12.0 + (n0 - 12.0) * tm / h * (1 - math.exp(-h / tm)),
                               rtol=1e-14)
    rest_mean, rest_thrust = thr.step_means(cmd, cmd, h)
    np.testing.assert_array_equal(rest_mean, cmd)
    np.testing.assert_allclose(rest_thrust, thr.gain * 144.0, rtol=1e-15)
    # the Simpson mean of the thrust over the step lies between its end values
    start, end = thr.thrust(n0), thr.thrust(thr.lag_step(n0, cmd, h)[2])
    assert np.all((thrust - np.minimum(start, end) > -1e-12)
                  & (np.maximum(start, end) - thrust > -1e-12))
