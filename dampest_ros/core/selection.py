"""Term selection: which damping terms do the data support?

Forward selection by the Bayesian information criterion over a library of candidate terms
(cross-coupling coefficients and fluid-memory states), on top of a base model:

1. For each memory candidate DOF, its rate λ is found by a profile search: the regression is
   linear in the gain c for a fixed λ, so RSS(λ) = min_c RSS(c, λ) is minimised over log λ
   (staged nonlinear least squares).
2. The normal equations of the base model plus every candidate are accumulated once; the fit
   of any subset is then a sub-matrix solve, so trying a candidate costs no pass over data.
3. Greedy: add the candidate that lowers BIC most, while it lowers it by more than
   ``min_improvement`` (10: "very strong" evidence on the Kass–Raftery scale) and removes at
   least ``min_err`` of its DOF's residual (error-reduction ratio).

BIC = n_eff Σ_i log(RSS_i / N) + k log n_eff, with n_eff = 2 · cutoff · T the number of
independent samples in the low-passed regression (DESIGN: parallel filtering).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from dampest_ros.core.batch import NormalEquations, _solve, accumulate, iter_regression
from dampest_ros.core.damping import (
    CrossSpec,
    DampingModel,
    DampingTerm,
    cross_term,
    filter_memory,
    memory_term,
)
from dampest_ros.core.preprocess import zero_phase
from dampest_ros.core.rigid_body import DOF_NAMES, RigidBody
from dampest_ros.core.samples import Samples

FloatArray = NDArray[np.float64]

#: Common couplings of a box- or torpedo-shaped vehicle: sway–yaw and heave–pitch damping
#: cross terms and the surge–heave lift (Fossen 2011, §6.4; SNAME names, |x| as in X_uu).
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
    error-reduction ratio, the share of its DOF's residual sum of squares it removed."""

    added: str
    n_params: int
    rss: FloatArray
    bic: float
    aic: float
    err: float


@dataclass
class Selection:
    """Result of :func:`select_terms`: the chosen model and the path that led to it."""

    model: DampingModel
    steps: list[SelectionStep] = field(default_factory=list)
    rates: dict[str, float] = field(default_factory=dict)


def _criteria(ne: NormalEquations, idx: NDArray[np.int64], weights: FloatArray, n_eff: float
              ) -> tuple[FloatArray, float, float]:
    """RSS per DOF, BIC and AIC of the least-squares fit on the columns ``idx``."""
    A = np.einsum("i,fipq->pq", weights, ne.A)[np.ix_(idx, idx)]
    b = np.einsum("i,fip->p", weights, ne.b)[idx]
    theta = _solve(A, b, np.ones(len(idx), dtype=bool), np.zeros(len(idx)))
    full = np.zeros(ne.A.shape[-1])
    full[idx] = theta
    rss = np.maximum(ne.rss(full), 1e-300)
    n = float(ne.n.sum())
    ll = n_eff * float(np.sum(np.log(rss / n)))
    return rss, ll + len(idx) * float(np.log(n_eff)), ll + 2.0 * len(idx)


def _with_terms(base: DampingModel, cross: Sequence[CrossSpec],
                memory: dict[int, float]) -> DampingModel:
    terms: dict[str, DampingTerm] = {t.kind: t for t in base.terms}
    if cross:
        extra = cross_term(list(cross))
        old = terms.get("cross")
        terms["cross"] = DampingTerm("cross", extra.meaning,
                                     (old.bases if old else []) + extra.bases)
    if memory:
        terms["freq"] = memory_term({DOF_NAMES[d]: [lam] for d, lam in memory.items()})
    order = ("linear", "quadratic", "cross", "freq", "added", "residual")
    return DampingModel([terms[k] for k in order if k in terms])


