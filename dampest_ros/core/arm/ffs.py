"""Finite Fourier series (FFS) joint trajectories: periodic, smooth, with q, q̇, q̈ analytic.

For joint j, with ω_f = 2π f_f the base angular frequency and L harmonics,

    q_j(t)  = q0_j + Σ_l [ a_jl / (l ω_f) sin(l ω_f t) − b_jl / (l ω_f) cos(l ω_f t) ]
    q̇_j(t)  = Σ_l [ a_jl cos(l ω_f t) + b_jl sin(l ω_f t) ]
    q̈_j(t)  = Σ_l l ω_f [ −a_jl sin(l ω_f t) + b_jl cos(l ω_f t) ]

so the trajectory repeats every 1/f_f seconds and the data of whole periods average
periodic noise out (Swevers et al. 1997).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FourierTrajectory:
    """An FFS trajectory for n joints.

    Attributes
    ----------
    q0 : ndarray, shape (n,)
        Offset (rad).
    a, b : ndarray, shape (n, L)
        Velocity amplitudes of the cosine and sine terms of harmonic l (rad/s).
    base_frequency : float
        f_f (Hz); the period is 1 / f_f.
    """

    q0: FloatArray
    a: FloatArray
    b: FloatArray
    base_frequency: float

    @property
    def period(self) -> float:
        """1 / f_f (s)."""
        return 1.0 / self.base_frequency

    @property
    def harmonics(self) -> int:
        """L."""
        return int(self.a.shape[1])

    def basis(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """sin and cos of every harmonic at t, and l ω_f.

        Parameters
        ----------
        t : ndarray, shape (N,)
            Time (s).

        Returns
        -------
        s, c : ndarray, shape (N, L)
            sin(l ω_f t), cos(l ω_f t).
        lw : ndarray, shape (L,)
            l ω_f (rad/s).
        """
        lw = 2.0 * np.pi * self.base_frequency * np.arange(1, self.harmonics + 1, dtype=float)
        phase = np.outer(np.asarray(t, dtype=float), lw)
        return np.sin(phase), np.cos(phase), lw

    def evaluate(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """q, q̇, q̈ at the given times.

        Parameters
        ----------
        t : ndarray, shape (N,)
            Time (s).

        Returns
        -------
        q, qd, qdd : ndarray, shape (N, n)
            rad, rad/s, rad/s².
        """
        s, c, lw = self.basis(t)
        # q = q0 + Σ (a sin − b cos) / (l ω_f)
        q = self.q0 + s @ (self.a / lw).T - c @ (self.b / lw).T
        # q̇ = Σ a cos + b sin
        qd = c @ self.a.T + s @ self.b.T
        # q̈ = Σ l ω_f (−a sin + b cos)
        qdd = -s @ (self.a * lw).T + c @ (self.b * lw).T
        return q, qd, qdd

    def with_coefficients(self, x: FloatArray) -> FourierTrajectory:
        """The same offset and frequency with coefficients x = [a.ravel(), b.ravel()]."""
        n, L = self.a.shape
        x = np.asarray(x, dtype=float)
        return FourierTrajectory(self.q0, x[:n * L].reshape(n, L), x[n * L:].reshape(n, L),
                                 self.base_frequency)

    @property
    def coefficients(self) -> FloatArray:
        """[a.ravel(), b.ravel()], shape (2 n L,)."""
        return np.concatenate([self.a.ravel(), self.b.ravel()])


def random_trajectory(q0: FloatArray, harmonics: int, base_frequency: float,
                      velocity_limit: FloatArray, rng: np.random.Generator) -> FourierTrajectory:
    """Random FFS coefficients whose velocity bound Σ_l (|a_jl| + |b_jl|) is the joint's
    velocity limit (the baseline a designed trajectory is compared against).

    Parameters
    ----------
    q0 : ndarray, shape (n,)
        Offset (rad).
    harmonics : int
        L.
    base_frequency : float
        f_f (Hz).
    velocity_limit : ndarray, shape (n,)
        |q̇_j| bound (rad/s) the coefficients are scaled to.
    rng : numpy.random.Generator

    Returns
    -------
    FourierTrajectory
    """
    n = len(q0)
    a = rng.uniform(-1.0, 1.0, (n, harmonics))
    b = rng.uniform(-1.0, 1.0, (n, harmonics))
    scale = np.asarray(velocity_limit, dtype=float) / (np.abs(a) + np.abs(b)).sum(axis=1)
    return FourierTrajectory(np.asarray(q0, dtype=float), a * scale[:, None],
                             b * scale[:, None], float(base_frequency))
