"""Term selection: which damping terms do the data support?

The candidates are a library of named single-entry coefficients (:func:`terms.library`:
linear ν_j, cross-flow ν_j|ν_k|, bilinear ν_j ν_k, speed magnitude ν_j‖v‖ and ν_j‖ω‖ in every
force row) and fluid-memory states, on top of a base model whose terms are always kept:

1. For each memory candidate DOF, its rate λ is found by a profile search: the regression is
   linear in the gain c for a fixed λ, so RSS(λ) = min_c RSS(c, λ) is minimised over log λ
   (staged nonlinear least squares).
2. Every distinct regressor column of the library is one scalar feature g_k(ν) = α_k(ν) ν_j,
   the same in every force row. The normal equations of the features (and memory states)
   against the target of each row are accumulated once, per contiguous time fold
   (:func:`batch.accumulate`), so fitting, scoring and cross-validating any subset is a
   small matrix computation: trying a candidate costs no pass over data.
3. Columns that are zero in the data, or numerically equal (up to scale) to a column before
   them (|corr| > 1 − ``tol``; e.g. u|u| and u·u when u > 0 throughout, or u|u| and u‖v‖
   when only u moves), are dropped with the reason.
4. Greedy forward search over all rows at once: each step adds the candidate with the
   largest blocked cross-validated gain (held-out RSS of its row over the folds, each fold
   predicted from the others), provided it also lowers BIC by more than ``min_improvement``,
   removes at least ``min_err`` of its row's residual, and is not (to ``tol``) a combination
   of the columns already in its row; until no candidate qualifies (or the model has
   ``max_terms`` parameters, when a budget is given).
5. Without a budget, each row keeps the added terms up to the one-standard-error size of its
   cross-validation curve along the order they entered (:mod:`.cv_budget`); the folds are
   apart by a guard of two periods of the cutoff, so the low-pass leaks nothing across.

BIC = n_eff Σ_i log(RSS_i / N) + k log n_eff, with n_eff = 2 · cutoff · T the number of
independent samples in the low-passed regression. Each row's least squares is separate (a
library coefficient acts on one row only), so neither BIC nor the path depends on per-DOF
weights, nor on the prior's magnitudes, which it never sees.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.cv_budget import (
    GUARD_PERIODS,
    TIE_RTOL,
    first_best,
    fold_errors,
    guarded_folds,
    one_se_size,
    scaled_lstsq,
)
from dampest_ros.core.identification.memory_rates import MemoryEvidence, memory_evidence
from dampest_ros.core.identification.point_selection import (
    EntryRules,
    PointSelection,
    select_points,
    weak_points,
)
from dampest_ros.core.identification.quadratic import solve_normal
from dampest_ros.core.identification.regression import (
    NormalEquations,
    accumulate,
    information_criteria,
    iter_entries,
    total_sum_of_squares,
)
from dampest_ros.core.physics.alpha import Alpha, AlphaBank
from dampest_ros.core.physics.damping import TERM_KINDS, Basis, DampingModel, DampingTerm
from dampest_ros.core.physics.point_drag import PointSpec
from dampest_ros.core.physics.rigid_body import DOF_NAMES, ConfigError, RigidBody
from dampest_ros.core.physics.terms import (
    FAMILIES,
    CrossSpec,
    cross_term,
    library,
    library_name,
    memory_term,
)
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]

#: Common couplings of a box- or torpedo-shaped vehicle: sway–yaw and heave–pitch damping
#: cross terms and the surge–heave lift (Fossen 2011, §6.4; SNAME names, |x| as in X_uu).
#: The gap search's cross candidates; selection searches the whole :func:`terms.library`.
DEFAULT_CROSS = (
    {"row": "Y", "col": "v", "alpha": "|r|"}, {"row": "Y", "col": "r", "alpha": "|v|"},
    {"row": "N", "col": "v", "alpha": "|r|"}, {"row": "N", "col": "r", "alpha": "|v|"},
    {"row": "Z", "col": "w", "alpha": "|q|"}, {"row": "M", "col": "q", "alpha": "|w|"},
    {"row": "Z", "col": "w", "alpha": "|u|"}, {"row": "M", "col": "w", "alpha": "u"},
    {"row": "Y", "col": "r", "alpha": "1"}, {"row": "N", "col": "v", "alpha": "1"},
)


@dataclass
class SelectionStep:
    """One row of the selection table: the model after adding ``added``; ``err`` is the
    error-reduction ratio, the share of its DOF's residual sum of squares it removed;
    ``cv`` the held-out (blocked cross-validated) residual sum of squares per DOF."""

    added: str
    n_params: int
    rss: FloatArray
    bic: float
    aic: float
    err: float
    cv: FloatArray = field(default_factory=lambda: np.zeros(6))


@dataclass
class Selection:
    """Result of :func:`select_terms`: the chosen model and the path that led to it.

    Attributes
    ----------
    dropped : dict
        Candidate name → why it was not searched (zero, numerically equal to another column
        in these data, or a memory state that is not passive fluid memory).
    tss : ndarray, shape (6,)
        Σ y² per DOF of the low-passed target (held-out R² = 1 − cv / tss).
    memory : list of MemoryEvidence
        Time- and frequency-domain estimates of each chosen memory state, with the final
        model's static terms in place.
    points : PointSelection or None
        The element drags searched before the library (:mod:`.point_selection`), when
        candidates were given.
    """

    model: DampingModel
    steps: list[SelectionStep] = field(default_factory=list)
    rates: dict[str, float] = field(default_factory=dict)
    dropped: dict[str, str] = field(default_factory=dict)
    tss: FloatArray = field(default_factory=lambda: np.ones(6))
    memory: list[MemoryEvidence] = field(default_factory=list)
    points: PointSelection | None = None

    def added(self, base: DampingModel) -> dict[int, list[str]]:
        """The parameters the search added to ``base``, per force row 0..5 (X..N)
        (:func:`added_terms`)."""
        return added_terms(self.model, base)

    def only_in(self, base: DampingModel, rows: Sequence[int]) -> DampingModel:
        """The selected model without the static terms it added outside ``rows`` (force rows
        0..5): what the search found where the base misfits, and the rest as selected (an
        element drag stays when one of the rows it acts in is among ``rows``)."""
        added = self.added(base)
        inside = {n for i in rows for n in added[i]}
        return _without(self.model, [n for i in range(6) if i not in rows for n in added[i]
                                     if n not in inside])

    @property
    def cv_r2(self) -> tuple[FloatArray, FloatArray]:
        """Held-out R² per DOF of the base model and of the selected one, each shape (6,)
        (after an element drag search, the base's without the element drags, and both of the
        whole target)."""
        if self.points is None:
            return 1.0 - self.steps[0].cv / self.tss, 1.0 - self.steps[-1].cv / self.tss
        return self.points.r2[0], 1.0 - self.steps[-1].cv / self.points.tss


def added_terms(model: DampingModel, base: DampingModel) -> dict[int, list[str]]:
    """The parameters of ``model`` that ``base`` lacks, per force row 0..5 (X..N), in the
    order of the model (memory gains in the row of their DOF, an element drag in every row it
    acts in)."""
    out: dict[int, list[str]] = {i: [] for i in range(6)}
    for t in model.terms:
        if t.kind == "freq":
            for d, name in zip(t.state_dofs, t.parameter_names, strict=True):
                if name not in base.parameter_names:
                    out[int(d)].append(name)
            continue
        for b in t.bases:
            if b.name in base.parameter_names or b.more:
                continue
            rows = np.flatnonzero(np.diag(b.B)) if t.kind == "point" else [_single_entry(b)[0]]
            for i in rows:
                out[int(i)].append(b.name)
    return out


def row_by_row(without: Selection, drags: Selection, base: DampingModel, rows: Sequence[int]
               ) -> tuple[DampingModel, list[int]]:
    """The terms two searches added to ``base`` in ``rows``, each row's from the search with
    the smaller held-out residual there: ``without`` element drags, or ``drags``
    (``points`` given, the drags searched first). The drags stay when a row takes the terms
    of ``drags``.

    Each row's single-entry terms are fitted to that row alone, so a row can take either
    search's terms; an element drag acts in several rows and joins with the first row that
    takes ``drags``. Comparing the held-out residual sums of squares (not R², whose
    denominators differ by the shared terms' force) keeps both searches' rules: each row's
    terms passed its blocked cross-validation and one-standard-error rule.

    Returns
    -------
    model : DampingModel
    taken : list of int
        The rows that take the terms of ``drags``.
    """
    taken = [i for i in rows if drags.steps[-1].cv[i] < without.steps[-1].cv[i]]
    if not taken:
        return without.only_in(base, rows), []
    mine, theirs = drags.added(base), without.added(base)
    others = [i for i in rows if i not in taken]
    point = drags.model.term("point")
    keep = {n for i in taken for n in mine[i]} | set(point.parameter_names if point else [])
    model = _without(drags.model, [n for i in range(6) for n in mine[i] if n not in keep])
    specs = {b.name: CrossSpec(*_single_entry(b), b.alpha, b.name) for t in without.model.terms
             if t.kind == "cross" for b in t.bases}
    return _with_terms(model, [specs[n] for i in others for n in theirs[i] if n in specs],
                       {}), taken


#: Searches of :func:`select_terms` when the base has terms acting in several rows: their
#: force is estimated with the base, then with the terms the previous search chose.
SHARED_ROUNDS = 2


#: Share of its row's residual a term must remove to enter the path (and to stay in it). The
#: one-standard-error rule on the blocked cross-validation curve sizes the model; this only
#: keeps the path from wandering into noise and processing error. At 10 % it stopped paths on
#: a plateau where the next term opened a large gain (a term removing 7.5 % let the one after
#: it remove 60 %: MuJoCo box_rov, seed 2, surge). At 2 % it let a term into a plant the base
#: describes exactly (native torpedo_auv, its C_A mask stated, --select: Z_wr, 4.9 % of the
#: heave residual the processing leaves, held-out R² .9999 either way).
MIN_ERR = 0.05

#: :data:`MIN_ERR` of the library search beside element forces the data kept (the ``point``
#: term). Such a plant has physics the library's forms lack, and what its forces leave in
#: the weakest DOF is many small parts: at 5 % the search stopped there (MuJoCo tooled_rov
#: seeds 1 and 3, pitch .9932; frame_rov seed 3, roll .9948; torpedo_auv noiseless seeds 1
#: and 2 under --select, surge .9883 and .9890) before cross-validation could judge them. At
#: 2 % the 42 runs of the seven MuJoCo vehicles (seeds 1-3, realistic and noiseless sensors)
#: hold ≥ .9955 in every DOF; 1 % adds terms (up to 143 parameters) without a better worst DOF.
MIN_ERR_BESIDE_ELEMENTS = 0.02


def _with_terms(base: DampingModel, cross: Sequence[CrossSpec],
                memory: dict[int, float], shared: Sequence[DampingTerm] = ()) -> DampingModel:
    terms: dict[str, DampingTerm] = {t.kind: t for t in [*base.terms, *shared]}
    if cross:
        extra = cross_term(list(cross))
        old = terms.get("cross")
        terms["cross"] = DampingTerm("cross", extra.meaning,
                                     (old.bases if old else []) + extra.bases)
    if memory:
        terms["freq"] = memory_term({DOF_NAMES[d]: [lam] for d, lam in memory.items()})
    return DampingModel([terms[k] for k in TERM_KINDS if k in terms])


def _key(col: int, alpha: Alpha) -> tuple[Any, ...]:
    """Canonical form of the feature α(ν) ν_col (ν_j ν_k and ν_k ν_j are one)."""
    if alpha.kind == "lin":
        return ("prod", *sorted((col, alpha.i)))
    if alpha.kind == "one":
        return ("one", col)
    return (alpha.kind, col, alpha.i, alpha.j, alpha.w)


def _single_entry(b: Basis) -> tuple[int, int]:
    """(row, col) of a basis with one unit entry; ConfigError otherwise."""
    nz = np.argwhere(b.B != 0)
    if len(nz) != 1 or b.B[nz[0][0], nz[0][1]] != 1.0:
        raise ConfigError("select", f"{b.name} acts on several rows; term selection keeps "
                          "single-entry terms only (leave the residual term out with --terms)")
    return int(nz[0][0]), int(nz[0][1])


class _Blocks(NamedTuple):
    """The blocks of one row's normal equations (ΦᵀΦ, Φᵀy) that a trial of the columns S plus
    each one of C reads, with any leading axes (e.g. folds).

    Attributes
    ----------
    ss, sc, cs : ndarrays, shapes (..., |S|, |S|), (..., |S|, |C|), (..., |C|, |S|)
    cc : ndarray, shape (..., |C|)
        The diagonal of the C block.
    bs, bc : ndarrays, shapes (..., |S|), (..., |C|)
    """

    ss: FloatArray
    sc: FloatArray
    cs: FloatArray
    cc: FloatArray
    bs: FloatArray
    bc: FloatArray

    @staticmethod
    def of(A: FloatArray, b: FloatArray, S: NDArray[np.int64], C: NDArray[np.int64]
           ) -> _Blocks:
        """The blocks of ``A`` (..., m, m) and ``b`` (..., m)."""
        return _Blocks(A[..., S[:, None], S], A[..., S[:, None], C], A[..., C[:, None], S],
                       A[..., C, C], b[..., S], b[..., C])

    def total(self) -> _Blocks:
        """The sum over the first axis (the folds)."""
        return _Blocks(*(x.sum(0) for x in self))

    def __sub__(self, other: tuple[FloatArray, ...]) -> _Blocks:
        """Block by block difference."""
        return _Blocks(*(x - y for x, y in zip(self, other, strict=True)))


def _trials(G: _Blocks, tol: float
            ) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
    """Least squares on the columns S plus each one candidate c ∈ C, for all c at once, from
    the blocks ``G`` of their normal equations (of one system, or of several along a leading
    axis: each array below then has it too).

    With the fit β = G_SS⁻¹ b_S on S, adding c gives (bordered normal equations)
    θ_c = (b_c − G_cS β) / d_c and θ_S = β − G_SS⁻¹ G_Sc θ_c, d_c = G_cc − G_cS G_SS⁻¹ G_Sc
    the part of column c that S does not explain; d_c < tol · G_cc marks c as (numerically)
    a combination of S.

    Returns
    -------
    th_S : ndarray, shape (|S|, |C|)
    th_c : ndarray, shape (|C|,)
    gain : ndarray, shape (|C|,)
        RSS(S) − RSS(S ∪ {c}).
    ok : ndarray of bool, shape (|C|,)
    """
    gcc = G.cc
    if G.ss.shape[-1]:
        sol = scaled_lstsq(G.ss, np.concatenate([G.sc, G.bs[..., None]], axis=-1))
        X, beta = sol[..., :-1], sol[..., -1]
        den = gcc - np.einsum("...kc,...kc->...c", G.sc, X)
        num = G.bc - np.einsum("...ck,...k->...c", G.cs, beta)
    else:
        X, beta = np.zeros((*gcc.shape[:-1], 0, gcc.shape[-1])), np.zeros((*gcc.shape[:-1], 0))
        den, num = gcc.copy(), G.bc.copy()
    ok = den > tol * np.maximum(gcc, 1e-300)
    th_c = np.where(ok, num / np.where(ok, den, 1.0), 0.0)
    th_S = beta[..., :, None] - X * th_c[..., None, :]
    return th_S, th_c, np.where(ok, num * th_c, 0.0), ok


def _held_out(A: FloatArray, b: FloatArray, c: FloatArray, S: Sequence[int],
              C: NDArray[np.int64], tol: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Blocked cross-validation of S ∪ {c} for every c ∈ C in one row (that of S:
    :func:`cv_budget.fold_errors`).

    Parameters
    ----------
    A : ndarray, shape (F, m, m)
    b : ndarray, shape (F, m)
    c : ndarray, shape (F,)
        Per-fold normal equations of the row.

    Returns
    -------
    cv_C : ndarray, shape (|C|,)
        Σ over folds of the held-out RSS of S ∪ {c}, each fold predicted from the others.
    gain : ndarray, shape (|C|,)
        In-sample RSS(S) − RSS(S ∪ {c}) on all folds (``ok`` folded in: 0 if collinear).
    coef : ndarray, shape (|C|,)
        The coefficient of c in the fit of S ∪ {c} on all folds.
    """
    # every product below is of the blocks of S and C: per fold, over all folds, and over
    # all folds but each (all folds at once along the first axis)
    folds = _Blocks.of(A, b, np.asarray(S, dtype=np.int64), C)
    G = folds.total()
    _, coef, gain, ok = _trials(G, tol)
    th_S, th_c, _, okf = _trials(G - folds, tol)
    # ‖y − Φθ‖² on fold f = c − 2 bᵀθ + θᵀAθ, θ = (θ_S, θ_c) for each candidate
    quad_S = np.einsum("fkc,fkl,flc->fc", th_S, folds.ss, th_S)
    cross = np.einsum("fck,fkc->fc", folds.cs, th_S)
    cv = (c[:, None] - 2.0 * (np.einsum("fk,fkc->fc", folds.bs, th_S) + folds.bc * th_c)
          + quad_S + 2.0 * th_c * cross + th_c ** 2 * folds.cc)
    # a candidate collinear with S on some fold's complement is not judged
    return np.where(ok & okf.all(axis=0), cv.sum(axis=0), np.inf), gain, coef


def select_terms(samples: Samples, base: DampingModel, body: RigidBody,
                 cross: Sequence[dict[str, str]] | None = None,
                 families: Sequence[str] = FAMILIES,
                 memory_dofs: Sequence[int] = (0, 1, 2, 5), cutoff: float = 2.0,
                 folds: int = 5, max_terms: int | None = None, min_improvement: float = 10.0,
                 min_err: float = MIN_ERR, tol: float = 1e-8, strict_base: bool = True,
                 rounds: int = 10, exchange: float = 2.0, keep_base: bool = False,
                 points: Sequence[PointSpec] = (),
                 min_err_beside: float = MIN_ERR_BESIDE_ELEMENTS) -> Selection:
    """Forward selection of element drags, library terms and memory states on top of
    ``base``.

    Parameters
    ----------
    samples : Samples
    base : DampingModel
        Terms always kept (typically the preset's linear + quadratic); single-entry bases
        only (every kind but ``residual``).
    body : RigidBody
    cross : sequence of dict, optional
        Candidate coefficients as :class:`CrossSpec` mappings instead of the library.
    families : sequence of str
        Library families searched when ``cross`` is not given (:data:`terms.FAMILIES`).
    memory_dofs : sequence of int
        DOFs that may carry a fluid-memory state (none if ``base`` has a memory term).
    cutoff : float
        Parallel low-pass of the regression (Hz).
    folds : int
        Contiguous time blocks of the cross-validation, apart by a guard of
        :data:`cv_budget.GUARD_PERIODS` periods of ``cutoff``.
    max_terms : int, optional
        Largest number of parameters of the selected model (base included); None: no cap,
        the number of searched terms in each row is the one-standard-error size of its
        cross-validation curve (:func:`cv_budget.one_se_size`).
    min_improvement : float
        BIC decrease needed to add a candidate (10: "very strong" on the Kass–Raftery scale).
    min_err : float
        Share of its row's remaining residual sum of squares a candidate must remove
        (:data:`MIN_ERR`): the residuals are correlated (model and processing errors), so BIC
        alone over-counts evidence for small terms.
    tol : float
        Relative tolerance below which two columns are equal (|corr| > 1 − tol) or a column
        is a combination of those already chosen.
    strict_base : bool
        Hold the base's terms to the test every searched term passes (else a base term goes
        only when its removal lowers BIC). Base columns that are zero in the data stay.
    rounds : int
        Most forward-then-backward rounds.
    exchange : float
        At ``max_terms``, the term whose removal costs least held-out R² is exchanged for the
        best candidate when that gains ``exchange`` times as much.
    keep_base : bool
        Keep every term of ``base`` whatever the data say (the search only adds).
    points : sequence of PointSpec
        Candidate element drags (:func:`point_drag.point_library`), searched first
        (:func:`point_selection.select_points`); those kept join the base as a shared term.
        Those that no longer pass their entry test beside the library terms go
        (:func:`point_selection.weak_points`), and the library is searched again without
        them, until none goes: a term that entered to make up for a drag's force in another
        row is tested without the drag. That search estimates the shared force with the
        terms the last search chose (without the drags gone) and runs once.
    min_err_beside : float
        ``min_err`` of the library search when the base holds element forces (a ``point``
        term: those of ``points`` the data kept, or the base's own;
        :data:`MIN_ERR_BESIDE_ELEMENTS`).

    Returns
    -------
    Selection

    Base parameters that act in several rows at once (the ``coriolis`` and ``point`` terms)
    cannot be chosen row by row: they stay, and the search runs on the target less their
    force, estimated by least squares (the rows weighted by 1 / Σ y_i², so that N and N·m
    weigh alike) with the base, then again with the terms the first search chose
    (:data:`SHARED_ROUNDS` searches); the fit of the selected model estimates them with the
    chosen terms.
    """
    options: dict[str, Any] = {
        "cross": cross, "families": families, "memory_dofs": memory_dofs, "cutoff": cutoff,
        "folds": folds, "max_terms": max_terms, "min_improvement": min_improvement,
        "min_err": min_err, "tol": tol, "strict_base": strict_base, "rounds": rounds,
        "exchange": exchange, "keep_base": keep_base}
    rules = EntryRules(min_improvement, _n_eff(samples, cutoff))

    def search(base: DampingModel, start: DampingModel | None = None) -> Selection:
        # beside element forces, the lower entry share
        share = min_err_beside if base.term("point") is not None else min_err
        return _search_beside_shared(samples, base, body, {**options, "min_err": share},
                                     start)

    found = select_points(samples, base, body, points, cutoff, rules, folds) if points else None
    if found is not None:
        base = found.model
    selection = search(base)
    pruned: list[str] = []
    while found is not None:
        removed = weak_points(samples, selection.model, body, cutoff, rules)
        if not removed:
            break
        # the library again without them: the terms that made up for them go too
        pruned += removed
        base = _without(base, removed)
        # the shared terms' force first estimated with the terms the last search chose
        selection = search(base, _without(selection.model, removed))
    if found is not None:
        found = replace(found, pruned=pruned)
    return replace(selection, points=found)


def _search_beside_shared(samples: Samples, base: DampingModel, body: RigidBody,
                          options: dict[str, Any], start: DampingModel | None = None
                          ) -> Selection:
    """:func:`_search` on top of ``base`` (``options`` its keywords): its terms acting in
    several rows (the ``coriolis`` and ``point`` terms) stay, the search runs on the target
    less their force, estimated with the base, then with the terms the previous search chose
    (:data:`SHARED_ROUNDS` searches); with a ``start`` (``base`` and the terms an earlier
    search chose), estimated with it and searched once."""
    shared = [t for t in base.terms if any(b.more for b in t.bases) or t.kind == "point"]
    if not shared:
        return _search(samples, base, body, (), **options)
    single = DampingModel([t for t in base.terms if t not in shared])
    model = base if start is None else start
    for _ in range(SHARED_ROUNDS if start is None else 1):
        theta = _least_squares(samples, model, body, options["cutoff"])
        values = dict(zip(model.parameter_names, theta, strict=True))
        part = DampingModel(shared)
        known = part.force(samples.nu, np.array([values[n] for n in part.parameter_names]))
        # y − Φ_shared θ_shared: the same as τ less that force
        selection = _search(replace(samples, tau=samples.tau - known), single, body, shared,
                            **options)
        model = selection.model
    return selection


#: A value per candidate (shape (|C|,)) or of one term.
_Real = FloatArray | float

#: A column of one row's regression: (row, column index in the normal equations, name).
_Column = tuple[int, int, str]


def _search(samples: Samples, base: DampingModel, body: RigidBody,
            shared: Sequence[DampingTerm], cross: Sequence[dict[str, str]] | None,
            families: Sequence[str], memory_dofs: Sequence[int], cutoff: float, folds: int,
            max_terms: int | None, min_improvement: float, min_err: float, tol: float,
            strict_base: bool, rounds: int, exchange: float, keep_base: bool) -> Selection:
    """The stepwise search of :func:`select_terms` on top of the single-row terms ``base``;
    the ``shared`` terms count in the budget and join the selected model."""
    base_names = base.parameter_names
    specs = library(families) if cross is None else [CrossSpec.from_dict(c) for c in cross]
    specs = [sp for sp in specs if sp.label not in base_names]
    feats, base_cols, cand = _feature_columns(base, specs)
    m = len(feats)
    # memory: the base's states, then candidate states with profiled rates
    mem0 = base.term("freq")
    rates, dropped = _memory_rates(samples, base, body,
                                   memory_dofs if mem0 is None else (), cutoff)
    mem_rates, mem_dofs, base_mem, cand_mem = _memory_columns(mem0, rates, m)
    ne = _feature_equations(samples, feats, mem_rates, mem_dofs, body, folds, cutoff)
    zero, corr, same_as = _equal_columns(ne.A.sum(0)[0][:m, :m], tol)
    usable, unsearched = _searchable(cand, base_cols, feats, zero, corr, same_as)
    dropped.update(unsearched)
    search = _Stepwise(ne, m, [*base_cols, *base_mem], [*usable, *cand_mem], zero,
                       base.n_params + sum(t.n_params for t in shared),
                       _n_eff(samples, cutoff),
                       _Rules(math.inf if max_terms is None else max_terms, min_improvement,
                              min_err, tol, strict_base, exchange, keep_base),
                       "base: " + "+".join([*base.kinds, *(t.kind for t in shared)]))
    search.run(rounds)
    if max_terms is None:
        search.one_se()
    final = search.chosen_names()
    base = _without(base, [n for n in base_names if n not in final])
    spec_of = {sp.label: sp for _, _, sp in cand}
    keep_cross = [spec_of[st.added] for st in search.steps[1:]
                  if st.added in spec_of and st.added in final]
    keep_mem = {d: rates[d] for d, col, _ in cand_mem if col in search.chosen[d]}
    keep_mem, memory, removed = _refine_memory(samples, base, body, keep_cross, keep_mem, cutoff)
    dropped.update(removed)
    model = _with_terms(base, keep_cross, keep_mem, shared)
    return Selection(model, search.steps, {f"freq.{DOF_NAMES[d]}.lambda1": lam
                                           for d, lam in keep_mem.items()}, dropped,
                     total_sum_of_squares(ne), memory)


def _n_eff(samples: Samples, cutoff: float) -> float:
    """Independent samples of the regression low-passed at ``cutoff`` Hz: 2 · cutoff · T, at
    most the number of samples."""
    return min(float(len(samples)), 2.0 * cutoff * len(samples) / samples.rate)


def _feature_columns(base: DampingModel, specs: Sequence[CrossSpec]
                     ) -> tuple[list[tuple[int, Alpha]], list[_Column],
                                list[tuple[int, int, CrossSpec]]]:
    """The distinct features g_k(ν) = α_k(ν) ν_col of the base's static terms and of the
    candidates, the base's single-entry columns first, then the candidates' (simplest first).

    Returns
    -------
    feats : list of (int, Alpha), length m
        (col, α) of each feature k, one per canonical product (:func:`_key`).
    base_cols : list of (row, feature, name)
        The base's static parameters.
    cand : list of (row, feature, CrossSpec)
        The candidates, in the order of ``specs``.
    """
    keys: dict[tuple[Any, ...], int] = {}
    feats: list[tuple[int, Alpha]] = []

    def feature(col: int, alpha: Alpha) -> int:
        k = _key(col, alpha)
        if k not in keys:
            keys[k] = len(feats)
            feats.append((col, alpha))
        return keys[k]

    base_cols: list[_Column] = []
    for t in base.terms:
        if t.kind != "freq":
            for bs in t.bases:
                r, col = _single_entry(bs)
                base_cols.append((r, feature(col, bs.alpha), bs.name))
    cand = [(sp.row, feature(sp.col, sp.alpha), sp) for sp in specs]
    return feats, base_cols, cand


def _memory_rates(samples: Samples, base: DampingModel, body: RigidBody,
                  dofs: Sequence[int], cutoff: float) -> tuple[dict[int, float], dict[str, str]]:
    """Profiled rate λ (1/s) of a memory state in each DOF of ``dofs`` on top of ``base``
    (:func:`memory_evidence`); the DOFs whose state is not passive fluid memory go to the
    second mapping with the reason (``"memory on u"`` → why)."""
    rates: dict[int, float] = {}
    dropped: dict[str, str] = {}
    if dofs:
        for ev in memory_evidence(samples, base, body, dofs, cutoff):
            if ev.contradiction:
                dropped[f"memory on {DOF_NAMES[ev.dof]}"] = ev.contradiction
            else:
                rates[ev.dof] = ev.rate
    return rates, dropped


def _memory_columns(mem0: DampingTerm | None, rates: dict[int, float], m: int
                    ) -> tuple[FloatArray, NDArray[np.int64], list[_Column], list[_Column]]:
    """The memory states after the m features: the base's (``mem0``), then one candidate
    state per DOF of ``rates``.

    Returns
    -------
    mem_rates : ndarray, shape (s,)
        Rate λ of each state (1/s).
    mem_dofs : ndarray of int, shape (s,)
        The DOF (and row) of each state.
    base_mem, cand_mem : list of (row, column, name)
        The base's states (column m + k) and the candidate states.
    """
    n0 = mem0.n_states if mem0 is not None else 0
    mem_rates = np.r_[mem0.rates if mem0 is not None else [], list(rates.values())]
    mem_dofs = np.r_[mem0.state_dofs if mem0 is not None else [], list(rates)].astype(np.int64)
    base_mem = [] if mem0 is None else [
        (int(d), m + k, nm)
        for k, (d, nm) in enumerate(zip(mem0.state_dofs, mem0.parameter_names, strict=True))]
    cand_mem = [(d, m + n0 + k, f"memory on {DOF_NAMES[d]} (λ = {lam:.3g} 1/s)")
                for k, (d, lam) in enumerate(rates.items())]
    return mem_rates, mem_dofs, base_mem, cand_mem


def _equal_columns(G0: FloatArray, tol: float
                   ) -> tuple[NDArray[np.bool_], FloatArray, NDArray[np.int64]]:
    """Zero and numerically equal (up to scale) feature columns, from their Gram matrix.

    Parameters
    ----------
    G0 : ndarray, shape (m, m)
        Σ g_k g_l over the data (the same in every row).
    tol : float
        Columns with |corr| > 1 − ``tol`` are equal.

    Returns
    -------
    zero : ndarray of bool, shape (m,)
    corr : ndarray, shape (m, m)
        |correlation| (about zero) of each pair.
    same_as : ndarray of int, shape (m,)
        The first earlier column, not zero and not itself a copy, that column k equals; −1 if
        none.
    """
    g = np.diag(G0)
    zero = g <= 1e-12 * max(float(g.max()), 1e-300)
    with np.errstate(invalid="ignore", divide="ignore"):
        # |corr_kl| = |G_kl| / √(G_kk G_ll)
        corr = np.abs(G0) / np.sqrt(np.outer(g, g))
    same_as = np.full(len(g), -1)
    for k in range(len(g)):
        if not zero[k]:
            earlier = np.flatnonzero((corr[k, :k] > 1.0 - tol) & ~zero[:k] & (same_as[:k] < 0))
            same_as[k] = earlier[0] if len(earlier) else -1
    return zero, corr, same_as


def _searchable(cand: Sequence[tuple[int, int, CrossSpec]], base_cols: Sequence[_Column],
                feats: Sequence[tuple[int, Alpha]], zero: NDArray[np.bool_], corr: FloatArray,
                same_as: NDArray[np.int64]) -> tuple[list[_Column], dict[str, str]]:
    """The candidates worth searching, as (row, feature, name); the others (zero in these
    data, or equal to an earlier column) with the reason. A candidate whose column is a base
    parameter's in its row is neither."""
    row_names = {(r, f): nm for r, f, nm in base_cols}
    usable: list[_Column] = []
    dropped: dict[str, str] = {}
    for r, f, sp in cand:
        if (r, f) in row_names:
            continue  # the same column as a base parameter of this row
        if zero[f]:
            dropped[sp.label] = "no excitation: its column is zero in these data"
        elif same_as[f] >= 0:
            other = row_names.get((r, int(same_as[f])))
            if other is None:
                col, a = feats[int(same_as[f])]
                other = library_name(r, col, a)
            dropped[sp.label] = (f"equals {other} in these data (|corr| = "
                                 f"{corr[f, same_as[f]]:.12f})")
        else:
            usable.append((r, f, sp.label))
        row_names.setdefault((r, f), sp.label)
    return usable, dropped


def _refine_memory(samples: Samples, base: DampingModel, body: RigidBody,
                   cross: Sequence[CrossSpec], rates: dict[int, float], cutoff: float
                   ) -> tuple[dict[int, float], list[MemoryEvidence], dict[str, str]]:
    """Each chosen memory state's rate again, with the other chosen terms in place, and its
    check in both domains: a state that is no longer passive memory there goes.

    Returns
    -------
    rates : dict
        DOF → refined rate λ (1/s) of the states that stay.
    memory : list of MemoryEvidence
        One per chosen state, kept or not.
    dropped : dict
        ``"memory on u"`` → why it was removed.
    """
    rates = dict(rates)
    memory: list[MemoryEvidence] = []
    dropped: dict[str, str] = {}
    for d in list(rates):
        others = _with_terms(base, cross, {k: v for k, v in rates.items() if k != d})
        ev = memory_evidence(samples, others, body, [d], cutoff)[0]
        memory.append(ev)
        if ev.contradiction:
            dropped[f"memory on {DOF_NAMES[d]}"] = f"removed after the search: {ev.contradiction}"
            del rates[d]
        else:
            rates[d] = ev.rate
    return rates, memory, dropped


@dataclass(frozen=True)
class _Rules:
    """The test a term passes to enter the model and to stay in it, and the budget (the
    parameters of :func:`select_terms` of the same names)."""

    max_terms: float
    min_improvement: float
    min_err: float
    tol: float
    strict_base: bool
    exchange: float
    keep_base: bool

    def qualifies(self, dbic: _Real, gain: _Real, rss_without: _Real, cv_with: _Real,
                  cv_without: _Real, passive: NDArray[np.bool_] | bool) -> NDArray[np.bool_]:
        """Whether a term passes, elementwise over candidates: it lowers BIC by more than
        ``min_improvement``, removes at least ``min_err`` of its row's residual sum of squares
        without it, lowers its row's held-out RSS, and is passive (a memory state only with a
        gain c > 0). Scalars or arrays of one shape (ΔBIC, RSS and held-out RSS in N²)."""
        return ((dbic < -self.min_improvement) & (gain >= self.min_err * rss_without)
                & (cv_with < cv_without) & np.isfinite(cv_with) & passive)


class _Removal(NamedTuple):
    """What taking the term ``col`` out of ``row`` would do."""

    row: int
    col: int
    rss: float  # the row's RSS without the term
    cv: float  # the row's held-out RSS without it
    dbic: float  # BIC with the term − without it
    loss: float  # held-out R² the row loses
    weak: bool  # it no longer passes the test it entered by


class _Stepwise:
    """The stepwise search over the six rows at once, and its path.

    Forward while a candidate qualifies and the budget allows, then backward (a later term
    can make an earlier one redundant), repeated. Every candidate's in-sample and held-out
    gain in its row is kept up to date (:func:`_held_out`), so a step costs no pass over data.

    Parameters
    ----------
    ne : NormalEquations
        Per-fold normal equations of every column in every row, A (F, 6, p, p).
    m : int
        Number of library features; columns ≥ m are memory states.
    base_cols, usable : sequence of (row, column, name)
        The base's parameters (chosen at the start) and the candidates.
    zero : ndarray of bool, shape (m,)
        Features that are zero in the data (a base one stays).
    k0 : int
        Parameters of the base, the shared terms included.
    n_eff : float
        Independent samples of the low-passed regression.
    rules : _Rules
    label : str
        Name of the first row of the path.
    """

    def __init__(self, ne: NormalEquations, m: int, base_cols: Sequence[_Column],
                 usable: Sequence[_Column], zero: NDArray[np.bool_], k0: int, n_eff: float,
                 rules: _Rules, label: str) -> None:
        self.ne, self.m, self.rules, self.n_eff = ne, m, rules, n_eff
        self.log_n = float(np.log(n_eff))
        self.N = float(ne.n.sum())
        self.chosen = {i: [f for r, f, _ in base_cols if r == i] for i in range(6)}
        self.pool = {i: [f for r, f, _ in usable if r == i] for i in range(6)}
        self.name_of = {(r, f): nm for r, f, nm in [*base_cols, *usable]}
        # the base's memory states, and its columns the data leave at zero (the fit flags them
        # 'no excitation' rather than the selection hiding them)
        self.keep_always = {(r, f) for r, f, _ in base_cols
                            if f >= m or zero[f] or rules.keep_base}
        self.from_base = {(r, f) for r, f, _ in base_cols}
        # the held-out errors of column sets and the in-sample fits of removals, each computed
        # once: each backward step asks again for the removals of the rows no step has
        # changed since the last one, and a removal's column set is the next addition's S
        self._errors: dict[tuple[int, tuple[int, ...]], FloatArray] = {}
        self._fits: dict[tuple[int, tuple[int, ...], int], tuple[float, float]] = {}
        tss = total_sum_of_squares(ne)
        self.rss = np.array([tss[i] - _fit_row(ne, i, self.chosen[i]) for i in range(6)])
        self.tss = np.maximum(tss, 1e-300)
        self.trials = {i: self._held_out(i, self.chosen[i], self.pool[i]) for i in range(6)}
        self.cv = np.array([float(self.trials[i][0]) for i in range(6)])
        self.k = k0
        bic, aic = self._criteria()
        self.steps = [SelectionStep(label, self.k, self.rss.copy(), bic, aic, 0.0,
                                    self.cv.copy())]

    def run(self, rounds: int) -> None:
        """At most ``rounds`` forward-then-backward rounds, until one changes nothing."""
        for _ in range(rounds):
            added = self._forward()
            if not self._backward() and not added:
                break

    def one_se(self) -> None:
        """In each row, take out the searched terms beyond the one-standard-error size of the
        cross-validation curve along the order they entered (:func:`cv_budget.one_se_size`),
        the last first."""
        for i in range(6):
            added = [f for f in self.chosen[i] if (i, f) not in self.from_base]
            if not added:
                continue
            kept = [f for f in self.chosen[i] if (i, f) in self.from_base]
            errors = np.array([self._fold_errors(i, kept + added[:k])
                               for k in range(len(added) + 1)])
            for f in reversed(added[one_se_size(errors):]):
                self._remove(self._removal(i, f))

    def chosen_names(self) -> set[str]:
        """Names of the parameters in the model now."""
        return {self.name_of[(i, f)] for i in range(6) for f in self.chosen[i]}

    def _held_out(self, i: int, S: Sequence[int], C: Sequence[int]
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Row ``i``'s held-out RSS of the columns S, and :func:`_held_out` of S plus each one
        of C."""
        ne = self.ne
        return (self._fold_errors(i, S).sum(),
                *_held_out(ne.A[:, i], ne.b[:, i], ne.c[:, i], S, np.array(C, dtype=np.int64),
                           self.rules.tol))

    def _in_sample(self, i: int, S: Sequence[int], col: int) -> tuple[float, float]:
        """Row ``i``'s in-sample RSS(S) − RSS(S ∪ {col}) and the coefficient of ``col``
        (:func:`_trials` on all folds)."""
        key = (i, tuple(S), col)
        if key not in self._fits:
            ne = self.ne
            G = _Blocks.of(ne.A[:, i], ne.b[:, i], np.asarray(S, dtype=np.int64),
                           np.array([col])).total()
            _, coef, gain, _ = _trials(G, self.rules.tol)
            self._fits[key] = float(gain[0]), float(coef[0])
        return self._fits[key]

    def _fold_errors(self, i: int, S: Sequence[int]) -> FloatArray:
        """:func:`cv_budget.fold_errors` of the columns S in row ``i``, shape (F,) (the
        one-standard-error rule walks the path again)."""
        key = (i, tuple(S))
        if key not in self._errors:
            ne = self.ne
            self._errors[key] = fold_errors(ne.A[:, i], ne.b[:, i], ne.c[:, i], S)
        return self._errors[key]

    def _criteria(self) -> tuple[float, float]:
        """(BIC, AIC) of the model now (dimensionless)."""
        return information_criteria(self.rss, self.N, self.n_eff, self.k)

    def _delta_bic(self, rss_with: _Real, rss_without: _Real) -> FloatArray:
        """BIC with one parameter more in a row − BIC without it, from the row's RSS with and
        without it (N², scalars or arrays)."""
        # ΔBIC = n_eff log(RSS_with / RSS_without) + log n_eff
        return self.n_eff * np.log(np.maximum(rss_with, 1e-300)
                                   / np.maximum(rss_without, 1e-300)) + self.log_n

    def _record(self, label: str, i: int) -> None:
        """Append the model now to the path, ``label`` the change made in row ``i``."""
        bic, aic = self._criteria()
        # error-reduction ratio: 1 − RSS_i / RSS_i before the change
        err = 1.0 - self.rss[i] / max(self.steps[-1].rss[i], 1e-300)
        self.steps.append(SelectionStep(label, self.k, self.rss.copy(), bic, aic, err,
                                        self.cv.copy()))

    def _best_addition(self, rows: Sequence[int] = range(6)) -> tuple[float, int, int] | None:
        """(score, row, pool index) of the candidate in ``rows`` with the largest held-out
        gain among those that qualify; None if none does."""
        best: tuple[float, int, int] | None = None
        for i in rows:
            _, cv_c, gain, coef = self.trials[i]
            if not len(cv_c):
                continue
            dbic = self._delta_bic(self.rss[i] - gain, self.rss[i])
            # a memory state enters only as passive memory (gain c > 0)
            passive = (np.array(self.pool[i]) < self.m) | (coef > 0)
            good = self.rules.qualifies(dbic, gain, self.rss[i], cv_c, self.cv[i], passive)
            if good.any():
                # score: change of the row's held-out unexplained share, (CV_c − CV_i) / TSS_i
                score = np.where(good, (cv_c - self.cv[i]) / self.tss[i], np.inf)
                j = first_best(score)
                if best is None or score[j] < best[0] - TIE_RTOL * abs(best[0]):
                    best = (float(score[j]), i, j)
        return best

    def _add(self, i: int, j: int) -> None:
        """Move candidate ``j`` of the pool of row ``i`` into the model."""
        f = self.pool[i].pop(j)
        self.cv[i] = float(self.trials[i][1][j])
        self.rss[i] = max(float(self.rss[i] - self.trials[i][2][j]), 0.0)
        self.chosen[i].append(f)
        self.k += 1
        self.trials[i] = self._held_out(i, self.chosen[i], self.pool[i])
        self._record(self.name_of[(i, f)], i)

    def _removal(self, i: int, col: int) -> _Removal:
        """What removing column ``col`` from row ``i`` would do: a searched term is weak when it
        no longer passes the test it entered by, a base one (unless ``strict_base``) when its
        removal lowers BIC."""
        rest = [c for c in self.chosen[i] if c != col]
        gain, coef = self._in_sample(i, rest, col)
        cv_wo = self._fold_errors(i, rest).sum()
        rss_wo = self.rss[i] + gain
        dbic = float(self._delta_bic(self.rss[i], rss_wo))
        if (i, col) in self.from_base and not self.rules.strict_base:
            weak = dbic > 0.0
        else:
            weak = not self.rules.qualifies(dbic, rss_wo - self.rss[i], rss_wo, self.cv[i],
                                            float(cv_wo), col < self.m or coef > 0)
        # held-out R² lost: (CV without − CV with) / TSS
        loss = (float(cv_wo) - self.cv[i]) / self.tss[i]
        return _Removal(i, col, rss_wo, float(cv_wo), dbic, loss, weak)

    def _remove(self, r: _Removal) -> None:
        """Take the term of ``r`` out of the model; it does not return to the pool."""
        self.rss[r.row], self.cv[r.row] = r.rss, r.cv
        self.chosen[r.row].remove(r.col)
        self.k -= 1
        self.trials[r.row] = self._held_out(r.row, self.chosen[r.row], self.pool[r.row])
        self._record("− " + self.name_of[(r.row, r.col)], r.row)

    def _forward(self) -> bool:
        """Add the best qualifying candidate while there is one and the budget allows;
        whether any was added."""
        added = False
        while self.k < self.rules.max_terms:
            best = self._best_addition()
            if best is None:
                break
            self._add(best[1], best[2])
            added = True
        return added

    def _backward(self) -> bool:
        """Remove the weakest term (largest ΔBIC) while one is weak, then, at the budget, try
        an exchange; whether the model changed. A removed term does not come back (no
        cycling)."""
        removed = False
        # a removal changes only its own row's statistics: the others' removals stay valid
        by_row = {i: self._row_removals(i) for i in range(6)}
        while True:
            weak = [r for rs in by_row.values() for r in rs if r.weak]
            if not weak:
                break
            worst = max(weak, key=lambda r: r.dbic)
            self._remove(worst)
            by_row[worst.row] = self._row_removals(worst.row)
            removed = True
        return self._exchange([r for rs in by_row.values() for r in rs]) or removed

    def _row_removals(self, i: int) -> list[_Removal]:
        """:meth:`_removal` of each term of row ``i`` that may go."""
        return [self._removal(i, col) for col in self.chosen[i]
                if (i, col) not in self.keep_always]

    def _exchange(self, removals: Sequence[_Removal]) -> bool:
        """At the budget, exchange the term whose removal costs least held-out R² for the best
        candidate when that gains ``exchange`` times as much; else let the worst-explained DOF
        take the place of a term of another (:meth:`_lift_worst_dof`). Whether a term went."""
        if self.k < self.rules.max_terms:
            return False
        best = self._best_addition()
        if best is not None and removals:
            cheapest = min(removals, key=lambda r: r.loss)
            if -best[0] > self.rules.exchange * cheapest.loss:
                self._remove(cheapest)
                return True
        return self._lift_worst_dof(removals)

    def _lift_worst_dof(self, removals: Sequence[_Removal]) -> bool:
        """No DOF left behind: the worst-explained DOF takes the place of the cheapest term of
        a DOF that stays better explained than the worst one is now (the smallest held-out R²
        of the six rises with every such exchange, so they end). Whether it did."""
        # held-out R²_i = 1 − CV_i / TSS_i
        r2 = 1.0 - self.cv / self.tss
        w = int(np.argmin(r2))
        best = self._best_addition([w])
        if best is None:
            return False
        cheapest_in: dict[int, _Removal] = {}
        for r in removals:
            if r.row not in cheapest_in or r.loss < cheapest_in[r.row].loss:
                cheapest_in[r.row] = r
        donors = [r for i, r in cheapest_in.items() if i != w and r2[i] - r.loss > r2[w]]
        if not donors:
            return False
        self._remove(min(donors, key=lambda r: (r.loss, r.row)))
        self._add(best[1], best[2])
        return True


def _least_squares(samples: Samples, model: DampingModel, body: RigidBody, cutoff: float
                   ) -> FloatArray:
    """Least-squares θ of ``model`` (every parameter free), shape (p,): the six rows
    together, each weighted by 1 / Σ y_i² (its unexplained share, so that N and N·m weigh
    alike)."""
    ne = accumulate(samples, model, body, cutoff=cutoff)
    A, b, _ = ne.total(1.0 / np.maximum(total_sum_of_squares(ne), 1e-300))
    return solve_normal(A, b, np.ones(model.n_params, dtype=bool), np.zeros(model.n_params))


@dataclass
class _FeatureRows:
    """The low-passed, decimated feature rows of one search's samples, chunk by chunk (the
    fold of each row and the rows), and their Gram matrix per fold: what does not depend on
    the target, kept for the next search of the same samples and features."""

    key: tuple[Any, ...]
    nu: FloatArray
    t: FloatArray
    segment: NDArray[np.int64]
    chunks: list[tuple[NDArray[np.int64], FloatArray]]
    G: FloatArray


#: The feature rows of the last search (:func:`_feature_equations`): a search beside shared
#: terms runs on the same samples with another target (SHARED_ROUNDS times), and the default
#: structure searches again once a drag is taken out.
_LAST_ROWS: list[_FeatureRows] = []
#: Largest feature rows kept (bytes): a 600 s log's library at 50 Hz is ~45 MB.
ROWS_KEPT = 96e6


def _rows_key(feats: Sequence[tuple[int, Alpha]], mem_rates: FloatArray,
              mem_dofs: NDArray[np.int64], cutoff: float, fold_of: NDArray[np.int64]
              ) -> tuple[Any, ...]:
    """What the feature rows depend on besides the samples' ν, times and segments."""
    return (list(feats), mem_rates.tolist(), mem_dofs.tolist(), cutoff, fold_of.tobytes())


def _feature_rows(samples: Samples, key: tuple[Any, ...]) -> _FeatureRows | None:
    """The kept feature rows when the last search had these samples (the same ν, times and
    segments) and ``key`` (:func:`_rows_key`), else None."""
    if _LAST_ROWS:
        last = _LAST_ROWS[0]
        if (last.nu is samples.nu and last.t is samples.t and last.segment is samples.segment
                and last.key == key):
            return last
    return None


def _feature_equations(samples: Samples, feats: Sequence[tuple[int, Alpha]],
                       mem_rates: FloatArray, mem_dofs: NDArray[np.int64], body: RigidBody,
                       folds: int, cutoff: float) -> NormalEquations:
    """Per-fold normal equations of the library features in every row, each feature
    g_k(ν) = α_k(ν) ν_col computed, low-passed and multiplied once for all six rows.

    Column k < m = len(feats) is feature k in every row; column m + s is memory state s
    (ż = −λ_s z + ν_dof), which acts in the row of its DOF only. The same statistics as
    :func:`batch.accumulate` of a model with bases 1 e_colᵀ, at a sixth of the cost and memory.
    The feature rows and their Gram matrix do not depend on the target: those of the last
    call are used again when the samples and features are the same (bit for bit the same
    statistics; only the target's products are formed anew).

    Returns
    -------
    NormalEquations
        A (folds, 6, p, p), b (folds, 6, p), c (folds, 6), n (folds,), p = m + len(mem_rates).
    """
    m = len(feats)
    p = m + len(mem_rates)
    # no sample within the low-pass's reach of a fold boundary counts (cv_budget)
    guard = round(GUARD_PERIODS * samples.rate / cutoff) if cutoff > 0 else 0
    fold_of = guarded_folds(len(samples), folds, guard)
    key = _rows_key(feats, mem_rates, mem_dofs, cutoff, fold_of)
    kept = _feature_rows(samples, key)
    Gy = np.zeros((folds, p, 6))
    c = np.zeros((folds, 6))
    n = np.zeros(folds)
    if kept is None:
        G = _new_feature_rows(samples, feats, mem_rates, mem_dofs, body, folds, cutoff,
                              fold_of, key, (Gy, c, n))
    else:
        G = kept.G
        ys = (y for _, _, y in iter_entries(samples, DampingModel([]), body, cutoff=cutoff,
                                            decimate=True))
        for (fo, F), y in zip(kept.chunks, ys, strict=True):
            _target_products(fo, F, y, Gy, c, n)
    A = np.repeat(G[:, None], 6, axis=1)
    b = Gy.transpose(0, 2, 1).copy()
    for s, d in enumerate(mem_dofs):
        # memory state s acts in row d only
        other = [i for i in range(6) if i != int(d)]
        A[:, other, m + s, :] = 0.0
        A[:, other, :, m + s] = 0.0
        b[:, other, m + s] = 0.0
    return NormalEquations(A, b, c, n)


def _target_products(fo: NDArray[np.int64], F: FloatArray, y: FloatArray, Gy: FloatArray,
                     c: FloatArray, n: FloatArray) -> None:
    """Add a chunk's Gᵀy, yᵀy and row count to each fold's (in place)."""
    for f in np.unique(fo[fo >= 0]):
        k = fo == f
        # Gᵀy, yᵀy per fold
        Gy[f] += F[k].T @ y[k]
        c[f] += np.einsum("ni,ni->i", y[k], y[k])
        n[f] += int(k.sum())


def _new_feature_rows(samples: Samples, feats: Sequence[tuple[int, Alpha]],
                      mem_rates: FloatArray, mem_dofs: NDArray[np.int64], body: RigidBody,
                      folds: int, cutoff: float, fold_of: NDArray[np.int64],
                      key: tuple[Any, ...], target: tuple[FloatArray, FloatArray, FloatArray]
                      ) -> FloatArray:
    """The Gram matrix per fold of :func:`_feature_equations`'s feature rows, the target's
    products added to ``target`` (Gᵀy, yᵀy, n, in place) on the way; the rows are kept (as
    the only ones) when they take at most :data:`ROWS_KEPT` bytes, else dropped chunk by
    chunk (memory flat with the log's length)."""
    m = len(feats)
    cols = np.array([c for c, _ in feats], dtype=np.int64)
    bank = AlphaBank([a for _, a in feats])
    terms = [DampingTerm("freq", "memory candidates", rates=mem_rates, state_dofs=mem_dofs)] \
        if len(mem_rates) else []
    p = m + len(mem_rates)

    def features(nu: FloatArray, z: FloatArray | None) -> FloatArray:
        g = np.empty((len(nu), p))
        # g_k = α_k(ν) ν_col(k)
        g[:, :m] = bank(nu) * nu[:, cols]
        if z is not None:
            g[:, m:] = z
        return g

    G = np.zeros((folds, p, p))
    chunks: list[tuple[NDArray[np.int64], FloatArray]] | None = []
    size = 0
    _LAST_ROWS.clear()
    for rows, F, y in iter_entries(samples, DampingModel(terms), body, cutoff=cutoff,
                                   decimate=True, entries=features):
        fo = fold_of[rows]
        for f in np.unique(fo[fo >= 0]):
            k = fo == f
            # GᵀG per fold
            G[f] += F[k].T @ F[k]
        _target_products(fo, F, y, *target)
        size += F.nbytes
        chunks = chunks if chunks is not None and size <= ROWS_KEPT else None
        if chunks is not None:
            chunks.append((fo, F))
    if chunks is not None:
        _LAST_ROWS.append(_FeatureRows(key, samples.nu, samples.t, samples.segment, chunks, G))
    return G


def _without(model: DampingModel, names: Sequence[str]) -> DampingModel:
    """The model without the static parameters ``names`` (terms left empty go)."""
    if not names:
        return model
    terms = []
    for t in model.terms:
        if t.kind != "freq":
            t = DampingTerm(t.kind, t.meaning, [b for b in t.bases if b.name not in names])
            if not t.bases:
                continue
        terms.append(t)
    return DampingModel(terms)


def _fit_row(ne: NormalEquations, i: int, cols: Sequence[int]) -> float:
    """Σ y² − RSS of the least-squares fit of row ``i`` on ``cols`` (all folds): bᵀθ."""
    if not cols:
        return 0.0
    idx = np.asarray(cols, dtype=np.int64)
    G, bv = ne.A[:, i].sum(0)[np.ix_(idx, idx)], ne.b[:, i].sum(0)[idx]
    theta = solve_normal(G, bv, np.ones(len(idx), dtype=bool), np.zeros(len(idx)))
    return float(bv @ theta)