def profile_rate(samples: Samples, base: DampingModel, body: RigidBody, dof: int,
                 weights: FloatArray, cutoff: float, bounds: tuple[float, float] = (0.05, 20.0)
                 ) -> tuple[float, float]:
    """Memory rate λ of one DOF by minimising the profiled weighted RSS over log λ.

    The memory column only acts on row ``dof``, so the base model's low-passed regressor
    row and target of that DOF are kept once; each trial λ then costs one recursive filter
    of ν_dof and one low-pass, not a pass over the full regression.

    Returns
    -------
    rate : float
        λ (1/s).
    rss : float
        Weighted RSS at that rate.
    """
    ne = accumulate(samples, base, body, folds=1, cutoff=cutoff)
    A = np.einsum("i,fipq->pq", weights, ne.A)
    b = np.einsum("i,fip->p", weights, ne.b)
    c = float(np.einsum("i,fi->", weights, ne.c))
    # the same (decimated) samples as the normal equations
    parts = [(np.arange(len(samples))[sl], Phi[:, dof, :], y[:, dof])
             for sl, Phi, y in iter_regression(samples, base, body, cutoff=cutoff,
                                               decimate=True)]
    used = np.concatenate([p[0] for p in parts])
    rows = np.concatenate([p[1] for p in parts])
    y_d = np.concatenate([p[2] for p in parts])
    w = float(weights[dof])

    def cost(log_rate: float) -> float:
        lam = np.array([np.exp(log_rate)])
        z = np.empty(len(samples))
        for sl in samples.segments():
            zs = filter_memory(samples.t[sl], samples.nu[sl, dof:dof + 1], lam)[:, 0]
            z[sl] = zero_phase(zs, samples.rate, cutoff) if cutoff > 0 else zs
        z = z[used]
        # bordered normal equations: [A, a; aᵀ, s] [θ; c_m] = [b; β]
        a = w * rows.T @ z
        Ab = np.block([[A, a[:, None]], [a[None, :], np.array([[w * z @ z]])]])
        bb = np.r_[b, w * z @ y_d]
        theta = _solve(Ab, bb, np.ones(len(bb), dtype=bool), np.zeros(len(bb)))
        return c - float(bb @ theta)

    lo, hi = np.log(bounds[0]), np.log(bounds[1])
    grid = np.linspace(lo, hi, 13)
    values = [cost(g) for g in grid]
    k = int(np.argmin(values))
    res = optimize.minimize_scalar(cost, bounds=(grid[max(k - 1, 0)],
                                                 grid[min(k + 1, len(grid) - 1)]),
                                   method="bounded", options={"xatol": 1e-4})
    return float(np.exp(res.x)), float(res.fun)


