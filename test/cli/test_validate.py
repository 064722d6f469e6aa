"""dampest validate: the per-sample forces of a model with fluid memory (the CLI itself is
tested on seeded simulations in test_logs.py)."""

from __future__ import annotations

import numpy as np

from dampest_ros.cli.validate import model_forces
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.terms import linear_term, memory_term
from dampest_ros.core.signals.preprocess import zero_phase
from dampest_ros.core.signals.samples import Samples
from dampest_ros.io.yaml_io import load_vehicle


def test_memory_goes_to_hydro_not_to_damping() -> None:
    body = load_vehicle("bluerov2_heavy").body
    rng = np.random.default_rng(4)
    n = 2000
    t = np.arange(n) / 50.0
    nu = np.column_stack([0.4 * np.sin(0.5 * t + k) for k in range(6)])
    s = Samples(t, nu, rng.normal(size=(n, 6)), rng.normal(size=(n, 6)) * 20,
                rng.normal(size=(n, 3)) * 0.1, np.ones(n), np.zeros(n, dtype=np.int64))
    model = DampingModel([linear_term(), memory_term({"u": [1.5]})])
    theta = np.r_[np.arange(1.0, 7.0), 30.0]  # X_u..N_r = 1..6, memory gain c = 30 on u
    f = model_forces(s, model, body, theta, cutoff=0.0)
    np.testing.assert_allclose(f["damping"], nu * np.arange(1.0, 7.0), rtol=1e-12)
    z = model.memory_states(t, nu)[:, 0]
    np.testing.assert_allclose(f["memory"][:, 0], 30.0 * z, rtol=1e-12)
    np.testing.assert_array_equal(f["memory"][:, 1:], 0.0)
    np.testing.assert_allclose(f["hydro"] - f["damping"] - f["memory"],
                               body.added_mass_force(nu, s.nu_dot), rtol=1e-9, atol=1e-9)
    # with a low-pass, the three stay consistent: hydro − damping − memory = LP(added mass)
    lp = model_forces(s, model, body, theta, cutoff=2.0)
    np.testing.assert_allclose(lp["hydro"] - lp["damping"] - lp["memory"],
                               zero_phase(body.added_mass_force(nu, s.nu_dot), 50.0, 2.0),
                               rtol=1e-9, atol=1e-9)
    # and the low-passed damping is D(ν)ν low-passed (linear term: D ν = diag(1..6) ν)
    np.testing.assert_allclose(lp["damping"], zero_phase(nu * np.arange(1.0, 7.0), 50.0, 2.0),
                               rtol=1e-6, atol=1e-6)
