"""Which element drags at points of the body the data support (the ``point`` term).

An element drag (:mod:`dampest_ros.core.physics.point_drag`) has one coefficient acting in a
force and two moments at once, so it cannot be searched row by row like the library's
single-entry terms (:mod:`.selection`). It is searched first, on top of the base model and
before the library (physically named terms first), by the same rules: a greedy forward path
over the candidates, each step the candidate with the least held-out error of the blocked
cross-validation (contiguous time folds apart by a guard, :mod:`.cv_budget`). The six rows are
fitted together with weights 1 / Σ y_i², so the error is Σ_i RSS_i / TSS_i, the unexplained
shares of the six DOFs (N and N·m weigh alike), and a coefficient fits all the rows it acts in
at once. A candidate enters only when, in a DOF it acts in, it lowers BIC by more than 10
(the library's test, :class:`EntryRules`; its 5 % share of the residual, which judges one
row's term, would stop the drags that each take a little from several DOFs). The path is cut
as the library search cuts each row's, at the one-standard-error size of a DOF's own held-out
errors along it: the largest of the six, so that a drag stays while one DOF gains more than
its standard error. Once the library terms have joined, a drag that no longer passes the test
it entered by goes (:func:`weak_points`), as the library search's backward step takes out a
weak term: a pair of drags at the bow and the stern stands in for a yaw cross-flow drag
N ∝ r|v| until the library's own N_rv enters. The library is then searched again without it
(:func:`.selection.select_terms`): a term that entered only to make up for a drag's side
effect (the roll moment of a sway drag above the origin) does not outlive the drag.

A drag and its mirror image across the xz plane (:func:`~dampest_ros.core.physics.point_drag.
mirror_pairs`: pontoons, skids, floats at ± y) are also offered as one step, both entering
together, each with its own coefficient, the test charging BIC for two (k log n_eff, k = 2).
Alone, a drag off the centre line ties its moment to its force (a heave drag at y gives the
roll moment y·Z), so where the heave is already explained its roll gain is paid for in heave and
neither twin may pass; together their sum carries the force and their difference the moment,
as the two elements of a symmetric vehicle do (MuJoCo sled_auv, seed 3: each pontoon's heave
drag alone lowered BIC nowhere, the pair lowered it by 92 in Z and 101 in K). The pair is one
step of the path and of its one-standard-error cut, and twins both in the model stay or go
together (:func:`weak_points`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.cv_budget import (
    GUARD_PERIODS,
    first_best,
    fold_errors,
    fold_fits,
    one_se_size,
    scaled_lstsq,
)
from dampest_ros.core.identification.regression import NormalEquations, accumulate
from dampest_ros.core.physics.damping import TERM_KINDS, DampingModel
from dampest_ros.core.physics.point_drag import (
    PointSpec,
    mirror_pairs,
    point_spec,
    point_term,
)
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
    steps : int
        The steps of the path kept (a mirror pair that entered together is one).
    r2 : tuple of two ndarrays, shape (6,)
        Held-out R² per DOF of the base and of ``model`` (the rows fitted together).
    tss : ndarray, shape (6,)
        Σ y² per DOF of the low-passed target (held-out R² = 1 − CV / tss).
    path : list of (str, float, float)
        The base (``base``), then each step as it entered (the kept ones first: a drag, or a
        mirror pair ``a + b``), with the held-out error Σ_i CV_i / TSS_i after it and its
        standard error.
    pruned : list of str
        The kept drags taken out once the library terms joined (:func:`weak_points`), the
        library searched again without them.
    """

    model: DampingModel
    chosen: list[PointSpec]
    steps: int
    r2: tuple[FloatArray, FloatArray]
    tss: FloatArray
    path: list[tuple[str, float, float]]
    pruned: list[str] = field(default_factory=list)


def with_points(base: DampingModel, points: Sequence[PointSpec]) -> DampingModel:
    """``base`` with the element drags ``points`` added to its ``point`` term (made if none)."""
    if not points:
        return base
    terms = {t.kind: t for t in base.terms}
    old = terms.get("point")
    terms["point"] = point_term([*(point_spec(b) for b in (old.bases if old else [])), *points])
    return DampingModel([terms[k] for k in TERM_KINDS if k in terms])


