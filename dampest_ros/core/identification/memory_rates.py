"""Fluid memory in the data: per DOF, the rate λ of a memory state found by a profile
search (the regression is linear in the gain c for a fixed λ) and the evidence for it
(:class:`MemoryEvidence`), for :func:`dampest_ros.core.identification.selection.select_terms`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.frequency import memory_impedance
from dampest_ros.core.identification.quadratic import solve_normal
from dampest_ros.core.identification.regression import NormalEquations, accumulate, iter_regression
from dampest_ros.core.physics.damping import DampingModel, filter_memory
from dampest_ros.core.physics.rigid_body import DOF_NAMES, RigidBody
from dampest_ros.core.signals.preprocess import zero_phase
from dampest_ros.core.signals.samples import Samples

FloatArray = NDArray[np.float64]

#: Search range of a memory rate λ (1/s): below it a trend or an offset, above it plain damping.
RATE_BOUNDS = (0.05, 20.0)


@dataclass(frozen=True)
class MemoryEvidence:
    """The two estimates of one DOF's fluid memory K(t) = c e^{−λt}: the time-domain profile
    (staged least squares) and the frequency-domain rational fit of the residual impedance
    (:func:`frequency.memory_impedance`).

    Fluid memory is passive: Re Z(iω) = c λ / (λ² + ω²) ≥ 0 needs c ≥ 0. A rate outside the
    search range is not memory either (a trend or an offset below it, plain damping above).
    """

    dof: int
    rate: float
    gain: float
    rate_freq: float
    gain_freq: float
    bounds: tuple[float, float]

    @property
    def contradiction(self) -> str:
        """Why these estimates are not fluid memory ('' if they are)."""
        lo, hi = self.bounds
        if not lo * 1.05 < self.rate < hi / 1.05:
            return (f"its rate λ = {self.rate:.3g} 1/s is at the edge of the search range "
                    f"[{lo:g}, {hi:g}]: a trend or an offset, not fluid memory")
        if self.gain <= 0.0:
            return (f"not passive: the best gain c = {self.gain:.3g} ≤ 0 would feed energy "
                    "into the vehicle")
        if self.gain_freq <= 0.0 or not lo <= self.rate_freq <= hi:
            return (f"the frequency-domain estimate (λ = {self.rate_freq:.3g} 1/s, c = "
                    f"{self.gain_freq:.3g}) is not passive memory in the searched range: the "
                    "residual has another cause (a current, an offset, a sensor bias; "
                    "see dampest gap)")
        return ""

    @property
    def agrees(self) -> bool:
        """Both estimates passive, their rates and their steady gains c/λ (the force per unit
        of a slow velocity) within a factor of 2."""
        steady = (self.gain_freq / self.rate_freq) / (self.gain / self.rate)
        return (not self.contradiction and 0.5 <= self.rate_freq / self.rate <= 2.0
                and 0.5 <= steady <= 2.0)

    def describe(self) -> str:
        """One line: both estimates and whether they agree."""
        text = (f"memory on {DOF_NAMES[self.dof]}: λ = {self.rate:.4g} 1/s, c = "
                f"{self.gain:.4g} (time domain); λ = {self.rate_freq:.4g} 1/s, c = "
                f"{self.gain_freq:.4g} (frequency domain)")
        if self.contradiction:
            return f"{text}: DISAGREE: {self.contradiction}"
        if not self.agrees:
            return (f"{text}: DISAGREE: their rates or steady gains c/λ differ by more than a "
                    "factor of 2; the memory is uncertain (broadband data, e.g. protocol C, "
                    "separate it from other causes: a delay, an added-mass error)")
        return f"{text}: agree"


def profile_rate(samples: Samples, base: DampingModel, body: RigidBody, dof: int,
                 weights: FloatArray, cutoff: float, ne: NormalEquations,
                 bounds: tuple[float, float] = RATE_BOUNDS) -> tuple[float, float, float]:
    """Memory rate λ of one DOF by minimising the profiled weighted RSS over log λ, among
    passive memories (gain c ≥ 0).

    The memory column only acts on row ``dof``, so the base model's low-passed regressor
    row and target of that DOF are kept once; each trial λ then costs one recursive filter
    of ν_dof and one low-pass, not a pass over the full regression. Where the best gain is
    negative the passive optimum is c = 0 (no memory), whose RSS is the base model's.

    Parameters
    ----------
    ne : NormalEquations
        The base model's low-passed, decimated normal equations on ``samples``
        (:func:`batch.accumulate`), shared by the DOFs profiled.

    Returns
    -------
    rate : float
        λ (1/s).
    rss : float
        Weighted RSS at that rate.
    gain : float
        The unconstrained least-squares gain c at that rate (≤ 0: no passive memory).
    """
    from scipy import optimize  # slow to import: only where memory is tested

    A, b, c = ne.total(weights)
    # the same (decimated) samples as the normal equations
    parts = [(np.arange(len(samples))[sl], Phi[:, dof, :], y[:, dof])
             for sl, Phi, y in iter_regression(samples, base, body, cutoff=cutoff,
                                               decimate=True)]
    used = np.concatenate([p[0] for p in parts])
    rows = np.concatenate([p[1] for p in parts])
    y_d = np.concatenate([p[2] for p in parts])
    w = float(weights[dof])
    rss_base = c - float(b @ solve_normal(A, b, np.ones(len(b), dtype=bool), np.zeros(len(b))))

    def solve(log_rate: float) -> tuple[float, float]:
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
        theta = solve_normal(Ab, bb, np.ones(len(bb), dtype=bool), np.zeros(len(bb)))
        # a negative gain is not passive: the best passive memory is none at all
        return (c - float(bb @ theta) if theta[-1] > 0 else rss_base), float(theta[-1])

    def cost(log_rate: float) -> float:
        return solve(log_rate)[0]

    lo, hi = np.log(bounds[0]), np.log(bounds[1])
    grid = np.linspace(lo, hi, 13)
    values = [cost(g) for g in grid]
    k = int(np.argmin(values))
    res = optimize.minimize_scalar(cost, bounds=(grid[max(k - 1, 0)],
                                                 grid[min(k + 1, len(grid) - 1)]),
                                   method="bounded", options={"xatol": 1e-4})
    return float(np.exp(res.x)), float(res.fun), solve(float(res.x))[1]


def memory_evidence(samples: Samples, base: DampingModel, body: RigidBody,
                    dofs: Sequence[int], cutoff: float,
                    bounds: tuple[float, float] = RATE_BOUNDS) -> list[MemoryEvidence]:
    """Both estimates of a memory state in each DOF of ``dofs`` on top of ``base``.

    The time domain profiles the rate among passive memories (:func:`profile_rate`, per-DOF
    weights 1/σ² from the residual of ``base``); the frequency domain fits the impedance of
    the same residual (:func:`frequency.memory_impedance`, one pass for all DOFs).

    Parameters
    ----------
    base : DampingModel
        The static model (it may hold memory states of other DOFs).
    dofs : sequence of int
    cutoff : float
        Parallel low-pass of the regression (Hz).
    bounds : tuple of float
        Search range of the rate (1/s).
    """
    ne = accumulate(samples, base, body, folds=1, cutoff=cutoff)
    A, b, _ = ne.total(np.ones(6))
    theta = solve_normal(A, b, np.ones(len(b), dtype=bool), np.zeros(len(b)))
    # per-DOF noise variance of the base's residual → weights 1/σ²
    weights = np.asarray(1.0 / np.maximum(ne.rss(theta) / float(ne.n.sum()), 1e-12))
    profiles = [profile_rate(samples, base, body, int(d), weights, cutoff, ne, bounds)
                for d in dofs]
    freq = memory_impedance(samples, base, body, theta, dofs)
    return [MemoryEvidence(int(d), lam, gain, z.rate, z.gain, bounds)
            for d, (lam, _, gain), z in zip(dofs, profiles, freq, strict=True)]
