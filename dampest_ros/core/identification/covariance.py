"""Covariance of the batch estimate: block-robust sandwich and sensor-bias sensitivity.

The residuals of a damping fit are correlated over seconds (low-passed noise, unmodelled slow
effects), so the covariance is the sandwich A⁺ (Σ_b s_b s_bᵀ) A⁺ over blocks of samples
(:func:`robust_covariance`); constant sensor biases, which residuals cannot reveal, add the
covariance of refits with the data offset by each bias (:func:`bias_covariance`).

Both are sums over the samples, so they run where the data are. The refits' data do not
depend on θ: :class:`BiasStatistics` are formed with the normal equations (a pooled fit's
are each log's, summed). The sandwich needs each block's score at θ, which the block's own
normal equations give (:class:`~dampest_ros.core.identification.regression.BlockEquations`):
they are formed with the fit's when the block length does not depend on the fit's rank
(:func:`settled_block`), else in a pass that takes ``map_parts``, which applies a function
to every part of the samples (e.g. the logs of a pooled fit, each on the worker that holds
it) and returns the parts' results, which add up to the whole's.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from dampest_ros.core.identification.quadratic import solve_normal
from dampest_ros.core.identification.regression import (
    BlockEquations,
    NormalEquations,
    accumulate,
    iter_regression,
)
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import RigidBody
from dampest_ros.core.signals.extent import Extent
from dampest_ros.core.signals.samples import CHUNK, Samples

FloatArray = NDArray[np.float64]

#: ``map_parts(fn)`` returns ``[fn(part, first), ...]`` over the parts of the samples, in
#: order, ``first`` the index of the part's first sample in the whole.
MapParts = Callable[[Callable[[Samples, int], Any]], list[Any]]


def whole(samples: Samples) -> MapParts:
    """The samples as their only part (the :data:`MapParts` of data held in memory)."""
    return lambda fn: [fn(samples, 0)]


class CovarianceOptions(Protocol):
    """The settings the covariances read
    (:class:`~dampest_ros.core.identification.batch.FitOptions`)."""

    @property
    def block(self) -> float: ...  # longest block (s)

    @property
    def cutoff(self) -> float: ...  # parallel low-pass (Hz)

    @property
    def gyro_bias(self) -> float: ...  # σ of a constant gyro bias (rad/s)

    @property
    def dvl_bias(self) -> float: ...  # σ of a constant DVL bias (m/s)

    @property
    def bias_stretch(self) -> int: ...  # samples per stretch of the bias refits


def block_length(extent: Extent, opts: CovarianceOptions, rank: int) -> float:
    """Length (s) of the robust covariance's blocks: ``opts.block``, shorter when the samples
    span fewer than 2 r + 1 of them, but never below two periods of the low-pass (``4 /
    cutoff``; 10 samples without one), over which filtered residuals stay correlated.

    The block sandwich's middle factor Σ_b s_b s_bᵀ has rank ≤ B: with fewer blocks than
    estimated directions r some directions get no variance at all (a 60 s log in 10 s blocks
    has 7 blocks for 12 parameters, and a σ six times too small on one of them).
    """
    span = sum(float(last - first) + 1.0 / extent.rate
               for first, last in extent.spans) if extent.n > 1 else 0.0
    floor = 4.0 / opts.cutoff if opts.cutoff > 0 else 10.0 / max(extent.rate, 1e-300)
    return float(max(min(opts.block, span / (2 * rank + 1)), floor))


#: Most floats (B · 6 · p²) the :class:`BlockEquations` formed with the normal equations
#: may take (32 MB); larger ones are left to a pass over the samples.
BLOCK_FLOATS = 2 ** 22


def block_count(extent: Extent, block: float) -> int:
    """Number of blocks B of the robust covariance (:func:`block_index`'s): those each
    segment begins, every one holding samples (a block is longer than two periods of the
    low-pass, so longer than a sample interval)."""
    return sum(int(np.floor((last - first) / block)) + 1 for first, last in extent.spans)


def settled_block(extent: Extent, opts: CovarianceOptions, p: int) -> float:
    """The :func:`block_length` a fit of ``p`` parameters has whatever its rank r ≤ p, when
    its :class:`BlockEquations` are small enough (:data:`BLOCK_FLOATS`) to form with the
    normal equations (``accumulate(..., block=…)``) and save the robust covariance its pass
    over the samples; 0 otherwise. The length falls as r grows, so it is settled when r = 1
    and r = p give the same."""
    if not (p and extent.n):
        return 0.0
    length = block_length(extent, opts, p)
    if length != block_length(extent, opts, 1):
        return 0.0
    return length if block_count(extent, length) * 6 * p * p <= BLOCK_FLOATS else 0.0


def part_blocks(samples: Samples, first: int, model: DampingModel, body: RigidBody,
                block: float, cutoff: float, chunk: int = CHUNK) -> BlockEquations:
    """The :class:`BlockEquations` of a part of the samples (a :data:`MapParts` call of
    :func:`robust_covariance`; ``first`` is unused: blocks start with each segment)."""
    blocks = accumulate(samples, model, body, folds=1, chunk=chunk, cutoff=cutoff,
                        block=block).blocks
    if blocks is None:
        raise ValueError("a part of the samples without samples")
    return blocks


def robust_covariance(extent: Extent, model: DampingModel, body: RigidBody,
                      theta: FloatArray, weights: FloatArray, ne: NormalEquations,
                      free: NDArray[np.bool_], basis: FloatArray, opts: CovarianceOptions,
                      map_parts: MapParts, chunk: int = CHUNK) -> FloatArray:
    """Block sandwich covariance A⁺ (Σ_b s_b s_bᵀ) A⁺ of the free parameters (NaN for the
    others; at least one is free).

    A⁺ = T (Tᵀ A T)⁻¹ Tᵀ is the inverse of A over the directions ``basis`` (T, shape
    (p_free, r)) spans, 0 in those the data do not determine (:func:`determined_directions`).

    s_b = Σ_{n ∈ block b} Σ_i w_i Φ_{n,i}ᵀ r_{n,i} is the weighted score of a block of
    :func:`block_length` seconds (:meth:`BlockEquations.scores`); summing within blocks makes
    the estimate robust to residuals that are correlated over less than a block (filtered
    noise, unmodelled slow effects). The blocks' normal equations come with ``ne`` when it
    holds blocks of that length (:func:`settled_block`), else from a pass over the samples
    (of ``extent``) part by part (``map_parts``; :func:`whole` for samples in memory); a
    block never spans two segments, so never two parts.
    """
    p = model.n_params
    cov = np.full((p, p), np.nan)
    A, _, _ = ne.total(weights)
    Af = A[np.ix_(free, free)]
    length = block_length(extent, opts, basis.shape[1])
    blocks = ne.blocks
    if blocks is None or blocks.length != length:
        blocks = BlockEquations.join(map_parts(partial(
            part_blocks, model=model, body=body, block=length, cutoff=opts.cutoff,
            chunk=chunk)))
    S = blocks.scores(theta, weights, free)
    B = len(S)
    # Σ_b s_b s_bᵀ · B/(B − 1)
    meat = S.T @ S * (B / max(B - 1, 1))
    Ainv = basis @ linalg.inv(basis.T @ Af @ basis) @ basis.T
    cov[np.ix_(free, free)] = Ainv @ meat @ Ainv
    return cov


@dataclass
class BiasStatistics:
    """The sensor-bias refits' data: per-DOF normal equations of the samples with ν offset
    by each sensor axis's σ, over the rows :func:`bias_statistics` takes, and, when those are
    not every row, the same without an offset. Unweighted per DOF, so any fit's weights
    apply, and additive over logs (:func:`pooled_bias`).

    Attributes
    ----------
    A : ndarray, shape (k, 6, p, p)
        Σ_n Φ_niᵀ Φ_ni per DOF i, with each of the k offsets.
    b : ndarray, shape (k, 6, p)
        Σ_n Φ_niᵀ y_ni likewise.
    base : tuple of ndarray, shapes (6, p, p) and (6, p), or None
        The same without an offset; None when every row was taken (no segment was cut to
        stretches): the fit's own estimate is then the base the refits differ from.
    """

    A: FloatArray
    b: FloatArray
    base: tuple[FloatArray, FloatArray] | None

    def with_base(self, normal: NormalEquations) -> tuple[FloatArray, FloatArray]:
        """The unoffset part: :attr:`base`, or for statistics of every row, those of
        ``normal``, the normal equations of the same samples (no guard between folds)."""
        return self.base if self.base is not None else (normal.A.sum(axis=0),
                                                        normal.b.sum(axis=0))


def pooled_bias(stats: Sequence[BiasStatistics], normals: Sequence[NormalEquations]
                ) -> BiasStatistics:
    """The statistics of several logs' samples at once (each log its own segments), from
    each log's and its normal equations (for the unoffset part of a log taken whole)."""
    A, b = stats[0].A.copy(), stats[0].b.copy()
    for other in stats[1:]:
        A += other.A
        b += other.b
    if all(x.base is None for x in stats):
        return BiasStatistics(A, b, None)
    parts = [x.with_base(n) for x, n in zip(stats, normals, strict=True)]
    A0, b0 = parts[0][0].copy(), parts[0][1].copy()
    for a, c in parts[1:]:
        A0 += a
        b0 += c
    return BiasStatistics(A, b, (A0, b0))


def bias_offsets(opts: CovarianceOptions) -> list[FloatArray]:
    """ν offsets of the bias refits: σ e_k for each DVL axis (``opts.dvl_bias``, m/s) and
    gyro axis (``opts.gyro_bias``, rad/s) with σ > 0, each shape (6,)."""
    sigma = np.array([opts.dvl_bias] * 3 + [opts.gyro_bias] * 3)
    return [sigma[k] * np.eye(6)[k] for k in np.flatnonzero(sigma > 0)]


def bias_rows(samples: Samples, stretch: int) -> tuple[Samples, bool]:
    """The rows the bias refits take: every segment whole, but a segment longer than three
    stretches of ``stretch`` samples as three evenly spread stretches of it (a sensitivity is
    an average property of the data, which these give at a fraction of the cost), each its
    own segment; and whether that is every row."""
    keep: list[NDArray[np.int64]] = []
    for sl in samples.segments():
        a, n = sl.start or 0, (sl.stop or 0) - (sl.start or 0)
        if n > 3 * stretch:
            keep += [np.arange(a + s, a + s + stretch)
                     for s in np.linspace(0, n - stretch, 3).astype(np.int64)]
        else:
            keep.append(np.arange(a, a + n))
    complete = sum(len(k) for k in keep) == len(samples)
    if complete:
        return samples, True
    data = samples.take(np.concatenate(keep))
    data.segment = np.repeat(np.arange(len(keep)), [len(k) for k in keep])
    return data, False


def bias_statistics(samples: Samples, model: DampingModel, body: RigidBody,
                    opts: CovarianceOptions, chunk: int = CHUNK) -> BiasStatistics | None:
    """The :class:`BiasStatistics` of ``samples`` (:func:`bias_rows`, low-passed and
    decimated as the fit's normal equations); None when no sensor has a bias."""
    offsets: list[FloatArray | None] = list(bias_offsets(opts))
    if not offsets:
        return None
    data, complete = bias_rows(samples, opts.bias_stretch)
    if not complete:
        offsets.insert(0, None)
    p = model.n_params
    A = np.zeros((len(offsets), 6, p, p))
    b = np.zeros((len(offsets), 6, p))
    for j, offset in enumerate(offsets):
        for _, Phi, y in iter_regression(data, model, body, chunk, opts.cutoff, offset=offset,
                                         decimate=True):
            rows = Phi.transpose(1, 0, 2)  # (6, n, p)
            # per DOF i: ΦᵢᵀΦᵢ and Φᵢᵀyᵢ, one matrix product each
            A[j] += rows.transpose(0, 2, 1) @ rows
            b[j] += np.einsum("inp,ni->ip", rows, y)
    if complete:
        return BiasStatistics(A, b, None)
    return BiasStatistics(A[1:], b[1:], (A[0], b[0]))


def bias_covariance(stats: BiasStatistics | None, theta: FloatArray, weights: FloatArray,
                    free: NDArray[np.bool_], basis: FloatArray) -> FloatArray:
    """Covariance of θ caused by unknown constant sensor biases (the error budget).

    For each axis k of the gyro and of the DVL (:func:`bias_offsets`) the data are refitted
    with ν offset by σ e_k; the change Δθ_k is one standard deviation of the error that bias
    causes, and Σ_k Δθ_k Δθ_kᵀ is the covariance (biases independent). Such errors are
    constant over the record, so the residuals cannot reveal them. The refits estimate the
    directions ``basis`` (shape (p_free, r)) spans (:func:`determined_directions`) with the
    fit's per-DOF ``weights`` (shape (6,)); they are differenced from θ when they took every
    row (``stats.base`` None), else from the refit of the same rows without an offset. 0
    when ``stats`` is None.
    """
    p = len(theta)
    cov = np.zeros((p, p))
    if stats is None:
        return cov

    def refit(A: FloatArray, b: FloatArray) -> FloatArray:
        # the weighted refit: Σ_i w_i ΦᵢᵀΦᵢ θ = Σ_i w_i Φᵢᵀyᵢ
        return solve_normal(np.einsum("i,ipq->pq", weights, A),
                            np.einsum("i,ip->p", weights, b), free, theta, basis=basis)

    base = theta if stats.base is None else refit(*stats.base)
    for A, b in zip(stats.A, stats.b, strict=True):
        d = refit(A, b) - base
        cov += np.outer(d, d)
    return cov


def covariance(extent: Extent, model: DampingModel, body: RigidBody, theta: FloatArray,
               weights: FloatArray, ne: NormalEquations, free: NDArray[np.bool_],
               basis: FloatArray, opts: CovarianceOptions, bias: BiasStatistics | None,
               map_parts: MapParts, chunk: int = CHUNK) -> FloatArray:
    """Covariance of θ̂, shape (p, p): the block-robust one (:func:`robust_covariance`; its
    pass over the samples of ``extent``, when it takes one, part by part: ``map_parts``) plus
    the sensor-bias budget (:func:`bias_covariance` of ``bias``), both in the directions
    ``basis`` (shape (p_free, r)) spans; NaN where no parameter is free.

    Parameters
    ----------
    weights : ndarray, shape (6,)
        The fit's per-DOF weights.
    """
    p = model.n_params
    if not free.any():
        return np.full((p, p), np.nan)
    # robust + bias: independent errors
    return (robust_covariance(extent, model, body, theta, weights, ne, free, basis, opts,
                              map_parts, chunk)
            + bias_covariance(bias, theta, weights, free, basis))
