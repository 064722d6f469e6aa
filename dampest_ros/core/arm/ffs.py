"""Finite Fourier series (FFS) joint trajectories: the design engine's
:class:`~dampest_ros.core.simulation.design.FourierTrajectory` (periodic, q, q̇, q̈ analytic; its
equations there) and the random coefficients a designed trajectory is compared against.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.simulation.design import FourierTrajectory

FloatArray = NDArray[np.float64]

__all__ = ["FourierTrajectory", "random_trajectory"]


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