def select_terms(samples: Samples, base: DampingModel, body: RigidBody,
                 cross: Sequence[dict[str, str]] = DEFAULT_CROSS,
                 memory_dofs: Sequence[int] = (0, 1, 2, 5), cutoff: float = 2.0,
                 min_improvement: float = 10.0, min_err: float = 0.1) -> Selection:
    """Forward BIC selection of cross-coupling and memory terms on top of ``base``.

    Parameters
    ----------
    samples : Samples
    base : DampingModel
        Terms always kept (typically linear + quadratic).
    body : RigidBody
    cross : sequence of dict
        Candidate cross coefficients (:class:`CrossSpec` mappings).
    memory_dofs : sequence of int
        DOFs that may carry a fluid-memory state.
    cutoff : float
        Parallel low-pass of the regression (Hz).
    min_improvement : float
        BIC decrease needed to add a candidate.
    min_err : float
        Share of its DOF's remaining residual sum of squares a candidate must remove: the
        residuals are correlated (model and processing errors), so BIC alone over-counts
        evidence for small terms.

    Returns
    -------
    Selection
    """
    base_names = set(base.parameter_names)
    specs = [s for s in (CrossSpec.from_dict(c) for c in cross) if s.label not in base_names]
    duration = len(samples) / samples.rate
    n_eff = min(float(len(samples)), 2.0 * cutoff * duration)
    ne0 = accumulate(samples, base, body, folds=1, cutoff=cutoff)
    idx0 = np.arange(base.n_params)
    rss0, _, _ = _criteria(ne0, idx0, np.ones(6), n_eff)
    # per-DOF weights 1/σ² from the base model's residuals
    weights = np.asarray(1.0 / np.maximum(rss0 / float(ne0.n.sum()), 1e-12))
    bounds = (0.05, 20.0)
    rates = {d: profile_rate(samples, base, body, d, weights, cutoff, bounds)[0]
             for d in memory_dofs}
    # a rate at the edge of the search range is a trend or an offset, not fluid memory
    rates = {d: lam for d, lam in rates.items()
             if bounds[0] * 1.05 < lam < bounds[1] / 1.05}
    superset = _with_terms(base, specs, rates)
    ne = accumulate(samples, superset, body, folds=1, cutoff=cutoff)
    names = superset.parameter_names
    groups = {s.label: [names.index(s.label)] for s in specs}
    mem = superset.term("freq")
    if mem is not None:
        for d, pname in zip(mem.state_dofs, mem.parameter_names, strict=True):
            groups[f"memory on {DOF_NAMES[int(d)]} (λ = {rates[int(d)]:.3g} 1/s)"] = \
                [names.index(pname)]
    chosen = [names.index(n) for n in base.parameter_names]
    rss, bic, aic = _criteria(ne, np.array(chosen), weights, n_eff)
    steps = [SelectionStep("base: " + "+".join(base.kinds), len(chosen), rss, bic, aic, 0.0)]
    row = {s.label: s.row for s in specs}
    if mem is not None:
        row.update({g: int(d) for g, d in zip(list(groups)[len(specs):], mem.state_dofs,
                                               strict=True)})
    remaining = dict(groups)
    while remaining:
        trials = {g: _criteria(ne, np.array(sorted(chosen + cols)), weights, n_eff)
                  for g, cols in remaining.items()}
        # evidence: BIC falls, and the term explains a share of its DOF's residual
        err = {g: 1.0 - trials[g][0][row[g]] / steps[-1].rss[row[g]] for g in trials}
        ok = [g for g in trials if trials[g][1] < steps[-1].bic - min_improvement
              and err[g] >= min_err]
        if not ok:
            break
        best = min(ok, key=lambda g: trials[g][1])
        chosen += remaining.pop(best)
        r, b_, a_ = trials[best]
        steps.append(SelectionStep(best, len(chosen), r, b_, a_, err[best]))
    keep_cross = [s for s in specs if names.index(s.label) in chosen]
    keep_mem = {int(d): rates[int(d)] for d, pname in
                zip(mem.state_dofs, mem.parameter_names, strict=True)
                if names.index(pname) in chosen} if mem is not None else {}
    # refine each chosen memory rate with the other chosen terms in place
    for d in list(keep_mem):
        others = _with_terms(base, keep_cross, {k: v for k, v in keep_mem.items() if k != d})
        keep_mem[d] = profile_rate(samples, others, body, d, weights, cutoff, bounds)[0]
    model = _with_terms(base, keep_cross, keep_mem)
    return Selection(model, steps, {f"freq.{DOF_NAMES[d]}.lambda1": lam
                                    for d, lam in keep_mem.items()})


def shift_tau(samples: Samples, delay: float) -> Samples:
    """Samples whose τ is delayed by ``delay`` seconds within each segment (τ(t − d))."""
    tau = np.empty_like(samples.tau)
    for sl in samples.segments():
        t = samples.t[sl]
        for i in range(6):
            tau[sl, i] = np.interp(t - delay, t, samples.tau[sl, i])
    return Samples(samples.t, samples.nu, samples.nu_dot, tau, samples.euler, samples.depth,
                   samples.segment)


def profile_delay(samples: Samples, model: DampingModel, body: RigidBody, cutoff: float = 2.0,
                  bounds: tuple[float, float] = (-0.05, 0.5)) -> float:
    """Delay (s) of the response after τ that minimises the residual of the fit.

    Each trial shifts the (band-limited) τ and refits by least squares on the decimated,
    low-passed regression; a coarse grid then a bounded scalar search.
    """
    def cost(delay: float) -> float:
        ne = accumulate(shift_tau(samples, delay), model, body, folds=1, cutoff=cutoff)
        idx = np.arange(model.n_params)
        rss, _, _ = _criteria(ne, idx, np.ones(6), 1.0)
        # scale-free: sum of the per-DOF log residuals (DOFs with large forces do not rule)
        return float(np.sum(np.log(np.maximum(rss, 1e-300))))

    grid = np.linspace(bounds[0], bounds[1], 12)
    values = [cost(g) for g in grid]
    k = int(np.argmin(values))
    res = optimize.minimize_scalar(cost, bounds=(grid[max(k - 1, 0)],
                                                 grid[min(k + 1, len(grid) - 1)]),
                                   method="bounded", options={"xatol": 1e-3})
    return float(res.x)
