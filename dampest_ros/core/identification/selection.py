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
   of the columns already in its row; until no candidate qualifies or the model has
   ``max_terms`` parameters.

BIC = n_eff Σ_i log(RSS_i / N) + k log n_eff, with n_eff = 2 · cutoff · T the number of
independent samples in the low-passed regression. Each row's least squares is separate (a
library coefficient acts on one row only), so neither BIC nor the path depends on per-DOF
weights, nor on the prior's magnitudes, which it never sees.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.memory_rates import MemoryEvidence, memory_evidence
from dampest_ros.core.identification.quadratic import solve_normal
from dampest_ros.core.identification.regression import (
    NormalEquations,
    accumulate,
    fold_index,
    iter_regression,
)
from dampest_ros.core.physics.alpha import Alpha, AlphaBank
from dampest_ros.core.physics.damping import TERM_KINDS, Basis, DampingModel, DampingTerm
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
    """

    model: DampingModel
    steps: list[SelectionStep] = field(default_factory=list)
    rates: dict[str, float] = field(default_factory=dict)
    dropped: dict[str, str] = field(default_factory=dict)
    tss: FloatArray = field(default_factory=lambda: np.ones(6))
    memory: list[MemoryEvidence] = field(default_factory=list)

    @property
    def cv_r2(self) -> tuple[FloatArray, FloatArray]:
        """Held-out R² per DOF of the base model and of the selected one, each shape (6,)."""
        return 1.0 - self.steps[0].cv / self.tss, 1.0 - self.steps[-1].cv / self.tss


#: Searches of :func:`select_terms` when the base has terms acting in several rows: their
#: force is estimated with the base, then with the terms the previous search chose.
SHARED_ROUNDS = 2


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


def _trials(G: FloatArray, bv: FloatArray, S: Sequence[int] | NDArray[np.int64],
            C: NDArray[np.int64],
            tol: float) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
    """Least squares on the columns S plus each one candidate c ∈ C, for all c at once.

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
    Sx = np.asarray(S, dtype=np.int64)
    gcc = np.diag(G)[C]
    if len(Sx):
        d = 1.0 / np.sqrt(np.maximum(np.diag(G)[Sx], 1e-300))
        Gss = G[np.ix_(Sx, Sx)] * np.outer(d, d)
        rhs = np.column_stack([G[np.ix_(Sx, C)], bv[Sx]]) * d[:, None]
        sol = np.linalg.lstsq(Gss, rhs, rcond=1e-13)[0] * d[:, None]
        X, beta = sol[:, :-1], sol[:, -1]
        den = gcc - np.einsum("kc,kc->c", G[np.ix_(Sx, C)], X)
        num = bv[C] - G[np.ix_(C, Sx)] @ beta
    else:
        X, beta = np.zeros((0, len(C))), np.zeros(0)
        den, num = gcc.copy(), bv[C].copy()
    ok = den > tol * np.maximum(gcc, 1e-300)
    th_c = np.where(ok, num / np.where(ok, den, 1.0), 0.0)
    th_S = beta[:, None] - X * th_c[None, :]
    return th_S, th_c, np.where(ok, num * th_c, 0.0), ok