@dataclass(frozen=True)
class EntryRules:
    """The test a candidate passes to enter the path, the library search's BIC test
    (:mod:`.selection`): in at least one DOF it acts in, it lowers BIC by more than
    ``min_improvement``, with ``n_eff`` independent samples and its number of coefficients
    (2 for a mirror pair)."""

    min_improvement: float
    n_eff: float

    def passed(self, rss_without: FloatArray, rss_with: FloatArray, k: int = 1) -> bool:
        """Whether a DOF's in-sample RSS, shape (6,) each, falls by the test's margin when
        ``k`` coefficients join."""
        ratio = np.maximum(rss_with, 1e-300) / np.maximum(rss_without, 1e-300)
        # ΔBIC of the row = n_eff log(RSS_with / RSS_without) + k log n_eff
        dbic = self.n_eff * np.log(ratio) + k * np.log(self.n_eff)
        return bool(np.any(dbic < -self.min_improvement))


def select_points(samples: Samples, base: DampingModel, body: RigidBody,
                  candidates: Sequence[PointSpec], cutoff: float, rules: EntryRules,
                  folds: int = 5) -> PointSelection:
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
        Mirror pairs among them are also offered together (module docstring).
    cutoff : float
        Parallel low-pass of the regression (Hz).
    rules : EntryRules
        What a candidate must do to enter the path.
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
    groups = [(k,) for k in range(len(candidates))] + mirror_pairs(candidates)
    chosen, errors = _path(ne, (A, b, c), base_cols,
                           [[cand_cols[k] for k in g] for g in groups], rules)
    steps = [[candidates[k] for k in groups[g]] for g in chosen]
    path = [(name, float(e.sum()), float(np.sqrt(len(e)) * np.std(e, ddof=1)))
            for name, e in zip(["base", *(" + ".join(s.label for s in st) for st in steps)],
                               errors, strict=True)]
    # each DOF's held-out errors per fold along the path, shape (K + 1, F, 6)
    entered = [[cand_cols[k] for g in chosen[:j] for k in groups[g]]
               for j in range(len(chosen) + 1)]
    rows = np.array([_row_fold_errors(ne, A, b, [*base_cols, *cols]) for cols in entered])
    # a step stays while one DOF gains more than its own standard error from it
    size = max(one_se_size(rows[:, :, i]) for i in range(6))
    kept = [s for st in steps[:size] for s in st]
    r2 = (1.0 - rows[0].sum(0) / tss, 1.0 - rows[size].sum(0) / tss)
    return PointSelection(with_points(base, kept), kept, size, r2, tss, path)


def weak_points(samples: Samples, model: DampingModel, body: RigidBody, cutoff: float,
                rules: EntryRules) -> list[str]:
    """The element drags of ``model`` that no longer pass ``rules`` beside its other terms,
    taken out one at a time, the weakest (least BIC gained in its best DOF) first; a drag
    whose mirror image is also in the model is judged with it, the pair going together or
    not at all (the test charging for two).

    Returns
    -------
    list of str
        The names of the drags taken out, in that order.
    """
    point = model.term("point")
    if point is None:
        return []
    ne = accumulate(samples, model, body, cutoff=cutoff)
    tss = np.maximum(ne.c.sum(0), 1e-300)
    A, b = np.einsum("fipq,i->fpq", ne.A, 1.0 / tss), np.einsum("fip,i->fp", ne.b, 1.0 / tss)
    names = model.parameter_names
    cols = list(range(len(names)))
    drags = [names.index(n) for n in point.parameter_names]
    pairs = mirror_pairs([point_spec(basis) for basis in point.bases])
    twins = {k for pair in pairs for k in pair}
    units = [(drags[i], drags[j]) for i, j in pairs] \
        + [(k,) for n, k in enumerate(drags) if n not in twins]
    removed: list[str] = []
    tot = _Totals.of(ne, A, b)
    while units:
        rss = _row_rss(tot, cols)
        without = {u: _row_rss(tot, [j for j in cols if j not in u]) for u in units}
        weak = [u for u in units if not rules.passed(without[u], rss, len(u))]
        if not weak:
            break
        u = min(weak, key=lambda v: float((without[v] / np.maximum(rss, 1e-300)).max()))
        cols = [j for j in cols if j not in u]
        units.remove(u)
        removed += [names[k] for k in u]
    return removed


