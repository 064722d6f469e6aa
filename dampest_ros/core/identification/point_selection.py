"""Which element drags at points of the body the data support (the ``point`` term).

An element drag (:mod:`dampest_ros.core.physics.point_drag`) has one coefficient acting in a
force and two moments at once, so it cannot be searched row by row like the library's
single-entry terms (:mod:`.selection`). It is searched first, on top of the base model and
before the library (physically named terms first), by the same rules: a greedy forward path over the
candidates, each step the candidate with the least held-out error of the blocked
cross-validation (contiguous time folds apart by a guard, :mod:`.cv_budget`). The six rows are
fitted together with weights 1 / Σ y_i², so the error is Σ_i RSS_i / TSS_i, the unexplained
shares of the six DOFs (N and N·m weigh alike), and a coefficient fits all the rows it acts in
at once. The path is cut as the library search cuts each row's, at the one-standard-error size
of a DOF's own held-out errors along it: the largest of the six, so that a drag stays while
one DOF gains more than its standard error from it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.cv_budget import (
    GUARD_PERIODS,
    fold_errors,
    fold_fits,
    one_se_size,
)
from dampest_ros.core.identification.regression import NormalEquations, accumulate
from dampest_ros.core.physics.damping import TERM_KINDS, DampingModel
from dampest_ros.core.physics.point_drag import PointSpec, point_spec, point_term
from dampest_ros.core.physics.rigid_body import RigidBody
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]


@dataclass
class PointSelection:
    """Result of :func:`select_points`.

    Attributes
    ----------
    model : DampingModel
        The base with the element drags kept (in the order they entered).
    chosen : list of PointSpec
        The element drags kept.
    r2 : tuple of two ndarrays, shape (6,)
        Held-out R² per DOF of the base and of ``model`` (the rows fitted together).
    tss : ndarray, shape (6,)
        Σ y² per DOF of the low-passed target (held-out R² = 1 − CV / tss).
    path : list of (str, float, float)
        The base (``base``), then each candidate as it entered (the kept ones first), with
        the held-out error Σ_i CV_i / TSS_i after it and its standard error.
    """

    model: DampingModel
    chosen: list[PointSpec]
    r2: tuple[FloatArray, FloatArray]
    tss: FloatArray
    path: list[tuple[str, float, float]]


def with_points(base: DampingModel, points: Sequence[PointSpec]) -> DampingModel:
    """``base`` with the element drags ``points`` added to its ``point`` term (made if none)."""
    if not points:
        return base
    terms = {t.kind: t for t in base.terms}
    old = terms.get("point")
    terms["point"] = point_term([*(point_spec(b) for b in (old.bases if old else [])), *points])
    return DampingModel([terms[k] for k in TERM_KINDS if k in terms])


def select_points(samples: Samples, base: DampingModel, body: RigidBody,
                  candidates: Sequence[PointSpec], cutoff: float, folds: int = 5
                  ) -> PointSelection:
    """The element drags among ``candidates`` the data support on top of ``base`` (module
    docstring).

    Parameters
    ----------
    samples : Samples
    base : DampingModel
        Terms always kept.
    body : RigidBody
    candidates : sequence of PointSpec
        Simplest first: among sizes the data cannot tell apart, the path's order decides.
    cutoff : float
        Parallel low-pass of the regression (Hz).
    folds : int
        Contiguous time folds of the cross-validation.

    Returns
    -------
    PointSelection
    """
    names = set(base.parameter_names)
    candidates = [c for c in candidates if c.label not in names]
    model = with_points(base, candidates)
    guard = round(GUARD_PERIODS * samples.rate / cutoff) if cutoff > 0 else 0
    ne = accumulate(samples, model, body, folds=folds, cutoff=cutoff, guard=guard)
    index = {n: k for k, n in enumerate(model.parameter_names)}
    base_cols = [index[n] for n in base.parameter_names]
    cand_cols = [index[c.label] for c in candidates]
    tss = np.maximum(ne.c.sum(0), 1e-300)
    # the six rows together, each weighted by 1 / TSS_i: Σ_i RSS_i / TSS_i
    A = np.einsum("fipq,i->fpq", ne.A, 1.0 / tss)
    b = np.einsum("fip,i->fp", ne.b, 1.0 / tss)
    c = ne.c @ (1.0 / tss)
    chosen: list[int] = []
    errors = [fold_errors(A, b, c, base_cols)]
    pool = list(range(len(candidates)))
    while pool:
        trial = [fold_errors(A, b, c, [*base_cols, *(cand_cols[k] for k in chosen),
                                       cand_cols[k]]) for k in pool]
        best = int(np.argmin([e.sum() for e in trial]))
        if trial[best].sum() >= errors[-1].sum():
            break
        chosen.append(pool.pop(best))
        errors.append(trial[best])
    path = [(name, float(e.sum()), float(np.sqrt(len(e)) * np.std(e, ddof=1)))
            for name, e in zip(["base", *(candidates[k].label for k in chosen)], errors,
                               strict=True)]
    # each DOF's held-out errors per fold along the path, shape (K + 1, F, 6)
    rows = np.array([_row_fold_errors(ne, A, b, [*base_cols, *(cand_cols[k] for k in chosen[:j])])
                     for j in range(len(chosen) + 1)])
    # a drag stays while one DOF gains more than its own standard error from it
    kept = [candidates[k] for k in chosen[:max(one_se_size(rows[:, :, i]) for i in range(6))]]
    r2 = (1.0 - rows[0].sum(0) / tss, 1.0 - rows[len(kept)].sum(0) / tss)
    return PointSelection(with_points(base, kept), kept, r2, tss, path)


def _row_fold_errors(ne: NormalEquations, A: FloatArray, b: FloatArray, cols: Sequence[int]
                     ) -> FloatArray:
    """Held-out residual sum of squares per fold and row of the joint fit on ``cols``, each
    fold predicted from the others, shape (F, 6).

    Parameters
    ----------
    ne : NormalEquations
        Per-fold, per-row normal equations.
    A, b : ndarray, shapes (F, p, p) and (F, p)
        The rows' weighted sum, whose fit on the other folds predicts each fold.
    cols : sequence of int
    """
    S = np.asarray(cols, dtype=np.int64)
    out = np.array(ne.c, dtype=float)
    for f, theta in enumerate(fold_fits(A, b, S)):
        # ‖y_i − Φ_i θ‖² on fold f = c_i − 2 b_iᵀθ + θᵀA_iθ, every row i
        Af, bf = ne.A[f][:, S][:, :, S], ne.b[f][:, S]
        out[f] += -2.0 * bf @ theta + np.einsum("p,ipq,q->i", theta, Af, theta)
    return out
