"""The pure-axis check: the samples flown along an axis against the model's law there, and
the σ it scales."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.cli.identify import force_dof
from dampest_ros.core.identification import axis_check as axis_check_module
from dampest_ros.core.identification.axis_check import (
    CONE,
    MIN_SAMPLES,
    AxisStatistics,
    along_axes,
    axis_check,
    axis_statistics,
)
from dampest_ros.core.identification.batch import FitOptions, fit
from dampest_ros.core.physics.frames import euler_from_matrix, quat_to_matrix
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.simulation.excitation import make_excitation, speed_limits
from dampest_ros.core.simulation.simulate import run
from dampest_ros.io.yaml_io import load_vehicle

QUIET = FitOptions(cutoff=2.0, gyro_bias=0.0, dvl_bias=0.0)


@pytest.fixture(scope="module")
def vehicle() -> Vehicle:
    return load_vehicle("bluerov2_heavy")


def flown(vehicle: Vehicle, protocol: str, cross_flow: float = 0.0,
          duration: float = 180.0) -> Samples:
    """ν, ν̇ of a simulated run and τ from Fossen's equation with the vehicle's damping, plus
    ``cross_flow`` · u|v| in surge (a force no term of the model has, zero along every
    axis), plus seeded noise of 2 % of each DOF's RMS force."""
    traj = run(vehicle, make_excitation(protocol, vehicle, duration, seed=4), dt=0.02)
    nu = traj.nu
    R = quat_to_matrix(traj.quaternion)
    tau = (traj.nu_dot @ vehicle.body.M.T + vehicle.body.coriolis_force(nu)
           + vehicle.damping.force(nu, vehicle.theta) + vehicle.body.restoring(R))
    tau[:, 0] += cross_flow * nu[:, 0] * np.abs(nu[:, 1])
    noise = np.random.default_rng(5).normal(size=tau.shape) * 0.02 * tau.std(axis=0)
    return Samples(traj.t, nu, traj.nu_dot, tau + noise, euler_from_matrix(R),
                   traj.position[:, 2], np.zeros(len(traj.t), dtype=np.int64))


def session(vehicle: Vehicle, cross_flow: float) -> Samples:
    """Protocol B (360 s) and the pure-axis legs (180 s), one session of two segments."""
    return Samples.concatenate([flown(vehicle, "B", cross_flow, 360.0),
                                flown(vehicle, "axes", cross_flow)])


def test_a_sample_is_along_an_axis_within_the_cone() -> None:
    """Shares of the range: along u when the others' norm is within CONE of u's share and
    u's share is at least MOVING (5 %)."""
    lim = np.array([1.0, 2.0, 1.0, 1.0, 1.0, 1.0])
    nu = np.array([[0.5, 0.0, 0, 0, 0, 0],
                   [0.5, 2 * 0.99 * CONE * 0.5, 0, 0, 0, 0],   # v's share just inside
                   [0.5, 2 * 1.01 * CONE * 0.5, 0, 0, 0, 0],   # just outside
                   [0.04, 0.0, 0, 0, 0, 0],                    # too slow
                   [0.0, 0.0, 0, 0, 0, -0.3]])
    near = along_axes(nu, lim)
    assert near.tolist() == [[True] + [False] * 5, [True] + [False] * 5, [False] * 6,
                             [False] * 6, [False] * 5 + [True]]


def test_the_model_form_passes_and_a_missing_force_scales_its_row(
        vehicle: Vehicle, monkeypatch: pytest.MonkeyPatch) -> None:
    """A session of mixed motion and pure-axis legs. Plant of the model's form: every DOF is
    checked and agrees (Birge ratio < 2; the samples' surge law within 1 % of the plant's
    X_u|u|). With a cross-flow force u|v| the model lacks, the mixed motion bends the model's
    surge law (its X_u triples) while the samples along the axis still show the plant's:
    surge disagrees by many σ, and exactly the surge row's parameters have their σ scaled by
    R, θ unchanged."""
    names = vehicle.damping.parameter_names
    x_uu = vehicle.theta[names.index("X_uu")]
    exact = fit(session(vehicle, 0.0), vehicle.damping, vehicle.body, QUIET)
    assert exact.axes is not None
    assert np.all(exact.axes.flown) and np.all(exact.axes.n >= MIN_SAMPLES)
    assert np.all(exact.axes.ratio < 2.0), exact.axes.ratio
    np.testing.assert_allclose(exact.axes.measured[0, 1], x_uu, rtol=0.01)

    plant = session(vehicle, 100.0)
    missing = fit(plant, vehicle.damping, vehicle.body, QUIET)
    assert missing.axes is not None
    scale = missing.axes.scale  # read before no axis is checked
    monkeypatch.setattr(axis_check_module, "MIN_SAMPLES", 10 ** 9)  # no axis checked
    unscaled = fit(plant, vehicle.damping, vehicle.body, QUIET)
    assert unscaled.axes is not None
    assert not unscaled.axes.flown.any()
    np.testing.assert_array_equal(missing.theta, unscaled.theta)
    np.testing.assert_allclose(missing.axes.measured[0, 1], x_uu, rtol=0.01)
    assert missing.axes.modelled[0, 0] > 2 * missing.axes.measured[0, 0]
    R = missing.axes.ratio[0]
    assert R > 5 and scale[0] == R
    surge = np.array([n.startswith("X_") for n in missing.names])
    ratio = missing.std / unscaled.std
    np.testing.assert_allclose(ratio[surge], R, rtol=1e-12)
    # the other rows' parameters: their own row's scale (one row each in this model)
    rows = [force_dof(n) for n in np.array(missing.names)[~surge]]
    np.testing.assert_allclose(ratio[~surge], scale[rows], rtol=1e-12)


def test_protocol_b_flies_no_axis_and_leaves_sigma(vehicle: Vehicle) -> None:
    """Mixed motion (protocol B) hardly passes along an axis: nothing is checked, σ stays."""
    s = flown(vehicle, "B", duration=120.0)
    f = fit(s, vehicle.damping, vehicle.body, QUIET)
    assert f.axes is not None and not f.axes.flown.any()
    np.testing.assert_array_equal(f.axes.scale, np.ones(6))


def test_statistics_of_parts_join_to_those_of_the_whole(vehicle: Vehicle) -> None:
    """Sums over samples: two halves (no low-pass to straddle the cut) join to the whole."""
    s = flown(vehicle, "axes", duration=120.0)
    lim = speed_limits(vehicle)
    half = len(s) // 2

    def part(sl: slice) -> Samples:
        return Samples(s.t[sl], s.nu[sl], s.nu_dot[sl], s.tau[sl], s.euler[sl],
                       s.depth[sl], s.segment[sl])

    whole = axis_statistics(s, vehicle.damping, vehicle.body, 0.0, lim)
    joined = AxisStatistics.join([axis_statistics(part(sl), vehicle.damping, vehicle.body,
                                                  0.0, lim)
                                  for sl in (slice(0, half), slice(half, None))])
    for name in ("XX", "Xy", "yy", "UU", "UAxis", "n"):
        np.testing.assert_allclose(getattr(joined, name), getattr(whole, name), rtol=1e-9,
                                   atol=1e-9, err_msg=name)
    check = axis_check(whole, vehicle.theta, np.zeros((len(vehicle.theta),) * 2))
    assert check.flown.sum() >= 4
