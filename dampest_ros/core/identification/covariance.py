"""Covariance of the batch estimate: block-robust sandwich and sensor-bias sensitivity.

The residuals of a damping fit are correlated over seconds (low-passed noise, unmodelled slow
effects), so the covariance is the sandwich A⁺ (Σ_b s_b s_bᵀ) A⁺ over blocks of samples
(:func:`robust_covariance`); constant sensor biases, which residuals cannot reveal, add the
covariance of refits with the data offset by each bias (:func:`bias_covariance`).

Both are sums over the samples, so they run where the data are: each takes ``map_parts``,
which applies a function to every part of the samples (e.g. the logs of a pooled fit, each on
the worker that holds it) and returns the parts' results, which add up to those of the whole.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from dampest_ros.core.identification.quadratic import solve_normal
from dampest_ros.core.identification.regression import NormalEquations, iter_regression
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import RigidBody
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


def block_length(samples: Samples, opts: CovarianceOptions, rank: int) -> float:
    """Length (s) of the robust covariance's blocks: ``opts.block``, shorter when the samples
    span fewer than 2 r + 1 of them, but never below two periods of the low-pass (``4 /
    cutoff``; 10 samples without one), over which filtered residuals stay correlated.

    The block sandwich's middle factor Σ_b s_b s_bᵀ has rank ≤ B: with fewer blocks than
    estimated directions r some directions get no variance at all (a 60 s log in 10 s blocks
    has 7 blocks for 12 parameters, and a σ six times too small on one of them).
    """
    span = sum(float(samples.t[sl][-1] - samples.t[sl][0]) + 1.0 / samples.rate
               for sl in samples.segments()) if len(samples) > 1 else 0.0
    floor = 4.0 / opts.cutoff if opts.cutoff > 0 else 10.0 / max(samples.rate, 1e-300)
    return float(max(min(opts.block, span / (2 * rank + 1)), floor))


def block_index(samples: Samples, block: float, t0: float | None = None
                ) -> NDArray[np.int64]:
    """Index 0..B−1 of the ``block``-second block (within its segment) of every sample;
    blocks are counted from ``t0`` (s; default: the first sample's time)."""
    start = samples.t[0] if t0 is None else t0
    block_of = np.floor((samples.t - start) / block).astype(np.int64)
    block_of += samples.segment * (int(block_of.max()) + 1)
    return np.unique(block_of, return_inverse=True)[1].astype(np.int64)


def block_count(samples: Samples, block: float) -> int:
    """Number of blocks B of the robust covariance."""
    return int(block_index(samples, block).max()) + 1 if len(samples) else 0


def block_scores(samples: Samples, first: int, model: DampingModel, body: RigidBody,
                 theta: FloatArray, weights: FloatArray, free: NDArray[np.bool_],
                 block: float, t0: float, cutoff: float, chunk: int = CHUNK
                 ) -> tuple[FloatArray, int]:
    """Σ_b s_b s_bᵀ over the blocks of these samples and their number B (a part of
    :func:`robust_covariance`; ``first`` is unused: blocks need only ``t0``)."""
    block_idx = block_index(samples, block, t0)
    S = np.zeros((int(block_idx.max()) + 1, int(free.sum())))
    for sl, Phi, y in iter_regression(samples, model, body, chunk, cutoff, decimate=True):
        r = y - Phi @ theta
        # weighted score of each sample: Σ_i w_i Φ_iᵀ r_i
        g = np.einsum("nip,ni,i->np", Phi[:, :, free], r, weights)
        np.add.at(S, block_idx[sl], g)
    return S.T @ S, len(S)


def robust_covariance(samples: Samples, model: DampingModel, body: RigidBody,
                      theta: FloatArray, weights: FloatArray, ne: NormalEquations,
                      free: NDArray[np.bool_], basis: FloatArray, opts: CovarianceOptions,
                      chunk: int = CHUNK, map_parts: MapParts | None = None) -> FloatArray:
    """Block sandwich covariance A⁺ (Σ_b s_b s_bᵀ) A⁺ of the free parameters.

    A⁺ = T (Tᵀ A T)⁻¹ Tᵀ is the inverse of A over the directions ``basis`` (T, shape
    (p_free, r)) spans, 0 in those the data do not determine (:func:`determined_directions`).

    s_b = Σ_{n ∈ block b} Σ_i w_i Φ_{n,i}ᵀ r_{n,i} is the weighted score of a block of
    :func:`block_length` seconds; summing within blocks makes the estimate robust to
    residuals that are correlated over less than a block (filtered noise, unmodelled slow
    effects). The blocks' sums are formed part by part (``map_parts``, default: all of
    ``samples`` at once); a block never spans two segments, so never two parts.
    """
    p = model.n_params
    cov = np.full((p, p), np.nan)
    if not free.any():
        return cov
    A, _, _ = ne.total(weights)
    Af = A[np.ix_(free, free)]
    parts = (map_parts or whole(samples))(partial(
        block_scores, model=model, body=body, theta=theta, weights=weights, free=free,
        block=block_length(samples, opts, basis.shape[1]), t0=float(samples.t[0]),
        cutoff=opts.cutoff, chunk=chunk))
    B = sum(b for _, b in parts)
    # Σ_b s_b s_bᵀ · B/(B − 1), the blocks of all parts
    meat = sum(m for m, _ in parts) * (B / max(B - 1, 1))
    Ainv = basis @ linalg.inv(basis.T @ Af @ basis) @ basis.T
    cov[np.ix_(free, free)] = Ainv @ meat @ Ainv
    return cov


def bias_normals(samples: Samples, first: int, model: DampingModel, body: RigidBody,
                 weights: FloatArray, offsets: list[FloatArray | None],
                 starts: NDArray[np.int64] | None, stretch: int, cutoff: float,
                 chunk: int = CHUNK) -> list[tuple[FloatArray, FloatArray]]:
    """Weighted normal equations (A, b) of these samples with ν offset by each of
    ``offsets`` (None: no offset), over the stretches ``[start, start + stretch)`` of the
    whole (all samples when ``starts`` is None) that fall in this part, which begins at
    sample ``first`` of the whole (a part of :func:`bias_covariance`)."""
    data = samples
    if starts is not None:
        index = np.arange(first, first + len(samples))
        # stretch k of each sample, −1 outside every stretch
        k = np.full(len(samples), -1)
        for j, a in enumerate(starts):
            k[(index >= a) & (index < a + stretch)] = j
        keep = np.flatnonzero(k >= 0)
        data = samples.take(keep)
        data.segment = k[keep] + len(starts) * data.segment
    p = model.n_params
    out = []
    for offset in offsets:
        A = np.zeros((p, p))
        b = np.zeros(p)
        if len(data):
            root = np.sqrt(weights)
            for _, Phi, y in iter_regression(data, model, body, chunk, cutoff, offset=offset,
                                             decimate=True):
                # Σ_n Σ_i w_i Φ_niᵀ Φ_ni as one matrix product of the √w-weighted rows
                P = (Phi * root[None, :, None]).reshape(-1, p)
                A += P.T @ P
                b += P.T @ (y * root).reshape(-1)
        out.append((A, b))
    return out


def bias_covariance(samples: Samples, model: DampingModel, body: RigidBody,
                    theta: FloatArray, weights: FloatArray, free: NDArray[np.bool_],
                    basis: FloatArray, opts: CovarianceOptions, chunk: int = CHUNK,
                    map_parts: MapParts | None = None) -> FloatArray:
    """Covariance of θ caused by unknown constant sensor biases (the error budget).

    For each axis k of the gyro (σ = ``opts.gyro_bias``) and of the DVL (``opts.dvl_bias``)
    the data are refitted with ν offset by σ e_k; the change Δθ_k is one standard deviation
    of the error that bias causes, and Σ_k Δθ_k Δθ_kᵀ is the covariance (biases independent).
    Such errors are constant over the record, so the residuals cannot reveal them. The
    refits estimate the directions ``basis`` spans (:func:`determined_directions`); their
    normal equations are summed part by part (``map_parts``, default: all of ``samples``).
    """
    p = model.n_params
    cov = np.zeros((p, p))
    sigma = np.array([opts.dvl_bias] * 3 + [opts.gyro_bias] * 3)
    if not free.any() or not np.any(sigma > 0):
        return cov
    # a sensitivity is an average property of the data: on long logs, three evenly spread
    # stretches of opts.bias_stretch samples give it at a fraction of the cost, refitted
    # without an offset too
    n, stretch = len(samples), opts.bias_stretch
    starts = np.linspace(0, n - stretch, 3).astype(np.int64) if n > 3 * stretch else None
    axes = np.flatnonzero(sigma > 0)
    offsets: list[FloatArray | None] = [sigma[k] * np.eye(6)[k] for k in axes]
    if starts is not None:
        offsets.insert(0, None)
    parts = (map_parts or whole(samples))(partial(
        bias_normals, model=model, body=body, weights=weights, offsets=offsets, starts=starts,
        stretch=stretch, cutoff=opts.cutoff, chunk=chunk))
    refits = [solve_normal(sum(part[j][0] for part in parts), sum(part[j][1] for part in parts),
                           free, theta, basis=basis) for j in range(len(offsets))]
    base = theta if starts is None else refits.pop(0)
    for th in refits:
        d = th - base
        cov += np.outer(d, d)
    return cov