def _held_out(A: FloatArray, b: FloatArray, c: FloatArray, S: Sequence[int],
              C: NDArray[np.int64], tol: float
              ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Blocked cross-validation of S and of S ∪ {c} for every c ∈ C in one row.

    Parameters
    ----------
    A : ndarray, shape (F, m, m)
    b : ndarray, shape (F, m)
    c : ndarray, shape (F,)
        Per-fold normal equations of the row.

    Returns
    -------
    cv_S : float array, shape ()
        Σ over folds of the held-out RSS of S, each fold predicted from the others.
    cv_C : ndarray, shape (|C|,)
        The same for S ∪ {c}.
    gain : ndarray, shape (|C|,)
        In-sample RSS(S) − RSS(S ∪ {c}) on all folds (``ok`` folded in: 0 if collinear).
    coef : ndarray, shape (|C|,)
        The coefficient of c in the fit of S ∪ {c} on all folds.
    """
    Sx = np.asarray(S, dtype=np.int64)
    G, bv = A.sum(0), b.sum(0)
    _, coef, gain, ok = _trials(G, bv, Sx, C, tol)
    cv_S = np.zeros(())
    cv_C = np.zeros(len(C))
    for f in range(len(c)):
        th_S, th_c, _, okf = _trials(G - A[f], bv - b[f], Sx, C, tol)
        Af, bf = A[f], b[f]
        # ‖y − Φθ‖² on fold f = c − 2 bᵀθ + θᵀAθ, θ = (θ_S, θ_c) for each candidate
        quad_S = np.einsum("kc,kl,lc->c", th_S, Af[np.ix_(Sx, Sx)], th_S)
        cross = np.einsum("ck,kc->c", Af[np.ix_(C, Sx)], th_S)
        cv_C += (c[f] - 2.0 * (bf[Sx] @ th_S + bf[C] * th_c) + quad_S
                 + 2.0 * th_c * cross + th_c ** 2 * np.diag(Af)[C])
        cv_C[~okf] = np.inf
        if len(Sx):
            d = 1.0 / np.sqrt(np.maximum(np.diag(G - A[f])[Sx], 1e-300))
            Gss = (G - A[f])[np.ix_(Sx, Sx)] * np.outer(d, d)
            beta = np.linalg.lstsq(Gss, (bv - b[f])[Sx] * d, rcond=1e-13)[0] * d
            cv_S = cv_S + c[f] - 2.0 * bf[Sx] @ beta + beta @ Af[np.ix_(Sx, Sx)] @ beta
        else:
            cv_S = cv_S + c[f]
    return cv_S, np.where(ok, cv_C, np.inf), gain, coef


def select_terms(samples: Samples, base: DampingModel, body: RigidBody,
                 cross: Sequence[dict[str, str]] | None = None,
                 families: Sequence[str] = FAMILIES,
                 memory_dofs: Sequence[int] = (0, 1, 2, 5), cutoff: float = 2.0,
                 folds: int = 5, max_terms: int = 25, min_improvement: float = 10.0,
                 min_err: float = 0.1, tol: float = 1e-8, strict_base: bool = True,
                 rounds: int = 10, exchange: float = 2.0
                 ) -> Selection:
    """Forward selection of library terms and memory states on top of ``base``.

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
        Contiguous time blocks of the cross-validation.
    max_terms : int
        Largest number of parameters of the selected model (base included).
    min_improvement : float
        BIC decrease needed to add a candidate (10: "very strong" on the Kass–Raftery scale).
    min_err : float
        Share of its row's remaining residual sum of squares a candidate must remove: the
        residuals are correlated (model and processing errors), so BIC alone over-counts
        evidence for small terms.
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

    Returns
    -------
    Selection

    Base parameters that act in several rows at once (the ``coriolis`` term) cannot be chosen
    row by row: they stay, and the search runs on the target less their force, estimated by
    least squares with the base, then again with the terms the first search chose
    (:data:`SHARED_ROUNDS` searches); the fit of the selected model estimates them with the
    chosen terms.
    """
    options: dict[str, Any] = {
        "cross": cross, "families": families, "memory_dofs": memory_dofs, "cutoff": cutoff,
        "folds": folds, "max_terms": max_terms, "min_improvement": min_improvement,
        "min_err": min_err, "tol": tol, "strict_base": strict_base, "rounds": rounds,
        "exchange": exchange}
    shared = [t for t in base.terms if any(b.more for b in t.bases)]
    if not shared:
        return _search(samples, base, body, (), **options)
    single = DampingModel([t for t in base.terms if t not in shared])
    model = base
    for _ in range(SHARED_ROUNDS):
        theta = _least_squares(samples, model, body, cutoff)
        values = dict(zip(model.parameter_names, theta, strict=True))
        part = DampingModel(shared)
        known = part.force(samples.nu, np.array([values[n] for n in part.parameter_names]))
        # y − Φ_shared θ_shared: the same as τ less that force
        selection = _search(replace(samples, tau=samples.tau - known), single, body, shared,
                            **options)
        model = selection.model
    return selection


def _search(samples: Samples, base: DampingModel, body: RigidBody,
            shared: Sequence[DampingTerm], cross: Sequence[dict[str, str]] | None,
            families: Sequence[str], memory_dofs: Sequence[int], cutoff: float, folds: int,
            max_terms: int, min_improvement: float, min_err: float, tol: float,
            strict_base: bool, rounds: int, exchange: float) -> Selection:
    """The stepwise search of :func:`select_terms` on top of the single-row terms ``base``;
    the ``shared`` terms count in the budget and join the selected model."""
    n_shared = sum(t.n_params for t in shared)
    base_names = base.parameter_names
    specs = library(families) if cross is None else [CrossSpec.from_dict(c) for c in cross]
    specs = [sp for sp in specs if sp.label not in base_names]
    # features: the base's single-entry columns first, then the candidates (simplest first)
    keys: dict[tuple[Any, ...], int] = {}
    feats: list[tuple[int, Alpha]] = []

    def feature(col: int, alpha: Alpha) -> int:
        k = _key(col, alpha)
        if k not in keys:
            keys[k] = len(feats)
            feats.append((col, alpha))
        return keys[k]

    base_cols: list[tuple[int, int, str]] = []  # (row, feature, name)
    for t in base.terms:
        if t.kind != "freq":
            for bs in t.bases:
                r, col = _single_entry(bs)
                base_cols.append((r, feature(col, bs.alpha), bs.name))
    cand = [(sp.row, feature(sp.col, sp.alpha), sp) for sp in specs]
    m = len(feats)
    # memory: the base's states, then candidate states with profiled rates
    mem0 = base.term("freq")
    duration = len(samples) / samples.rate
    n_eff = min(float(len(samples)), 2.0 * cutoff * duration)
    rates: dict[int, float] = {}
    dropped: dict[str, str] = {}
    if mem0 is None and memory_dofs:
        evidence = memory_evidence(samples, base, body, memory_dofs, cutoff)
        for ev in evidence:
            if ev.contradiction:
                dropped[f"memory on {DOF_NAMES[ev.dof]}"] = ev.contradiction
            else:
                rates[ev.dof] = ev.rate
    mem_rates = np.r_[mem0.rates if mem0 is not None else [], list(rates.values())]
    mem_dofs = np.r_[mem0.state_dofs if mem0 is not None else [], list(rates)].astype(np.int64)
    n0 = mem0.n_states if mem0 is not None else 0
    if mem0 is not None:
        base_cols += [(int(d), m + k, nm) for k, (d, nm) in
                      enumerate(zip(mem0.state_dofs, mem0.parameter_names, strict=True))]
    ne = _feature_equations(samples, feats, mem_rates, mem_dofs, body, folds, cutoff)
    N = float(ne.n.sum())
    G0 = ne.A.sum(0)[0][:m, :m]  # the features' Gram matrix (the same in every row)
    # zero and numerically equal columns (up to scale), compared with those before them
    g = np.diag(G0)
    zero = g <= 1e-12 * max(float(g.max()), 1e-300)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.abs(G0) / np.sqrt(np.outer(g, g))
    same_as = np.full(m, -1)
    for k in range(m):
        if not zero[k]:
            earlier = np.flatnonzero((corr[k, :k] > 1.0 - tol) & ~zero[:k] & (same_as[:k] < 0))
            same_as[k] = earlier[0] if len(earlier) else -1
    row_names = {(r, f): nm for r, f, nm in base_cols}
    usable: list[tuple[int, int, str]] = []  # (row, column, name)
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
    for k, d in enumerate(mem_dofs[n0:]):
        usable.append((int(d), m + n0 + k, f"memory on {DOF_NAMES[int(d)]} "
                                           f"(λ = {rates[int(d)]:.3g} 1/s)"))
    spec_of = {sp.label: sp for _, _, sp in cand}
    # stepwise search, every row at once: forward while a candidate qualifies and the budget
    # allows, then backward (a later term can make an earlier one redundant), repeated
    chosen = {i: [f for r, f, _ in base_cols if r == i] for i in range(6)}
    name_of = {(r, f): nm for r, f, nm in [*base_cols, *usable]}
    # the base's memory states, and its columns the data leave at zero (the fit flags them
    # 'no excitation' rather than the selection hiding them)
    keep_always = {(r, f) for r, f, _ in base_cols if f >= m or zero[f]}
    from_base = {(r, f) for r, f, _ in base_cols}
    pool = {i: [f for r, f, _ in usable if r == i] for i in range(6)}
    rss = np.array([ne.c.sum(0)[i] - _fit_row(ne, i, chosen[i]) for i in range(6)])
    tss = np.maximum(ne.c.sum(0), 1e-300)

    def refresh(i: int) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        return _held_out(ne.A[:, i], ne.b[:, i], ne.c[:, i], chosen[i],
                         np.array(pool[i], dtype=np.int64), tol)

    state = {i: refresh(i) for i in range(6)}
    cv = np.array([float(state[i][0]) for i in range(6)])
    k_now = base.n_params + n_shared
    log_n = float(np.log(n_eff))

    def crit(r: FloatArray, k: int) -> tuple[float, float]:
        ll = n_eff * float(np.sum(np.log(np.maximum(r, 1e-300) / N)))
        return ll + k * log_n, ll + 2.0 * k

    def record(label: str, i: int) -> None:
        bic, aic = crit(rss, k_now)
        steps.append(SelectionStep(label, k_now, rss.copy(), bic, aic,
                                   1.0 - rss[i] / max(steps[-1].rss[i], 1e-300), cv.copy()))

    bic, aic = crit(rss, k_now)
    steps = [SelectionStep("base: " + "+".join([*base.kinds, *(t.kind for t in shared)]), k_now,
                           rss.copy(), bic, aic, 0.0, cv.copy())]
    def best_addition(rows: Sequence[int] = range(6)) -> tuple[float, int, int] | None:
        """(score, row, pool index) of the candidate with the largest held-out gain (score
        = change of the row's held-out unexplained share, < 0) among those that qualify."""
        best: tuple[float, int, int] | None = None
        for i in rows:
            _, cv_c, gain, coef = state[i]
            if not len(cv_c):
                continue
            new = np.maximum(rss[i] - gain, 1e-300)
            dbic = n_eff * np.log(new / max(rss[i], 1e-300)) + log_n
            # a memory state enters only as passive memory (gain c > 0)
            passive = (np.array(pool[i]) < m) | (coef > 0)
            good = ((dbic < -min_improvement) & (gain >= min_err * rss[i])
                    & (cv_c < cv[i]) & np.isfinite(cv_c) & passive)
            if good.any():
                score = np.where(good, (cv_c - cv[i]) / tss[i], np.inf)
                j = int(np.argmin(score))
                if best is None or score[j] < best[0]:
                    best = (float(score[j]), i, j)
        return best

    def remove(i: int, col: int, rss_wo: float, cv_wo: float) -> None:
        nonlocal k_now
        rss[i], cv[i] = rss_wo, cv_wo
        chosen[i].remove(col)
        k_now -= 1
        state[i] = refresh(i)
        record("− " + name_of[(i, col)], i)

    def add(i: int, j: int) -> None:
        nonlocal k_now
        f = pool[i].pop(j)
        cv[i] = float(state[i][1][j])
        rss[i] = max(float(rss[i] - state[i][2][j]), 0.0)
        chosen[i].append(f)
        k_now += 1
        state[i] = refresh(i)
        record(name_of[(i, f)], i)

    for _ in range(rounds):
        changed = False
        while k_now < max_terms:
            best = best_addition()
            if best is None:
                break
            add(best[1], best[2])
            changed = True
        while True:
            # the weakest term: a searched one that no longer passes the test it entered by,
            # or a base one whose removal lowers BIC; it does not come back (no cycling)
            worst: tuple[float, int, int, float, float] | None = None
            cheapest: tuple[float, int, int, float, float] | None = None
            cheapest_in: dict[int, tuple[float, int, int, float, float]] = {}
            for i in range(6):
                for col in chosen[i]:
                    if (i, col) in keep_always:
                        continue
                    rest = [c for c in chosen[i] if c != col]
                    cv_wo, _, gain, coef = _held_out(ne.A[:, i], ne.b[:, i], ne.c[:, i], rest,
                                                     np.array([col], dtype=np.int64), tol)
                    rss_wo = rss[i] + float(gain[0])
                    dbic = n_eff * float(np.log(max(rss[i], 1e-300) / max(rss_wo, 1e-300))) \
                        + log_n
                    weak = dbic > 0.0 if ((i, col) in from_base and not strict_base) else not (
                        dbic < -min_improvement and rss_wo - rss[i] >= min_err * rss_wo
                        and cv[i] < float(cv_wo) and (col < m or float(coef[0]) > 0))
                    if weak and (worst is None or dbic > worst[0]):
                        worst = (dbic, i, col, rss_wo, float(cv_wo))
                    loss = (float(cv_wo) - cv[i]) / tss[i]
                    if cheapest is None or loss < cheapest[0]:
                        cheapest = (loss, i, col, rss_wo, float(cv_wo))
                    if i not in cheapest_in or loss < cheapest_in[i][0]:
                        cheapest_in[i] = (loss, i, col, rss_wo, float(cv_wo))
            if worst is not None:
                remove(*worst[1:])
                changed = True
                continue
            # at the budget: exchange the term whose loss costs least held-out R² for the best
            # candidate when that gains more than twice as much
            if k_now < max_terms:
                break
            best = best_addition()
            if best is not None and cheapest is not None and -best[0] > exchange * cheapest[0]:
                remove(*cheapest[1:])
                changed = True
                break
            # no DOF left behind: the worst-explained DOF takes the place of the cheapest term
            # of a DOF that stays better explained than the worst one is now (the smallest
            # held-out R² of the six rises with every such exchange, so they end)
            r2 = 1.0 - cv / tss
            w = int(np.argmin(r2))
            best = best_addition([w])
            if best is not None:
                donors = [c for i, c in cheapest_in.items() if i != w and r2[i] - c[0] > r2[w]]
                if donors:
                    remove(*min(donors)[1:])
                    add(best[1], best[2])
                    changed = True
            break
        if not changed:
            break
    final = {name_of[(i, f)] for i in range(6) for f in chosen[i]}
    base = _without(base, [n for n in base_names if n not in final])
    keep_cross = [spec_of[st.added] for st in steps[1:]
                  if st.added in spec_of and st.added in final]
    keep_mem = {int(d): rates[int(d)] for k, d in enumerate(mem_dofs[n0:])
                if m + n0 + k in chosen[int(d)]}
    # refine each chosen memory rate with the other chosen terms in place, and check it again
    # in both domains: a state that is no longer passive memory there goes
    memory = []
    for d in list(keep_mem):
        others = _with_terms(base, keep_cross, {k: v for k, v in keep_mem.items() if k != d})
        ev = memory_evidence(samples, others, body, [d], cutoff)[0]
        memory.append(ev)
        if ev.contradiction:
            dropped[f"memory on {DOF_NAMES[d]}"] = f"removed after the search: {ev.contradiction}"
            del keep_mem[d]
        else:
            keep_mem[d] = ev.rate
    model = _with_terms(base, keep_cross, keep_mem, shared)
    return Selection(model, steps, {f"freq.{DOF_NAMES[d]}.lambda1": lam
                                    for d, lam in keep_mem.items()}, dropped,
                     np.asarray(ne.c.sum(0), dtype=float), memory)


def _least_squares(samples: Samples, model: DampingModel, body: RigidBody, cutoff: float
                   ) -> FloatArray:
    """Unweighted least-squares θ of ``model`` (every parameter free), shape (p,)."""
    ne = accumulate(samples, model, body, cutoff=cutoff)
    A, b, _ = ne.total(np.ones(6))
    return solve_normal(A, b, np.ones(model.n_params, dtype=bool), np.zeros(model.n_params))


def _feature_equations(samples: Samples, feats: Sequence[tuple[int, Alpha]],
                       mem_rates: FloatArray, mem_dofs: NDArray[np.int64], body: RigidBody,
                       folds: int, cutoff: float) -> NormalEquations:
    """Per-fold normal equations of the library features in every row, each feature
    g_k(ν) = α_k(ν) ν_col computed, low-passed and multiplied once for all six rows.

    Column k < m = len(feats) is feature k in every row; column m + s is memory state s
    (ż = −λ_s z + ν_dof), which acts in the row of its DOF only. The same statistics as
    :func:`batch.accumulate` of a model with bases 1 e_colᵀ, at a sixth of the cost and memory.

    Returns
    -------
    NormalEquations
        A (folds, 6, p, p), b (folds, 6, p), c (folds, 6), n (folds,), p = m + len(mem_rates).
    """
    m = len(feats)
    cols = np.array([c for c, _ in feats], dtype=np.int64)
    bank = AlphaBank([a for _, a in feats])
    terms = [DampingTerm("freq", "memory candidates", rates=mem_rates, state_dofs=mem_dofs)] \
        if len(mem_rates) else []
    p = m + len(mem_rates)

    def features(nu: FloatArray, z: FloatArray | None) -> FloatArray:
        g = np.empty((len(nu), 1, p))
        # g_k = α_k(ν) ν_col(k)
        g[:, 0, :m] = bank(nu) * nu[:, cols]
        if z is not None:
            g[:, 0, m:] = z
        return g

    fold_of = fold_index(len(samples), folds)
    G = np.zeros((folds, p, p))
    Gy = np.zeros((folds, p, 6))
    c = np.zeros((folds, 6))
    n = np.zeros(folds)
    for rows, F3, y in iter_regression(samples, DampingModel(terms), body, cutoff=cutoff,
                                       decimate=True, regressor=features):
        F = F3[:, 0, :]
        fo = fold_of[rows]
        for f in np.unique(fo):
            k = fo == f
            # GᵀG, Gᵀy, yᵀy per fold
            G[f] += F[k].T @ F[k]
            Gy[f] += F[k].T @ y[k]
            c[f] += np.einsum("ni,ni->i", y[k], y[k])
            n[f] += int(k.sum())
    A = np.repeat(G[:, None], 6, axis=1)
    b = Gy.transpose(0, 2, 1).copy()
    for s, d in enumerate(mem_dofs):
        # memory state s acts in row d only
        other = [i for i in range(6) if i != int(d)]
        A[:, other, m + s, :] = 0.0
        A[:, other, :, m + s] = 0.0
        b[:, other, m + s] = 0.0
    return NormalEquations(A, b, c, n)


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
