"""Term constructors (dampest_ros.core.physics.terms) checked against independent forms."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import ConfigError, coriolis_force
from dampest_ros.core.physics.terms import coriolis_term
from dampest_ros.core.physics.vehicle import damping_from_spec


def test_the_coriolis_term_is_fossens_added_mass_coriolis_of_its_corrections() -> None:
    """Its force is C(ν)ν of M = diag(δA, 0) (rigid_body.coriolis_force, which shares no code
    with the term), its regressor reproduces it, and it does no work."""
    model = DampingModel([coriolis_term()])
    theta = np.array([-40.0, -35.0, 12.0])  # kg
    nu = np.random.default_rng(3).normal(size=(200, 6))
    M = np.zeros((6, 6))
    M[:3, :3] = np.diag(theta)
    np.testing.assert_allclose(model.force(nu, theta), coriolis_force(M, nu), atol=1e-12)
    np.testing.assert_allclose(np.einsum("nip,p->ni", model.regressor(nu), theta),
                               coriolis_force(M, nu), atol=1e-12)
    assert np.abs(model.dissipation(nu, theta)).max() < 1e-12
    # isotropic: MuJoCo's Magnus lift, a force κ ω × v on the body and no moment
    kappa = 40.0
    f = model.force(nu, np.full(3, -kappa))
    np.testing.assert_allclose(-f[:, :3], kappa * np.cross(nu[:, 3:], nu[:, :3]), atol=1e-12)
    np.testing.assert_allclose(f[:, 3:], 0.0, atol=1e-12)


def test_a_vehicle_file_names_the_corrections_it_has() -> None:
    model, theta = damping_from_spec({"linear": {"X_u": 1.0},
                                      "coriolis": {"coriolis.m_w": -3.0}})
    assert model.parameter_names == ["X_u", "coriolis.m_w"]
    assert theta.tolist() == [1.0, -3.0]
    with pytest.raises(ConfigError, match=r"coriolis\.m_u, coriolis\.m_v, coriolis\.m_w"):
        damping_from_spec({"coriolis": {"coriolis.m_p": 1.0}})
