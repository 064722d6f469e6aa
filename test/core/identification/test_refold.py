"""Terms a format cannot carry, refitted onto entries it can over the flown envelope
(dampest_ros.core.identification.refold)."""

from __future__ import annotations

import numpy as np

from dampest_ros.core.identification.refold import all_entries, diagonal_entries, refold
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.point_drag import PointSpec, point_term
from dampest_ros.core.physics.terms import quadratic_term

FLOWN = np.array([[-0.8, -0.4, -0.5, -0.6, -0.6, -0.7], [1.2, 0.4, 0.5, 0.6, 0.6, 0.7]])


def test_a_normal_drag_at_the_origin_is_one_diagonal_entry() -> None:
    """drag.uu@(0,0,0) = 12 is F_x = −12 |u| u: the diagonal entry u|u| takes it exactly
    (the quadratic X_uu beside it is not refolded)."""
    model = DampingModel([quadratic_term(), point_term([PointSpec((0.0, 0.0, 0.0), 0,
                                                                  "normal")])])
    theta = np.r_[np.full(6, 5.0), 12.0]
    which = np.r_[np.zeros(6, dtype=bool), True]
    r = refold(model, theta, which, FLOWN, diagonal_entries())
    assert r.entries == [(0, 0, 0)]
    np.testing.assert_allclose(r.values, [12.0], rtol=1e-12)
    assert r.share[0] == 1.0 and np.isnan(r.share[1:]).all() and r.rms[0] < 1e-12


def test_an_off_centre_drag_needs_the_cross_entries() -> None:
    """drag.v|U|@(0.5,0,0) = 20, a fin at the stern: a sway force on the fin's own speed and
    a yaw moment 0.5 × that force. The diagonal entries reproduce 50 % of the sway force's
    square and 40 % of the yaw moment's; every entry 98.7 % of both."""
    model = DampingModel([point_term([PointSpec((0.5, 0.0, 0.0), 1, "|U|")])])
    which = np.ones(1, dtype=bool)
    diagonal = refold(model, np.array([20.0]), which, FLOWN, diagonal_entries())
    full = refold(model, np.array([20.0]), which, FLOWN, all_entries())
    assert np.isnan(full.share[[0, 2, 3, 4]]).all()  # no surge, heave, roll or pitch force
    assert 0.45 < diagonal.share[1] < 0.6 and 0.35 < diagonal.share[5] < 0.5, diagonal.share
    assert full.share[1] > 0.985 and full.share[5] > 0.985, full.share
    # the yaw moment is the sway force times the lever arm: the same share, half the miss
    np.testing.assert_allclose(full.share[5], full.share[1], rtol=1e-9)
    np.testing.assert_allclose(full.rms[5], 0.5 * full.rms[1], rtol=1e-9)
