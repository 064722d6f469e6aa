"""The element drag search (dampest_ros.core.identification.point_selection) on data with a
known drag at a point of the body."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from dampest_ros.core.identification import selection
from dampest_ros.core.identification.point_selection import EntryRules, select_points
from dampest_ros.core.identification.regression import accumulate
from dampest_ros.core.identification.selection import select_terms
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.directions import BODY_AXES
from dampest_ros.core.physics.point_drag import PointSpec, point_library, point_term
from dampest_ros.core.physics.rigid_body import RigidBody
from dampest_ros.core.physics.terms import CrossSpec, cross_term, linear_term, quadratic_term
from dampest_ros.core.signals.samples import Samples
from dampest_ros.io.yaml_io import load_vehicle
from test.core.identification.test_selection import RATE, smooth, synthetic

#: The element of the truth: a skid 0.3 m forward and 0.2 m below the origin, heave drag.
TRUTH = PointSpec((0.3, 0.0, 0.2), 2)
POINTS = [(0.3, 0.0, 0.2), (0.0, -0.3, 0.21), (-0.2, 0.1, -0.1)]


def drag_at_a_point() -> tuple[RigidBody, DampingModel, Samples]:
    """Body, base (linear + quadratic) and 120 s of samples, 1 % noise, seeded, of the base
    plus a heave drag of 60 N s²/m² at :data:`TRUTH`."""
    body = load_vehicle("bluerov2_heavy").body
    rng = np.random.default_rng(11)
    nu = smooth(rng, int(120 * RATE), np.array([0.3, 0.2, 0.2, 0.3, 0.3, 0.3]), 0.5)
    base = DampingModel([linear_term(), quadratic_term()])
    base_theta = np.r_[[10.0, 12.0, 15.0, 1.0, 1.0, 1.0], [40.0, 50.0, 60.0, 2.0, 2.0, 2.0]]
    law = base.force(nu, base_theta) \
        + DampingModel([point_term([TRUTH])]).force(nu, np.array([60.0]))
    samples = synthetic(body, nu, law, 0.01, seed=3)
    return body, base, samples


def test_the_drag_at_its_point_is_found_first_and_alone() -> None:
    """Linear + quadratic drag and a heave drag of 60 N s²/m² at (0.3, 0, 0.2) m (heave and
    pitch), 120 s, 1 % noise, seeded: of 18 candidates at three points the search keeps the
    true one only, which lifts the held-out R² of Z and M from below 0.99 to above 0.999; its
    least-squares coefficient is within 2 % of 60."""
    body, base, samples = drag_at_a_point()
    found = select_points(samples, base, body, point_library([(p, BODY_AXES) for p in POINTS]), 2.0,
                          EntryRules(10.0, 2.0 * 2.0 * 120.0))
    assert found.chosen == [TRUTH]
    before, after = found.r2
    assert before[[2, 4]].max() < 0.99 and after[[2, 4]].min() > 0.999, (before, after)
    ne = accumulate(samples, found.model, body, cutoff=2.0)
    A, b, _ = ne.total(1.0 / ne.c.sum(0))
    theta = np.linalg.solve(A, b)
    assert abs(theta[-1] - 60.0) < 1.2, theta[-1]


def test_a_term_that_made_up_for_a_pruned_drag_goes_with_it() -> None:
    """Linear + quadratic drag and a sway–yaw coupling Y_v|r| = 60 (no element drag), 300 s,
    2 % noise, seeded: the sway drags at (0, ±0.625, 0) stand in for Y_v|r| and enter first,
    the library's Y_vr then makes them weak and they go. The library searched again without
    them adds Y_vr alone (searched only beside them it also kept Y_vU, which had entered to
    make up for their speed-dependent part), whose least-squares value is within 2 % of 60."""
    body = load_vehicle("bluerov2_heavy").body
    rng = np.random.default_rng(12)
    nu = smooth(rng, int(300 * RATE), np.array([0.2, 0.3, 0.2, 0.1, 0.1, 0.5]), 0.5)
    base = DampingModel([linear_term(), quadratic_term()])
    base_theta = np.r_[[10.0, 12.0, 15.0, 1.0, 1.0, 1.0], [40.0, 50.0, 60.0, 2.0, 2.0, 2.0]]
    coupling = DampingModel([cross_term([CrossSpec.from_dict(
        {"row": "Y", "col": "v", "alpha": "|r|"})])])
    law = base.force(nu, base_theta) + coupling.force(nu, np.array([60.0]))
    samples = synthetic(body, nu, law, 0.02, seed=3)
    points = [((0.0, 0.625, 0.0), BODY_AXES), ((0.0, -0.625, 0.0), BODY_AXES),
              ((0.0, 0.0, 0.625), BODY_AXES), ((0.0, 0.0, -0.625), BODY_AXES)]
    sel = select_terms(samples, base, body, memory_dofs=(), points=point_library(points))
    assert sel.points is not None
    assert sorted(sel.points.pruned) == ["drag.v|U|@(0,-0.625,0)", "drag.v|U|@(0,0.625,0)"]
    assert sel.model.parameter_names == [*base.parameter_names, "Y_vr"]
    ne = accumulate(samples, sel.model, body, cutoff=2.0)
    A, b, _ = ne.total(1.0 / ne.c.sum(0))
    theta = np.linalg.solve(A, b)
    assert abs(theta[-1] - 60.0) < 1.2, theta[-1]


def test_a_mirror_pair_enters_together_where_neither_twin_passes_alone() -> None:
    """A hull's heave drag of 150 N s²/m² at (0, 0, −0.1) m and a pair of pontoons' of 60
    each at (0, ±0.3, 0.05) m, strong heave and little roll (RMS 0.4 m/s and 0.05 rad/s), 120
    s, 2 % noise, seeded. Once the hull's drag carries the heave, a pontoon alone adds a roll
    moment y·Z tied to a heave force the data do not want, and neither lowers BIC by 10 (the
    search judging twins one at a time kept the hull's alone: roll R² .391); the pair, offered
    as one step, enters first and the hull's after it, roll R² > .9999, each coefficient within
    2 % of its truth."""
    body = load_vehicle("bluerov2_heavy").body
    hull, port, stbd = (0.0, 0.0, -0.1), (0.0, -0.3, 0.05), (0.0, 0.3, 0.05)
    rng = np.random.default_rng(21)
    nu = smooth(rng, int(120 * RATE), np.array([0.3, 0.2, 0.4, 0.05, 0.15, 0.3]), 0.5)
    base = DampingModel([linear_term(), quadratic_term()])
    base_theta = np.r_[[10.0, 12.0, 15.0, 1.0, 1.0, 1.0], [40.0, 50.0, 20.0, 2.0, 2.0, 2.0]]
    truth = [PointSpec(port, 2), PointSpec(stbd, 2), PointSpec(hull, 2)]
    law = base.force(nu, base_theta) \
        + DampingModel([point_term(truth)]).force(nu, np.array([60.0, 60.0, 150.0]))
    samples = synthetic(body, nu, law, 0.02, seed=3)
    found = select_points(samples, base, body,
                          point_library([(p, BODY_AXES) for p in (hull, port, stbd)]), 2.0,
                          EntryRules(10.0, 2.0 * 2.0 * 120.0))
    assert found.chosen == truth and found.steps == 2
    assert found.path[1][0] == "drag.w|U|@(0,-0.3,0.05) + drag.w|U|@(0,0.3,0.05)"
    before, after = found.r2
    assert before[3] < 0.4 and after[3] > 0.9999, (before, after)
    ne = accumulate(samples, found.model, body, cutoff=2.0)
    A, b, _ = ne.total(1.0 / ne.c.sum(0))
    theta = np.linalg.solve(A, b)[-3:]
    np.testing.assert_allclose(theta, [60.0, 60.0, 150.0], rtol=0.02)



def test_the_library_search_beside_kept_element_forces_takes_the_lower_entry_share(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The data of the first test (a heave drag at a point, found and kept): the library
    search beside it takes ``MIN_ERR_BESIDE_ELEMENTS`` (2 %); without candidate points, or
    when none is kept, ``MIN_ERR`` (5 %)."""
    body, base, samples = drag_at_a_point()
    shares: list[float] = []
    search = selection._search_beside_shared

    def spy(samples: Samples, base: DampingModel, body: RigidBody, options: dict[str, Any],
            start: DampingModel | None) -> selection.Selection:
        shares.append(options["min_err"])
        return search(samples, base, body, options, start)

    monkeypatch.setattr(selection, "_search_beside_shared", spy)
    sel = select_terms(samples, base, body, memory_dofs=(),
                       points=point_library([(p, BODY_AXES) for p in POINTS]))
    assert sel.points is not None and sel.points.chosen == [TRUTH]
    assert shares == [selection.MIN_ERR_BESIDE_ELEMENTS] == [0.02]
    shares.clear()
    select_terms(samples, base, body, memory_dofs=())
    # far from the truth's point, nothing is kept
    select_terms(samples, base, body, memory_dofs=(),
                 points=point_library([((-0.5, 0.0, -0.4), (BODY_AXES[0],))]))
    assert shares == [selection.MIN_ERR] * 2 == [0.05] * 2
