"""The search for the missing effects: screen every candidate on the held-out part of the
residual, refine the best significant one on its exact model, refit all added effects jointly,
repeat until none is significant (:func:`find_gap`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, optimize, stats

from dampest_ros.core.gap.data import FORCE_UNITS, Chunk, GapData, bind, noise_weights, rms
from dampest_ros.core.gap.effects import Effect
from dampest_ros.core.gap.library import library
from dampest_ros.core.gap.trust import Degradation, degradations
from dampest_ros.core.gap.update import updated_model
from dampest_ros.core.identification.regression import information_criteria
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, ConfigError

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

NO_FURTHER = "no further missing effect found"


# --- screening and fitting ------------------------------------------------------------------


@dataclass
class Screen:
    """One candidate screened against the current residual.

    Attributes
    ----------
    effect : Effect
    p : ndarray, shape (k,)
        Magnitudes fitted on the training part (linearised model).
    rss_train, rss_test : ndarray, shape (6,)
        Residual sums of squares per DOF after the fit.
    heldout : float
        Held-out reduction of the weighted residual sum of squares (0..1).
    heldout_dof : ndarray, shape (6,)
        Held-out reduction per DOF.
    gain : float
        Held-out log-likelihood gain ½ n_eff Σ_i log(RSS_i,before / RSS_i,after).
    dbic : float
        BIC change on the training part (negative: evidence for the effect).
    err : float
        Error-reduction ratio on the training part (weighted).
    relevance : float
        Held-out RMS of the force the effect explains, as a share of the force scale of its
        DOF (:attr:`GapData.force_scale`), largest over DOFs.
    significant : bool
    note : str
        Why the fitted magnitudes do not describe the effect (then not significant).
    """

    effect: Effect
    p: FloatArray
    rss_train: FloatArray
    rss_test: FloatArray
    heldout: float
    heldout_dof: FloatArray
    gain: float
    dbic: float
    err: float
    relevance: float
    significant: bool = False
    note: str = ""

    def score(self, n_eff: float) -> float:
        """Held-out evidence for ranking: the gain less ½ k log n_eff (parsimony)."""
        return self.gain - 0.5 * self.effect.k * float(np.log(max(n_eff, 2.0)))


@dataclass
class Step:
    """One accepted effect and the state of the model after it.

    Attributes
    ----------
    effect : Effect
    screen : Screen
        The screening result that chose it.
    p : ndarray, shape (k,)
        Magnitudes after the exact refit (all added effects refitted jointly).
    cov : ndarray, shape (k, k)
        Block-robust covariance of p.
    rms_before, rms_after : ndarray, shape (6,)
        Held-out residual RMS per DOF before and after the step (N, N·m).
    bic_before, bic_after : float
        BIC of the training part (n_eff Σ_i log(RSS_i/N) + k log n_eff).
    runner_up : str
        Title of the second-best candidate (what it competed with).
    worse : list of Degradation
        The DOFs whose held-out residual grew in the step, with why
        (:func:`.trust.degradations`).
    """

    effect: Effect
    screen: Screen
    p: FloatArray
    cov: FloatArray
    rms_before: FloatArray
    rms_after: FloatArray
    bic_before: float
    bic_after: float
    runner_up: str = ""
    worse: list[Degradation] = field(default_factory=list)

    @property
    def description(self) -> str:
        """The magnitude in words."""
        return self.effect.describe(self.p, self.cov)

    @property
    def reduction(self) -> FloatArray:
        """Held-out RMS reduction per DOF (0..1), shape (6,)."""
        return np.asarray(1.0 - self.rms_after / np.maximum(self.rms_before, 1e-300))


@dataclass
class GapResult:
    """Outcome of :func:`find_gap`.

    Attributes
    ----------
    steps : list of Step
    effects : list of (Effect, ndarray)
        The added effects with their final (jointly refitted) magnitudes.
    covs : list of ndarray
        Their covariances.
    r0 : ndarray, shape (N, 6)
        Residual of the believed model.
    r : ndarray, shape (N, 6)
        Residual after the added effects.
    screens : list of list of Screen
        All screening results of every round (the last round found nothing significant).
    skipped : dict of str to str
        Candidates that could not be tested, with the reason.
    conclusion : str
    rejected : dict of str to str
        Significant candidates that were not added, with the reason of their last rejection
        (:func:`rejection`).
    """

    steps: list[Step]
    effects: list[tuple[Effect, FloatArray]]
    covs: list[FloatArray]
    r0: FloatArray
    r: FloatArray
    screens: list[list[Screen]] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)
    conclusion: str = NO_FURTHER
    rejected: dict[str, str] = field(default_factory=dict)

    @property
    def named(self) -> list[str]:
        """Keys of the effects named, in order."""
        return [s.effect.key for s in self.steps]


@dataclass(frozen=True)
class GapOptions:
    """Thresholds of the search.

    Attributes
    ----------
    min_heldout : float
        Smallest held-out reduction of the weighted residual sum of squares (share).
    min_heldout_dof : float
        Smallest held-out reduction of the residual sum of squares in the best DOF.
    min_bic : float
        Smallest BIC decrease on the training part (10: "very strong" evidence).
    min_relevance : float
        Smallest held-out force the effect explains in some DOF, as a share of that DOF's
        force scale: effects far below the force level are real but do not matter (e.g. the
        drift of a gyro's bias within its specification).
    max_steps : int
    max_tries : int
        Significant candidates tried per round before the search stops (each is refitted
        and may be rejected, :func:`rejection`).
    refit_nfev : int
        Function evaluations of the exact refit.
    alpha : float
        Probability of naming an effect that is absent, for the test of its magnitudes
        against their own σ (:func:`insignificance`) and of the summed held-out gain
        (:func:`rejection`).
    max_trade : float
        Largest share of the held-out log-likelihood an effect gains that DOFs growing inside
        the believed model's flown envelope may cost (:func:`rejection`).
    """

    min_heldout: float = 0.03
    min_heldout_dof: float = 0.10
    min_bic: float = 10.0
    min_relevance: float = 0.0025
    max_steps: int = 6
    max_tries: int = 6
    refit_nfev: int = 30
    alpha: float = 1e-3
    max_trade: float = 0.1


def _lsq(X: FloatArray, y: FloatArray, w: FloatArray) -> FloatArray:
    """Weighted least squares Σ_n Σ_i w_i (y_ni − X_ni p)², minimum-norm for zero columns.

    Parameters
    ----------
    X : ndarray, shape (n, 6, k)
    y : ndarray, shape (n, 6)
    w : ndarray, shape (6,)
    """
    A = np.einsum("nik,nil,i->kl", X, X, w)
    b = np.einsum("nik,ni,i->k", X, y, w)
    d = np.sqrt(np.maximum(np.diag(A), 0.0))
    ok = d > 1e-9 * max(float(d.max()), 1e-300)
    p = np.zeros(X.shape[2])
    if ok.any():
        s = 1.0 / d[ok]
        As = A[np.ix_(ok, ok)] * np.outer(s, s)
        p[ok] = s * linalg.lstsq(As, s * b[ok], cond=1e-10)[0]
    return p


def _bic(rss: FloatArray, n: float, n_eff: float, k: int) -> float:
    """n_eff Σ_i log(RSS_i / n) + k log n_eff (:func:`information_criteria`)."""
    return information_criteria(rss, n, n_eff, k)[0]


def screen(data: GapData, effect: Effect, r: FloatArray, w: FloatArray,
           opts: GapOptions) -> Screen:
    """Fit ``effect``'s linearisation to the residual on the training part; score it on the
    held-out part.

    For each starting point p0 (:meth:`Effect.starts`) the residual is regressed on
    ρ(p0) + J(p0) Δp; the start with the smallest weighted training residual wins.

    Parameters
    ----------
    data : GapData
    effect : Effect
    r : ndarray, shape (N, 6)
        Current residual (N, N·m).
    w : ndarray, shape (6,)
        Per-DOF weights 1/σ².
    opts : GapOptions

    Returns
    -------
    Screen
    """
    tr, te = data.train, data.test
    best: tuple[float, FloatArray, FloatArray] | None = None
    for p0 in effect.starts(data):
        off = np.zeros_like(r) if effect.linear else \
            data.filtered(bind(effect.predict, data, p0))
        X = data.filtered(bind(effect.columns, data, p0))
        dp = _lsq(X[tr], (r - off)[tr], w)
        e = r - off - X @ dp
        cost = float(np.sum(w * np.sum(e[tr] ** 2, axis=0)))
        if best is None or cost < best[0]:
            best = (cost, p0 + dp, e)
    assert best is not None
    _, p, e = best
    lo, hi = effect.bounds()
    p = np.clip(p, lo, hi)
    before_tr = np.sum(r[tr] ** 2, axis=0)
    before_te = np.sum(r[te] ** 2, axis=0)
    rss_tr = np.sum(e[tr] ** 2, axis=0)
    rss_te = np.sum(e[te] ** 2, axis=0)
    heldout = 1.0 - float(w @ rss_te / (w @ before_te))
    heldout_dof = 1.0 - rss_te / np.maximum(before_te, 1e-300)
    gain = 0.5 * data.n_eff_test * float(np.sum(np.log(np.maximum(before_te, 1e-300)
                                                        / np.maximum(rss_te, 1e-300))))
    n_tr = float(tr.sum())
    dbic = _bic(rss_tr, n_tr, data.n_eff_train, effect.k) - _bic(before_tr, n_tr,
                                                                 data.n_eff_train, 0)
    err = 1.0 - float(w @ rss_tr / (w @ before_tr))
    explained = np.sqrt(np.mean((r - e)[te] ** 2, axis=0))
    relevance = float(np.max(explained / np.maximum(data.force_scale, 1e-300)))
    note = effect.implausible(data, p)
    sig = (heldout >= opts.min_heldout and float(heldout_dof.max()) >= opts.min_heldout_dof
           and dbic <= -opts.min_bic and relevance >= opts.min_relevance and not note)
    return Screen(effect, p, rss_tr, rss_te, heldout, heldout_dof, gain, dbic, err, relevance,
                  sig, note)


def correction(data: GapData, effects: Sequence[tuple[Effect, FloatArray]]) -> FloatArray:
    """Σ_e ρ_e(p_e), low-passed like the regression, shape (N, 6)."""
    out = np.zeros((len(data.samples), 6))
    if not effects:
        return out

    def total(ch: Chunk) -> FloatArray:
        return np.asarray(np.sum([e.predict(data, ch, p) for e, p in effects], axis=0),
                          dtype=float)

    return out + data.filtered(total)


def refit(data: GapData, effects: Sequence[tuple[Effect, FloatArray]], w: FloatArray,
          max_nfev: int = 30, reweight: int = 2) -> tuple[list[FloatArray], list[FloatArray]]:
    """Refit the magnitudes of all ``effects`` jointly on their exact models.

    Minimises Σ_train Σ_i w_i (r0 − Σ_e ρ_e(p_e))² with ``scipy.optimize.least_squares``
    (trust region, analytic columns for linear effects, central differences otherwise), then
    a block-robust covariance A⁻¹ (Σ_b s_b s_bᵀ) A⁻¹ of the magnitudes, blocks of
    ``data.block`` seconds (the residuals are correlated by the low-pass). The per-DOF
    weights start at ``w`` and are re-estimated ``reweight`` times from the residual the
    effects leave, so that they reflect the noise rather than the gap being explained.

    Returns
    -------
    ps : list of ndarray
        Magnitudes per effect.
    covs : list of ndarray
        Covariance per effect.
    """
    tr = data.train
    sizes = [e.k for e, _ in effects]
    cuts = np.cumsum(sizes)[:-1]
    x0 = np.concatenate([p for _, p in effects])
    lo = np.concatenate([e.bounds()[0] for e, _ in effects])
    hi = np.concatenate([e.bounds()[1] for e, _ in effects])
    # strictly inside finite bounds (least_squares' trust region needs an interior start)
    fin_lo, fin_hi = np.isfinite(lo), np.isfinite(hi)
    inner_lo, inner_hi = lo.copy(), hi.copy()
    inner_lo[fin_lo] += 1e-9 * (1 + np.abs(lo[fin_lo]))
    inner_hi[fin_hi] -= 1e-9 * (1 + np.abs(hi[fin_hi]))
    x0 = np.minimum(np.maximum(x0, inner_lo), inner_hi)
    scale = np.concatenate([np.asarray(e.steps, dtype=float) for e, _ in effects])
    sw = np.sqrt(w)
    lin_cols = {i: data.filtered(bind(e.columns, data, np.zeros(e.k)))
                for i, (e, _) in enumerate(effects) if e.linear}

    def split(x: FloatArray) -> list[tuple[Effect, FloatArray]]:
        return [(e, p) for (e, _), p in zip(effects, np.split(x, cuts), strict=True)]

    def resid(x: FloatArray) -> FloatArray:
        parts = split(x)
        rho = np.zeros_like(data.r0)
        nonlin = [(e, p) for e, p in parts if not e.linear]
        if nonlin:
            rho += correction(data, nonlin)
        for i, (_, p) in enumerate(parts):
            if i in lin_cols:
                rho += lin_cols[i] @ p
        return np.asarray(((data.r0 - rho)[tr] * sw).ravel(), dtype=float)

    def jac(x: FloatArray) -> FloatArray:
        cols = []
        for i, (e, p) in enumerate(split(x)):
            X = lin_cols[i] if i in lin_cols else data.filtered(bind(e.columns, data, p))
            cols.append(-(X[tr] * sw[None, :, None]).reshape(-1, e.k))
        return np.concatenate(cols, axis=1)

    x = x0
    for _ in range(reweight + 1):
        res = optimize.least_squares(resid, x, jac=jac, bounds=(lo, hi), x_scale=scale,
                                     method="trf", max_nfev=max_nfev, xtol=1e-6, ftol=1e-8)
        x = res.x
        # per-DOF weights from the residual the effects leave (the noise, not the gap)
        w = noise_weights(resid(x).reshape(-1, 6) / sw, np.ones(int(tr.sum()), dtype=bool))
        sw = np.sqrt(w)
    # block-robust covariance on the training rows
    J = jac(x).reshape(int(tr.sum()), 6, -1) / -sw[None, :, None]
    e = resid(x).reshape(-1, 6) / sw
    A = np.einsum("nik,nil,i->kl", J, J, w)
    g = np.einsum("nik,ni,i->nk", J, e, w)
    blocks = data.block_index[tr]
    S = np.zeros((int(blocks.max()) + 1, len(x)))
    np.add.at(S, blocks - int(blocks.min()), g)
    S = S[np.any(S != 0, axis=1)]
    B = len(S)
    Ainv = linalg.pinv(A)
    cov = Ainv @ (S.T @ S * (B / max(B - 1, 1))) @ Ainv
    ps = list(np.split(x, cuts))
    idx = np.split(np.arange(len(x)), cuts)
    return ps, [cov[np.ix_(i, i)] for i in idx]


def find_gap(data: GapData, candidates: Sequence[Effect] | None = None,
             options: GapOptions | None = None,
             progress: Callable[[str], None] | None = None) -> GapResult:
    """Name the missing effects one at a time until none is significant.

    Each round: weights 1/σ_i² from the current residual on the training part; every
    candidate not yet added is screened (:func:`screen`); the significant ones
    are tried in order of their held-out log-likelihood gain, less ½ log n_eff per unknown:
    all added effects and the candidate are refitted jointly on their exact models
    (:func:`refit`), and the candidate is added unless :func:`insignificance` or
    :func:`rejection` finds a reason (its magnitudes are within their own σ, a DOF grows
    inside the believed model's envelope by more than the others gain, the summed held-out
    gain is not significant, M would not be positive definite, D(ν) would generate
    energy), in which case the next one is tried (at most ``options.max_tries`` per round;
    a candidate rejected in one round is tried again in the next, when another effect may
    have taken the share of the residual it traded against). The held-out RMS per DOF
    before and after and the training BIC are recorded.

    Parameters
    ----------
    data : GapData
    candidates : sequence of Effect, optional
        Default: :func:`library`.
    options : GapOptions, optional
    progress : callable, optional
        Receives one line of text per step and per rejected candidate.

    Returns
    -------
    GapResult
    """
    opts = options or GapOptions()
    cands = list(candidates) if candidates is not None else library()
    skipped = {e.key: why for e in cands if (why := e.available(data))}
    cands = [e for e in cands if e.key not in skipped]
    added: list[tuple[Effect, FloatArray]] = []
    covs: list[FloatArray] = []
    steps: list[Step] = []
    screens: list[list[Screen]] = []
    rejected: dict[str, str] = {}
    r = data.r0.copy()
    tr, te = data.train, data.test
    n_tr = float(tr.sum())
    k_total = 0
    conclusion = NO_FURTHER
    while True:
        w = noise_weights(r, tr)
        done = {a.key for a, _ in added}
        round_ = [screen(data, e, r, w, opts) for e in cands if e.key not in done]
        round_.sort(key=lambda s: -s.score(data.n_eff_test))
        screens.append(round_)
        ok = [s for s in round_ if s.significant]
        if ok and len(steps) >= opts.max_steps:
            conclusion = (f"stopped after --max-steps {opts.max_steps}; "
                          f"{ok[0].effect.title} is still significant")
            break
        chosen = None
        for cand in ok[:opts.max_tries]:
            trial = [*added, (cand.effect, cand.p)]
            ps, cs = refit(data, trial, w, opts.refit_nfev)
            new = [(e, p) for (e, _), p in zip(trial, ps, strict=True)]
            r_new = data.r0 - correction(data, new)
            why = insignificance(cand.effect, new[-1][1], cs[-1], opts.alpha) or \
                rejection(data, new, r, r_new, cand.effect.k, opts.min_relevance, opts.alpha,
                          opts.max_trade)
            if not why:
                chosen = cand, new, cs, r_new
                rejected.pop(cand.effect.key, None)
                break
            rejected[cand.effect.key] = why
            if progress:
                progress(f"rejected: {cand.effect.title}: {why}")
        if chosen is None:
            break
        best, new, cs, r_new = chosen
        if progress:
            progress(f"step {len(steps) + 1}: {best.effect.title} (held-out −"
                     f"{100 * best.heldout:.1f} %, ΔBIC {best.dbic:.0f})")
        bic_before = _bic(np.sum(r[tr] ** 2, axis=0), n_tr, data.n_eff_train, k_total)
        k_total += best.effect.k
        bic_after = _bic(np.sum(r_new[tr] ** 2, axis=0), n_tr, data.n_eff_train, k_total)
        runner = next((s.effect.title for s in round_ if s is not best), "")
        worse = degradations(data, new, r, r_new, best.effect.k, opts.min_relevance)
        steps.append(Step(best.effect, best, new[-1][1], cs[-1], rms(r, te), rms(r_new, te),
                          bic_before, bic_after, runner, worse))
        added, covs, r = new, cs, r_new
    return GapResult(steps, added, covs, data.r0, r, screens, skipped, conclusion, rejected)


def insignificance(effect: Effect, p: FloatArray, cov: FloatArray, alpha: float) -> str:
    """Why the magnitudes ``p`` of ``effect`` are not significant given their own covariance;
    empty when they are.

    The Wald statistic W = p_mᵀ C_mm⁻¹ p_m of the magnitudes m (:attr:`Effect.magnitudes`)
    is χ²(|m|) when the effect is absent; the effect is significant when W exceeds the
    (1 − α) quantile (α = 1e-3: 3.3 σ for one magnitude, 13.8 for two). A current of
    0.013 ± 0.006 m/s in a pool is not.

    Parameters
    ----------
    effect : Effect
    p : ndarray, shape (k,)
    cov : ndarray, shape (k, k)
        Block-robust covariance of p (:func:`refit`).
    alpha : float
        False-alarm probability of naming an absent effect.
    """
    m = list(range(effect.k) if effect.magnitudes is None else effect.magnitudes)
    pm, C = p[m], cov[np.ix_(m, m)]
    try:
        # W = p_mᵀ C⁻¹ p_m
        w = float(pm @ np.linalg.solve(C, pm))
    except np.linalg.LinAlgError:
        return "its magnitudes have no covariance (not determined by these data)"
    limit = float(stats.chi2.isf(alpha, len(m)))
    if np.isfinite(w) and w > limit:
        return ""
    return (f"below its own significance: {effect.describe(p, cov)} (Wald {w:.3g} ≤ "
            f"{limit:.3g}, the χ² {100 * (1 - alpha):g} % point of {len(m)} magnitude(s))")


def rejection(data: GapData, effects: Sequence[tuple[Effect, FloatArray]], r_before: FloatArray,
              r_after: FloatArray, k: int, min_change: float = GapOptions.min_relevance,
              alpha: float = GapOptions.alpha, max_trade: float = GapOptions.max_trade
              ) -> str:
    """Why the model with ``effects`` (the last one new) must not be accepted; empty if it may.

    The step is weighed on the whole held-out evidence, the log-likelihood gain of the
    stacked DOFs ½ n_eff Σ_i log(MS_i,before / MS_i,after) (each DOF normalised by its own
    noise). A DOF that grows only where the effects move ν_r outside the believed model's
    flown envelope is extrapolation of that model (:func:`.trust.degradations`) and is left
    out of the sum. Reasons, in this order:

    - DOFs grow inside the envelope by more than ``max_trade`` of what the other DOFs gain
      (in log-likelihood): the effect trades a DOF against another, which describes a
      modelling error, not itself;
    - the summed gain is not significant: twice it stays below the χ²(k) (1 − ``alpha``)
      point;
    - the updated M_RB + M_A is not symmetric positive definite (or M_A not positive
      semi-definite);
    - the updated D(ν) generates energy: νᵀD(ν)ν below the believed model's smallest value
      (and below 0) on the data or on a grid over the flown envelope
      (:meth:`GapData.power_points`), or a fluid-memory gain c < 0 (an active kernel).

    Parameters
    ----------
    data : GapData
    effects : sequence of (Effect, ndarray)
    r_before, r_after : ndarray, shape (N, 6)
        Residual before and after the step (N, N·m).
    k : int
        Unknowns of the new effect.
    min_change : float
        Smallest rise of a DOF's held-out RMS that counts, as a share of its force scale.
    alpha : float
        False-alarm probability of the summed gain.
    max_trade : float
        Largest share of the gained log-likelihood that DOFs growing inside the envelope may
        cost.
    """
    te = data.test
    ms0 = np.mean(r_before[te] ** 2, axis=0)
    ms1 = np.mean(r_after[te] ** 2, axis=0)
    gain = 0.5 * data.n_eff_test * np.log(np.maximum(ms0, 1e-300) / np.maximum(ms1, 1e-300))
    worse = degradations(data, effects, r_before, r_after, k, min_change)
    counted = np.ones(6, dtype=bool)
    counted[[d.dof for d in worse if d.extrapolation]] = False
    inside = [d for d in worse if not d.extrapolation]
    gained = float(np.sum(np.maximum(gain[counted], 0.0)))
    lost = float(sum(-gain[d.dof] for d in inside))
    if inside and lost > max_trade * gained:
        d = max(inside, key=lambda d: d.after / max(d.before, 1e-300))
        return (f"the held-out residual of {FORCE_NAMES[d.dof]} grows (RMS {d.before:.3g} → "
                f"{d.after:.3g} {FORCE_UNITS[d.dof]}, {d.why}), more than "
                f"{100 * max_trade:g} % of what the other DOFs gain")
    evidence = float(np.sum(gain[counted]))
    limit = float(stats.chi2.isf(alpha, k))
    if 2.0 * evidence <= limit:
        return (f"the held-out evidence summed over the DOFs is not significant (2 Δlog L "
                f"{2.0 * evidence:.3g} ≤ {limit:.3g})")
    upd = updated_model(data, effects)
    try:
        upd.body(data)
    except ConfigError as exc:
        return f"the mass matrix would be invalid: {exc.field} {exc.reason}"
    return dissipation_violation(data, upd.model, upd.theta)


def dissipation_violation(data: GapData, model: DampingModel, theta: FloatArray) -> str:
    """Where ``model`` with ``theta`` generates energy and the believed model does not;
    empty if nowhere.

    νᵀD(ν)ν (static terms, W) is evaluated on :meth:`GapData.power_points`; the bound is the
    believed model's smallest value there when that is negative, else 0 (less 1e-9 of the
    believed model's largest |νᵀD(ν)ν| for rounding). Fluid-memory gains must be ≥ 0 (or not
    below the believed model's smallest).
    """
    pts = data.power_points
    P0 = data.model.dissipation(pts, data.theta)
    P = model.dissipation(pts, theta)
    floor = min(float(P0.min()), 0.0) - 1e-9 * max(float(np.abs(P0).max()), 1.0)
    if float(P.min()) < floor:
        j = int(np.argmin(P))
        nu = ", ".join(f"{n} {v:+.2g}" for n, v in zip(DOF_NAMES, pts[j], strict=True) if v)
        return (f"D(ν) would generate energy: νᵀD(ν)ν = {float(P[j]):.3g} W at ν = "
                f"({nu or 'rest'})")
    c0, c = data.model.memory_gain(data.theta), model.memory_gain(theta)
    c_floor = min(float(c0.min()) if c0.size else 0.0, 0.0)
    if c.size and float(c.min()) < c_floor:
        return f"a fluid-memory gain c = {float(c.min()):.3g} < 0 would generate energy"
    return ""