def _path(ne: NormalEquations, joint: tuple[FloatArray, FloatArray, FloatArray],
          base_cols: Sequence[int], groups: Sequence[Sequence[int]], rules: EntryRules
          ) -> tuple[list[int], list[FloatArray]]:
    """The greedy forward path: each step the group of candidates (a drag, or a mirror pair)
    that passes ``rules`` with the least joint held-out error, while that error falls; a group
    with a column already in is no longer offered.

    Parameters
    ----------
    ne : NormalEquations
        Per-fold, per-row normal equations of the base's and the candidates' columns.
    joint : tuple of ndarrays, shapes (F, p, p), (F, p), (F,)
        The rows' weighted sum.
    base_cols : sequence of int
        The base's columns.
    groups : sequence of sequence of int
        The columns of each step that may be offered.
    rules : EntryRules

    Returns
    -------
    chosen : list of int
        Indices into ``groups``, in the order they entered.
    errors : list of ndarray, shape (F,) each
        The joint held-out error per fold of the base, then after each step.
    """
    A, b, c = joint
    cols = list(base_cols)
    chosen: list[int] = []
    errors = [fold_errors(A, b, c, cols)]
    tot = _Totals.of(ne, A, b)
    rss = _row_rss(tot, cols)
    pool = list(range(len(groups)))
    while pool:
        fits = [(g, _row_rss(tot, [*cols, *groups[g]])) for g in pool]
        # the held-out errors of those that pass the entry test alone
        good = [(g, fold_errors(A, b, c, [*cols, *groups[g]]), r) for g, r in fits
                if rules.passed(rss, r, len(groups[g]))]
        if not good:
            break
        # the least joint held-out error, a tie (rounding) to the first offered
        g, e, r = good[first_best(np.array([float(t[1].sum()) for t in good]))]
        if e.sum() >= errors[-1].sum():
            break
        chosen.append(g)
        cols += groups[g]
        pool = [h for h in pool if not set(groups[h]) & set(groups[g])]
        errors.append(e)
        rss = r
    return chosen, errors


class _Totals(NamedTuple):
    """The normal equations summed over the folds: the rows' weighted sum (``A`` (p, p),
    ``b`` (p,)) and each row's (``rows_A`` (6, p, p), ``rows_b`` (6, p), ``rows_c`` (6,))."""

    A: FloatArray
    b: FloatArray
    rows_A: FloatArray
    rows_b: FloatArray
    rows_c: FloatArray

    @staticmethod
    def of(ne: NormalEquations, A: FloatArray, b: FloatArray) -> _Totals:
        """The sums over the folds of ``ne`` and of the weighted sum ``A``, ``b``."""
        return _Totals(A.sum(0), b.sum(0), ne.A.sum(0), ne.b.sum(0), ne.c.sum(0))


def _row_rss(tot: _Totals, cols: Sequence[int]) -> FloatArray:
    """In-sample residual sum of squares per row of the joint fit on ``cols`` over all folds,
    shape (6,)."""
    S = np.asarray(cols, dtype=np.int64)
    theta = scaled_lstsq(tot.A[S[:, None], S], tot.b[S])
    G, bv = tot.rows_A[:, S[:, None], S], tot.rows_b[:, S]
    # ‖y_i − Φ_i θ‖² = c_i − 2 b_iᵀθ + θᵀA_iθ, every row i
    return np.asarray(tot.rows_c - 2.0 * bv @ theta + np.einsum("p,ipq,q->i", theta, G, theta))


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
