"""Covariance of the batch estimate: block-robust sandwich and sensor-bias sensitivity.

The residuals of a damping fit are correlated over seconds (low-passed noise, unmodelled slow
effects), so the covariance is the sandwich A⁺ (Σ_b s_b s_bᵀ) A⁺ over blocks of samples
(:func:`robust_covariance`); constant sensor biases, which residuals cannot reveal, add the
covariance of refits with the data offset by each bias (:func:`bias_covariance`).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from dampest_ros.core.damping import DampingModel
from dampest_ros.core.quadratic import solve_normal
from dampest_ros.core.regression import NormalEquations, iter_regression
from dampest_ros.core.rigid_body import RigidBody
from dampest_ros.core.samples import CHUNK, Samples

FloatArray = NDArray[np.float64]

STRETCH = 20000  # samples per stretch of the sensor-bias sensitivity on long logs


class CovarianceOptions(Protocol):
    """The settings the covariances read (:class:`~dampest_ros.core.batch.FitOptions`)."""

    @property
    def block(self) -> float: ...  # longest block (s)

    @property
    def cutoff(self) -> float: ...  # parallel low-pass (Hz)

    @property
    def gyro_bias(self) -> float: ...  # σ of a constant gyro bias (rad/s)

    @property
    def dvl_bias(self) -> float: ...  # σ of a constant DVL bias (m/s)


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


def block_index(samples: Samples, block: float) -> NDArray[np.int64]:
    """Index 0..B−1 of the ``block``-second block (within its segment) of every sample."""
    block_of = np.floor((samples.t - samples.t[0]) / block).astype(np.int64)
    block_of += samples.segment * (int(block_of.max()) + 1)
    return np.unique(block_of, return_inverse=True)[1].astype(np.int64)


def block_count(samples: Samples, block: float) -> int:
    """Number of blocks B of the robust covariance."""
    return int(block_index(samples, block).max()) + 1 if len(samples) else 0


def robust_covariance(samples: Samples, model: DampingModel, body: RigidBody,
                      theta: FloatArray, weights: FloatArray, ne: NormalEquations,
                      free: NDArray[np.bool_], basis: FloatArray, opts: CovarianceOptions,
                      chunk: int = CHUNK) -> FloatArray:
    """Block sandwich covariance A⁺ (Σ_b s_b s_bᵀ) A⁺ of the free parameters.

    A⁺ = T (Tᵀ A T)⁻¹ Tᵀ is the inverse of A over the directions ``basis`` (T, shape
    (p_free, r)) spans, 0 in those the data do not determine (:func:`determined_directions`).

    s_b = Σ_{n ∈ block b} Σ_i w_i Φ_{n,i}ᵀ r_{n,i} is the weighted score of a block of
    :func:`block_length` seconds; summing within blocks makes the estimate robust to
    residuals that are correlated over less than a block (filtered noise, unmodelled slow
    effects).
    """
    p = model.n_params
    cov = np.full((p, p), np.nan)
    if not free.any():
        return cov
    A, _, _ = ne.total(weights)
    Af = A[np.ix_(free, free)]
    block_idx = block_index(samples, block_length(samples, opts, basis.shape[1]))
    S = np.zeros((int(block_idx.max()) + 1, int(free.sum())))
    for sl, Phi, y in iter_regression(samples, model, body, chunk, opts.cutoff,
                                      decimate=True):
        r = y - Phi @ theta
        # weighted score of each sample: Σ_i w_i Φ_iᵀ r_i
        g = np.einsum("nip,ni,i->np", Phi[:, :, free], r, weights)
        np.add.at(S, block_idx[sl], g)
    B = len(S)
    meat = S.T @ S * (B / max(B - 1, 1))
    Ainv = basis @ linalg.inv(basis.T @ Af @ basis) @ basis.T
    cov[np.ix_(free, free)] = Ainv @ meat @ Ainv
    return cov


def bias_covariance(samples: Samples, model: DampingModel, body: RigidBody,
                    theta: FloatArray, weights: FloatArray, free: NDArray[np.bool_],
                    basis: FloatArray, opts: CovarianceOptions, chunk: int = CHUNK) -> FloatArray:
    """Covariance of θ caused by unknown constant sensor biases (the error budget).

    For each axis k of the gyro (σ = ``opts.gyro_bias``) and of the DVL (``opts.dvl_bias``)
    the data are refitted with ν offset by σ e_k; the change Δθ_k is one standard deviation
    of the error that bias causes, and Σ_k Δθ_k Δθ_kᵀ is the covariance (biases independent).
    Such errors are constant over the record, so the residuals cannot reveal them. The
    refits estimate the directions ``basis`` spans (:func:`determined_directions`).
    """
    p = model.n_params
    cov = np.zeros((p, p))
    sigma = np.array([opts.dvl_bias] * 3 + [opts.gyro_bias] * 3)
    if not free.any() or not np.any(sigma > 0):
        return cov
    # a sensitivity is an average property of the data: on long logs, three evenly spread
    # stretches of STRETCH samples give it at a fraction of the cost
    data = samples
    if len(samples) > 3 * STRETCH:
        starts = np.linspace(0, len(samples) - STRETCH, 3).astype(int)
        index = np.concatenate([np.arange(a, a + STRETCH) for a in starts])
        data = samples.take(index)
        data.segment = np.repeat(np.arange(3), STRETCH) + 3 * data.segment

    def refit(offset: FloatArray | None) -> FloatArray:
        A = np.zeros((p, p))
        b = np.zeros(p)
        for _, Phi, y in iter_regression(data, model, body, chunk, opts.cutoff,
                                         offset=offset, decimate=True):
            A += np.einsum("nip,niq,i->pq", Phi, Phi, weights)
            b += np.einsum("nip,ni,i->p", Phi, y, weights)
        return solve_normal(A, b, free, theta, basis=basis)

    base = theta if data is samples else refit(None)
    for k in np.flatnonzero(sigma > 0):
        offset = np.zeros(6)
        offset[k] = sigma[k]
        d = refit(offset) - base
        cov += np.outer(d, d)
    return cov
