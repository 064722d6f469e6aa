"""The identified Model as controllers evaluate it, and the controller's gain from it."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.identification.identified import damping_from_names
from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.rigid_body import ConfigError, coriolis_force
from dampest_ros.core.simulation.control import VelocityPI, tracking_rms
from dampest_ros.core.simulation.simulate import Simulator, track
from dampest_ros.io.yaml_io import load_vehicle


def test_force_matrix_and_std_from_names() -> None:
    v = load_vehicle("bluerov2_heavy")
    names = v.damping.parameter_names
    std = np.full(len(names), 0.1)
    m = Model(names, v.theta, std, v.body.M)  # structure rebuilt from the names
    nu = np.array([0.5, -0.2, 0.1, 0.3, 0.0, -0.4])
    # D(ν)ν for linear + quadratic diagonal terms: (X_u + X_uu|u|) u, …
    lin, quad = v.theta[:6], v.theta[6:]
    np.testing.assert_allclose(m.damping_force(nu), (lin + quad * np.abs(nu)) * nu)
    np.testing.assert_allclose(m.D(nu), np.diag(lin + quad * np.abs(nu)))
    # σ of D(ν)ν with independent parameters: √(σ² u² + σ² u⁴)
    np.testing.assert_allclose(m.damping_force_std(nu), 0.1 * np.sqrt(nu**2 + nu**4))
    np.testing.assert_allclose(m.feedforward(nu), m.damping_force(nu)
                               + coriolis_force(v.body.M, nu))
    with pytest.raises(ConfigError, match="Y_vr"):
        damping_from_names(["X_u", "Y_vr"])


def tracking_rms_60s(feedforward: bool) -> float:
    """Velocity PI (bandwidth 1 rad/s) tracking sines in surge, heave and yaw for 60 s."""
    v = load_vehicle("bluerov2_heavy")
    model = Model(v.damping.parameter_names, v.theta, np.zeros(12), v.body.M)
    ctrl = VelocityPI.for_vehicle(v, 1.0, model.feedforward if feedforward else None)
    t = 0.02 * np.arange(3000)
    ref = np.zeros((3000, 6))
    ref[:, [0, 2, 5]] = [0.5, 0.2, 0.4] * np.sin(np.outer(t, [0.3, 0.2, 0.25]))
    nu = track(Simulator(v, dt=0.02, record=False), ctrl, ref, 0.02)
    return tracking_rms(ref, nu, [0, 2, 5], skip=500)


def test_feedforward_from_the_model_improves_tracking() -> None:
    pid, ff = tracking_rms_60s(False), tracking_rms_60s(True)
    print(f"\nvelocity tracking RMS: PI {pid:.4f}, PI + D(ν)ν + C(ν)ν {ff:.4f}")
    assert ff < 0.5 * pid


@pytest.mark.parametrize("switches", [
    {"inertial": False, "coriolis": True, "munk": True},    # MuJoCo's plant
    {"inertial": True, "coriolis": True, "munk": False},    # no Munk moments
    {"inertial": True, "coriolis": False, "munk": False},   # no C_A at all
])
def test_coriolis_force_honours_the_added_mass_switches(switches: dict[str, bool]) -> None:
    """C(ν)ν and the feed-forward of a Model with M_A and the switches equal the
    core RigidBody's to 1e-12 (the Munk moment is N = (Y_v̇ − X_u̇) u v, big at these speeds).
    """
    from dataclasses import replace

    from dampest_ros.core.physics.rigid_body import AddedMassTerms

    v = load_vehicle("torpedo_auv")
    terms = AddedMassTerms(**switches)
    body = replace(v.body, added_mass_terms=terms)
    nu = np.random.default_rng(4).normal(0.0, [1.0, 0.5, 0.4, 0.6, 0.5, 0.7], (50, 6))
    m = Model(v.damping.parameter_names, v.theta, np.zeros(v.theta.size), body.M,
              damping=v.damping, M_A=body.added_mass, added_mass_terms=terms)
    scale = float(np.abs(body.coriolis_force(nu)).max())
    np.testing.assert_allclose(m.coriolis_force(nu), body.coriolis_force(nu), rtol=0,
                               atol=1e-12 * scale)
    np.testing.assert_allclose(m.feedforward(nu), m.damping_force(nu) + body.coriolis_force(nu),
                               rtol=0, atol=1e-12 * scale)
    # the velocity switches matter: the full C(ν)ν differs by far more than the tolerance
    # (inertial acts on ν̇ only: C(ν)ν is the full one)
    gap = np.abs(coriolis_force(body.M, nu) - m.coriolis_force(nu)).max()
    assert gap > 1e6 * 1e-12 * scale if not terms.munk else gap < 1e-12 * scale
    # switches that turn an effect off need M_A
    with pytest.raises(ConfigError, match="M_A"):
        Model(v.damping.parameter_names, v.theta, np.zeros(v.theta.size), body.M,
              damping=v.damping, added_mass_terms=terms)
