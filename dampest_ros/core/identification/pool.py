"""Many logs of one vehicle: the pooled fit and the drift of the damping between logs.

The batch fit's normal equations are sufficient statistics: the statistics of several logs
add up to those of all their samples at once, A = Σ_b A_b, b = Σ_b b_b, c = Σ_b c_b. Each log
is therefore preprocessed and reduced on its own (in parallel, anywhere: :class:`LogStatistics`
is all a worker sends; the samples stay where they were read), and the pooled fit solves the
summed statistics, the sensor-bias
refits' included (:class:`~dampest_ros.core.identification.covariance.BiasStatistics`), and
so do the block-robust covariance's per-block normal equations
(:class:`~dampest_ros.core.identification.regression.BlockEquations`, each log's blocks
counted from its own start) when the block length does not depend on the fit's rank. The
passes over the samples left (the scan for samples where the estimate generates energy, and
the covariance's when its blocks did not come with the statistics) run over the logs'
samples as segments of one set, log by log where each log is held (``map_logs``), and so
does the one that joins their :class:`~dampest_ros.core.signals.extent.Extent` (the pooled
percentiles of |ν| and |τ| from each log's largest values).
Cross-validation folds of the pooled fit are the k-th fifths of
every log (:func:`pooled_normal`), so each fold holds some of every trial.

Drift: each log's own estimate θ_b ± σ_b, ordered by its start time, is tested for a change
per coefficient (:func:`drift`): a χ² test of homogeneity against the precision-weighted mean,
Bonferroni-corrected over the coefficients, and for those that moved, the split between two
consecutive logs that separates the two weighted means the most.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import special

from dampest_ros.core.identification.batch import Fit, FitOptions, fit, fit_statistics
from dampest_ros.core.identification.covariance import (
    BiasStatistics,
    bias_statistics,
    pooled_bias,
    settled_block,
)
from dampest_ros.core.identification.regression import (
    BlockEquations,
    NormalEquations,
    accumulate,
)
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import ConfigError, RigidBody
from dampest_ros.core.signals.extent import Extent, largest, top_count
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]


@dataclass
class LogStatistics:
    """What one log contributes to a pooled fit.

    Attributes
    ----------
    name : str
        The log (path or URL), for reports.
    start : float
        Time of its first sample (s; the log's own clock, e.g. UNIX time for a recorded bag).
    extent : Extent
        Its samples' (which stay where they were read).
    normal : NormalEquations
        Their statistics (:func:`~dampest_ros.core.identification.batch.accumulate`, 5 folds).
    bias : BiasStatistics or None
        Those of the sensor-bias refits (None: the options give no sensor a bias).
    fit : Fit
        The log's own estimate (for the drift).
    """

    name: str
    start: float
    extent: Extent
    normal: NormalEquations
    bias: BiasStatistics | None
    fit: Fit


def log_statistics(name: str, samples: Samples, model: DampingModel, body: RigidBody,
                   options: FitOptions, prior: FloatArray | None = None,
                   prior_std: FloatArray | None = None, extent: Extent | None = None
                   ) -> LogStatistics:
    """Reduce one log: its normal equations and its own fit (the map step).

    Parameters
    ----------
    name : str
    samples : Samples
    model : DampingModel
    body : RigidBody
    options : FitOptions
        Those of the pooled fit (the same cutoff); the speed range is the log's own.
    prior, prior_std : ndarray, shape (p,), optional
    extent : Extent, optional
        :meth:`~dampest_ros.core.signals.extent.Extent.of` ``samples`` (formed here when
        not given).
    """
    extent = extent or Extent.of(samples)
    ne = accumulate(samples, model, body, cutoff=options.cutoff,
                    block=settled_block(extent, options, model.n_params))
    bias = bias_statistics(samples, model, body, options)
    own = fit(samples, model, body, options, prior=prior, prior_std=prior_std, normal=ne,
              bias=bias, extent=extent)
    return LogStatistics(name, float(samples.t[0]), extent, ne, bias, own)


def pooled_normal(normals: Sequence[NormalEquations]) -> NormalEquations:
    """Σ of the logs' statistics, fold by fold: fold k is the k-th fifth of every log; the
    robust covariance's blocks are every log's, in order, when each log has blocks of one
    length (:func:`~dampest_ros.core.identification.covariance.settled_block`)."""
    if not normals:
        raise ConfigError("logs", "no log to pool")
    shapes = {n.A.shape for n in normals}
    if len(shapes) != 1:
        raise ConfigError("logs", f"statistics of different shapes {sorted(shapes)}: the "
                                  "logs were reduced with different models")
    blocks = [n.blocks for n in normals if n.blocks is not None]
    joined = (BlockEquations.join(blocks) if len(blocks) == len(normals)
              and len({x.length for x in blocks}) == 1 else None)
    return NormalEquations(sum((n.A for n in normals), np.zeros_like(normals[0].A)),
                           sum((n.b for n in normals), np.zeros_like(normals[0].b)),
                           sum((n.c for n in normals), np.zeros_like(normals[0].c)),
                           sum((n.n for n in normals), np.zeros_like(normals[0].n)), joined)


#: ``map_logs(fn)`` returns ``[fn(samples, k), ...]`` for the samples of log k = 0, 1, … of a
#: pooled fit, each call where those samples are held (a Dask worker, or here:
#: :func:`map_here`).
MapLogs = Callable[[Callable[[Samples, int], Any]], list[Any]]


def map_here(samples: Sequence[Samples]) -> MapLogs:
    """The :data:`MapLogs` of logs' samples held here, in order."""
    return lambda fn: [fn(part, k) for k, part in enumerate(samples)]


def _largest(samples: Samples, k: int, count: int) -> FloatArray:
    """:func:`~dampest_ros.core.signals.extent.largest` ``count`` of a log (a
    :data:`MapLogs` call)."""
    return largest(samples, count)


def pooled_extent(logs: Sequence[LogStatistics], map_logs: MapLogs) -> Extent:
    """The :class:`~dampest_ros.core.signals.extent.Extent` of the logs' samples put
    together, from their own and their largest |ν| and |τ| (one small pass, log by log where
    each is held)."""
    count = top_count(sum(g.extent.n for g in logs))
    return Extent.join([g.extent for g in logs], map_logs(partial(_largest, count=count)))


def _on_part(samples: Samples, k: int, fn: Callable[[Samples, int], Any], firsts: Sequence[int]
             ) -> Any:
    """``fn`` on log k's samples, told where they begin in the pooled set (a
    :data:`~dampest_ros.core.identification.covariance.MapParts` call, run where the log is)."""
    return fn(samples, firsts[k])


def pooled_fit(logs: Sequence[LogStatistics], model: DampingModel, body: RigidBody,
               options: FitOptions, map_logs: MapLogs, prior: FloatArray | None = None,
               prior_std: FloatArray | None = None, extent: Extent | None = None) -> Fit:
    """The fit of all the logs' samples at once, from their summed statistics (the reduce).

    θ, its covariance and every per-DOF figure equal those of
    :func:`~dampest_ros.core.identification.batch.fit` on the logs' samples put together
    (:meth:`Samples.concatenate`) to rounding; only the cross-validation folds differ (see
    :func:`pooled_normal`). The passes over the samples (the dissipativity check's scan; the
    robust covariance's when the logs' statistics hold no blocks of its length; the pooled
    extent's) run log by log through ``map_logs``. ``extent`` is :func:`pooled_extent`
    when the caller has made it already.
    """
    firsts = np.cumsum([0] + [g.extent.n for g in logs[:-1]]).tolist()

    def map_parts(fn: Callable[[Samples, int], Any]) -> list[Any]:
        return map_logs(partial(_on_part, fn=fn, firsts=firsts))

    biases = [g.bias for g in logs if g.bias is not None]  # none, or every log's
    bias = pooled_bias(biases, [g.normal for g in logs]) if biases else None
    return fit_statistics(extent or pooled_extent(logs, map_logs),
                          pooled_normal([g.normal for g in logs]), bias, map_parts, model, body,
                          options, prior, prior_std)


@dataclass
class Drift:
    """Per-log estimates and the test of change, for B logs and p coefficients.

    Attributes
    ----------
    names : list of str
    logs : list of str
        In start-time order, shape (B,).
    start : ndarray, shape (B,)
        Start times (s).
    theta, std : ndarray, shape (B, p)
        Each log's estimate and standard deviation (NaN where that log does not identify
        the coefficient).
    chi2 : ndarray, shape (p,)
        Σ_b ((θ_b − θ̄)/σ_b)² over the logs that identify it, θ̄ the precision-weighted mean.
    dof : ndarray of int, shape (p,)
        Its degrees of freedom (logs that identify it − 1; 0 when fewer than two do: then
        χ² and the p-value are NaN, the coefficient is not tested).
    p_value : ndarray, shape (p,)
    moved : ndarray of bool, shape (p,)
        p_value below ``alpha`` / p (Bonferroni over the coefficients).
    change_after : ndarray of int, shape (p,)
        For a moved coefficient, the index of the last log before the change (the split
        whose before/after weighted means differ most in their σ), −1 otherwise.
    shift : ndarray, shape (p,)
        After − before of those means (NaN when not moved).
    shift_std : ndarray, shape (p,)
        Its standard deviation.
    alpha : float
    """

    names: list[str]
    logs: list[str]
    start: FloatArray
    theta: FloatArray
    std: FloatArray
    chi2: FloatArray
    dof: NDArray[np.int64]
    p_value: FloatArray
    moved: NDArray[np.bool_]
    change_after: NDArray[np.int64]
    shift: FloatArray
    shift_std: FloatArray
    alpha: float


def _weighted(theta: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Precision-weighted means over axis 0 and their σ, NaN-free inputs with w = 0 for
    missing entries."""
    sw = w.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        # θ̄ = Σ w_b θ_b / Σ w_b, σ(θ̄) = 1/√Σ w_b (w_b = 1/σ_b²)
        return (w * theta).sum(axis=0) / sw, 1.0 / np.sqrt(sw)


def drift(logs: Sequence[LogStatistics], alpha: float = 0.01) -> Drift:
    """Test each coefficient for a change between the logs (ordered by start time).

    Parameters
    ----------
    logs : sequence of LogStatistics
        At least two.
    alpha : float
        Family-wise false-alarm probability over the coefficients.
    """
    if len(logs) < 2:
        raise ConfigError("logs", "a drift needs at least two logs")
    order = sorted(range(len(logs)), key=lambda k: (logs[k].start, k))
    fits = [logs[k].fit for k in order]
    names = fits[0].names
    theta = np.array([f.theta for f in fits])
    std = np.array([f.std for f in fits])
    ok = np.array([f.identified for f in fits]) & np.isfinite(std) & (std > 0)
    w = np.where(ok, 1.0 / np.where(ok, std, 1.0) ** 2, 0.0)  # 1/σ_b², 0 where missing
    th = np.where(ok, theta, 0.0)
    mean, _ = _weighted(th, w)
    # χ² = Σ_b w_b (θ_b − θ̄)², B_j − 1 degrees of freedom
    dof = np.maximum(ok.sum(axis=0) - 1, 0)
    tested = dof > 0  # identified by two logs or more
    chi2 = np.where(tested, np.where(ok, w * (th - mean) ** 2, 0.0).sum(axis=0), np.nan)
    # the χ² survival function (scipy.special's, which scipy.stats.chi2.sf calls)
    p_value = np.where(tested, special.chdtrc(np.maximum(dof, 1), np.where(tested, chi2, 0.0)),
                       np.nan)
    moved = (dof > 0) & (p_value < alpha / max(len(names), 1))
    B, p = theta.shape
    change_after = np.full(p, -1, dtype=np.int64)
    shift = np.full(p, np.nan)
    shift_std = np.full(p, np.nan)
    for j in np.flatnonzero(moved):
        best = -1.0
        for k in range(B - 1):
            m0, s0 = _weighted(th[:k + 1, j:j + 1], w[:k + 1, j:j + 1])
            m1, s1 = _weighted(th[k + 1:, j:j + 1], w[k + 1:, j:j + 1])
            if not (np.isfinite(m0[0]) and np.isfinite(m1[0])):
                continue
            # z of the difference of the two means
            z = abs(m1[0] - m0[0]) / np.hypot(s0[0], s1[0])
            if z > best:
                best, change_after[j] = z, k
                shift[j], shift_std[j] = m1[0] - m0[0], np.hypot(s0[0], s1[0])
    return Drift(names=list(names), logs=[logs[k].name for k in order],
                 start=np.array([logs[k].start for k in order]),
                 theta=np.where(ok, theta, np.nan), std=np.where(ok, std, np.nan),
                 chi2=chi2, dof=dof.astype(np.int64), p_value=p_value, moved=moved,
                 change_after=change_after, shift=shift, shift_std=shift_std, alpha=alpha)


@dataclass
class Consistency:
    """Whether each log belongs with the others: its own estimate against theirs.

    Attributes
    ----------
    logs : list of str
        In the given order, shape (B,).
    chi2 : ndarray, shape (B,)
        Σ_j (θ_bj − θ̄_oj)² / (σ_bj² + σ(θ̄_oj)²) over the coefficients log b identifies, θ̄_o
        the precision-weighted mean of the other logs kept, as :func:`drift` weighs them
        (NaN: not tested).
    dof : ndarray of int, shape (B,)
        The number of those coefficients.
    p_value : ndarray, shape (B,)
    left_out : list of int
        The logs found inconsistent (p below ``alpha`` / B, Bonferroni over the logs), in the
        order they were taken out: the worst first, each test repeated without it.
    alpha : float
    """

    logs: list[str]
    chi2: FloatArray
    dof: NDArray[np.int64]
    p_value: FloatArray
    left_out: list[int]
    alpha: float


def _against(logs: Sequence[LogStatistics], b: int, others: Sequence[int]
             ) -> tuple[float, int]:
    """χ² and degrees of freedom of log ``b``'s estimate against the precision-weighted
    mean of ``others``, per coefficient as :func:`drift` weighs them, over the coefficients
    log ``b`` and at least one other identify."""
    mine = logs[b].fit
    ok = np.array([logs[k].fit.identified for k in others]) & np.isfinite(
        np.array([logs[k].fit.std for k in others]))
    std = np.array([logs[k].fit.std for k in others])
    w = np.where(ok & (std > 0), 1.0 / np.where(ok & (std > 0), std, 1.0) ** 2, 0.0)
    mean, mean_std = _weighted(np.where(ok, np.array([logs[k].fit.theta for k in others]),
                                        0.0), w)
    use = mine.identified & np.isfinite(mean) & (mine.std > 0)
    if not use.any():
        return float("nan"), 0
    # Σ_j (θ_bj − θ̄_oj)² / (σ_bj² + σ(θ̄_oj)²)
    z2 = (mine.theta[use] - mean[use]) ** 2 / (mine.std[use] ** 2 + mean_std[use] ** 2)
    return float(z2.sum()), int(use.sum())


def consistency(logs: Sequence[LogStatistics], alpha: float = 0.001) -> Consistency:
    """Test that the logs are of one vehicle: each log's estimate against the others'.

    A log of another vehicle (or one whose damping changed) gives a θ_b the others' estimate
    does not explain within the two covariances. The worst log whose p-value is below
    ``alpha`` / B is taken out and the test repeated on the rest, while three logs or more
    remain (with two, neither can be named).

    Parameters
    ----------
    logs : sequence of LogStatistics
        At least two.
    alpha : float
        Family-wise false-alarm probability over the logs. The σ of one short log are
        somewhat optimistic (χ²/dof up to 2.5 between 60 s native logs of one vehicle), so
        the default is 0.1 %; a log of another vehicle scores p ~ 1e-7.
    """
    B = len(logs)
    kept = list(range(B))
    chi2, dof = np.full(B, np.nan), np.zeros(B, dtype=np.int64)
    left: list[int] = []
    while True:
        for b in kept:
            chi2[b], dof[b] = _against(logs, b, [k for k in kept if k != b])
        p_value = np.where(dof > 0, special.chdtrc(np.maximum(dof, 1), np.nan_to_num(chi2)),
                           np.nan)
        worst = min(kept, key=lambda k: (np.nan_to_num(p_value[k], nan=1.0), -k))
        if len(kept) < 3 or not p_value[worst] < alpha / B:
            break
        kept.remove(worst)
        left.append(worst)
    return Consistency([g.name for g in logs], chi2, dof, p_value, left, alpha)
