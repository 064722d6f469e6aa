"""The regression's chunked passes (dampest_ros.core.identification.regression): the entries
of Φ kept between passes over the same samples are those a fresh pass forms, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.identification.regression import accumulate, iter_entries
from dampest_ros.core.physics.alpha import Alpha
from dampest_ros.core.physics.damping import Basis, DampingModel, DampingTerm, unit
from dampest_ros.core.physics.directions import BODY_AXES
from dampest_ros.core.physics.point_drag import point_library, point_term
from dampest_ros.core.physics.point_lift import lift_basis, magnus_basis
from dampest_ros.core.physics.terms import (
    coriolis_term,
    cross_term,
    library,
    linear_term,
    quadratic_term,
)
from dampest_ros.io.yaml_io import load_vehicle
from test.core.identification.test_selection import RATE, smooth, synthetic


def test_entries_kept_between_passes_are_a_fresh_passs_to_the_bit() -> None:
    """Models sharing parameters in every way a structure search and its fit pass over one
    log: the library's single entries, the added-mass corrections (several atoms each) and
    element drags (|wᵀν| α, one matrix product in a model's α: a one-column product rounds
    otherwise, so a model's single drag and a drag new among kept ones are the cases). Each pass
    gives what the model's own entries low-passed afresh give, decimated or not, and the
    normal equations are those of the first pass over the same model."""
    body = load_vehicle("bluerov2_heavy").body
    rng = np.random.default_rng(5)
    nu = smooth(rng, int(60 * RATE), np.array([0.3, 0.2, 0.2, 0.3, 0.3, 0.3]), 0.5)
    base = [linear_term(), quadratic_term(), coriolis_term()]
    samples = synthetic(body, nu, DampingModel(base[:2]).force(nu, np.ones(12)), 0.01, seed=1)
    drags = point_library([((0.3, 0.0, 0.2), BODY_AXES), ((0.0, -0.3, 0.21), BODY_AXES)])
    names = DampingModel(base).parameter_names
    cross = [sp for sp in library() if sp.label not in names][::25]

    def model(points: list[int], specs: slice) -> DampingModel:
        terms: list[DampingTerm] = [*base, *([cross_term(cross[specs])] if cross[specs] else [])]
        return DampingModel(terms + ([point_term([drags[k] for k in points])] if points else []))

    models = [model([6, 8], slice(0, 8)), model([6, 8, 10], slice(2, 12)), model([6], slice(4, 16)),
              model(list(range(len(drags))), slice(0, 16)), model([], slice(0, 0))]
    first = accumulate(samples, models[2], body, cutoff=2.0)
    for decimate in (True, False):
        for m in models:
            # then ν offset along each axis, as the sensor-bias refits take it
            for offset in [None, *(0.01 * np.eye(6))]:
                kept = list(iter_entries(samples, m, body, cutoff=2.0, decimate=decimate,
                                         offset=offset))
                fresh = list(iter_entries(samples, m, body, cutoff=2.0, decimate=decimate,
                                          offset=offset, entries=m.regressor_entries))
                assert len(kept) == len(fresh)
                for (rows, X, y), (rows_f, X_f, y_f) in zip(kept, fresh, strict=True):
                    assert np.array_equal(np.asarray(rows), np.asarray(rows_f))
                    assert X.tobytes() == X_f.tobytes() and y.tobytes() == y_f.tobytes()
    again = accumulate(samples, models[2], body, cutoff=2.0)
    assert again.A.tobytes() == first.A.tobytes() and again.b.tobytes() == first.b.tobytes()


KINDS = [Alpha("one"), Alpha("abs", 5), Alpha("lin", 1), Alpha("prod", 0, 4),
         Alpha("absprod", 2, 3), Alpha("norm"), Alpha("anorm"), Alpha("pnorm", 1, 2),
         Alpha("area", 4), Alpha("area", 1, 2), Alpha("absproj", w=(0.6, 0, 0.8, 0, 0, 0)),
         Alpha("pspeed", w=(0.3, 0.0, 0.2)), Alpha("pshare", w=(0.3, 0.0, 0.2, 0.0, 1.0, 0.0))]


@pytest.mark.parametrize("basis", [Basis(f"b{k}", unit(k % 6, (2 * k + 1) % 6), a)
                                   for k, a in enumerate(KINDS)]
                         + [lift_basis("lift", (0.3, 0.1, 0.2), np.eye(3)[0]),
                            magnus_basis("magnus", (0.3, 0.1, 0.2))]
                         + list(coriolis_term().bases), ids=lambda b: b.name)
def test_a_column_reads_the_components_of_nu_it_says(basis: Basis) -> None:
    """Offsetting a component of ν that a parameter's column does not read leaves the column
    the same numbers (what lets a bias refit take the kept entries); one it reads changes
    it."""
    model = DampingModel([DampingTerm("point", "", [basis])])
    nu = np.random.default_rng(2).normal(size=(200, 6))
    X = model.regressor(nu)
    for k in range(6):
        moved = model.regressor(nu + 0.01 * np.eye(6)[k])
        assert np.array_equal(moved, X) == (k not in basis.reads), k
