"""The default structure: the base's terms, and library terms only in the DOFs where they
misfit (against a law known term by term, seeded)."""

from __future__ import annotations

import numpy as np

from dampest_ros.core.identification.misfit import misfit_terms
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.terms import linear_term, quadratic_term
from dampest_ros.io.yaml_io import load_vehicle
from test.core.identification.test_selection import RATE, smooth, synthetic

LINEAR = np.array([10.0, 12.0, 30.0, 1.0, 1.5, 2.0])
QUADRATIC = np.array([140.0, 210.0, 190.0, 1.2, 1.5, 1.5])


def law(nu: np.ndarray, hidden: bool) -> np.ndarray:
    """Linear + quadratic drag per DOF; with ``hidden`` also a lift Z ← 40 u·w and a yaw
    cross-flow drag N ← 8 r|v| the base lacks."""
    F = LINEAR * nu + QUADRATIC * np.abs(nu) * nu
    if hidden:
        F[:, 2] += 40.0 * nu[:, 0] * nu[:, 2]
        F[:, 5] += 8.0 * nu[:, 5] * np.abs(nu[:, 1])
    return F


def test_terms_are_added_only_where_the_base_misfits() -> None:
    """300 s of every DOF moving, 2 % noise: with the hidden terms Z and N misfit (held-out
    R² below 0.999 and over 3× the library's unexplained share) and exactly Z_uxw and N_rv
    are added there; without them nothing misfits and the base comes back unchanged."""
    body = load_vehicle("bluerov2_heavy").body
    n = int(300 * RATE)
    nu = smooth(np.random.default_rng(5), n, np.array([0.4, 0.3, 0.3, 0.3, 0.3, 0.4]), 0.3)
    base = DampingModel([linear_term(), quadratic_term()])
    found = misfit_terms(synthetic(body, nu, law(nu, True), 0.02, 6), base, body, 2.0)
    assert found is not None
    assert found.rows == [2, 5], (found.before, found.after)
    assert found.added == {2: ["Z_uxw"], 5: ["N_rv"]}
    assert set(found.model.parameter_names) == {*base.parameter_names, "Z_uxw", "N_rv"}
    assert all(found.ratio(i) > 3.0 for i in found.rows)
    clean = misfit_terms(synthetic(body, nu, law(nu, False), 0.02, 6), base, body, 2.0)
    assert clean is not None and clean.rows == [] and clean.added == {}
    assert clean.model is base
