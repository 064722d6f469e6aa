"""Terms a simulator's format cannot carry (element drags, products, speed norms), refitted
onto entries it can: F_i = c ν_j or c ν_j |ν_k| per force row i, by least squares over the
flown envelope (``dampest export --refold``).

The entries reproduce the force of the refolded terms where the vehicle flew, not their
form: how much of that force they reproduce is part of the result and of the exported file.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import product

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification.dissipative import envelope
from dampest_ros.core.physics.damping import DampingModel

FloatArray = NDArray[np.float64]

#: Sizes of the grids over the flown envelope the entries are fitted on.
SCALES = (1.0, 0.5, 0.25, 0.1)

#: An entry of force row i: (i, j, k) is F_i = c ν_j for k = −1, else F_i = c ν_j |ν_k|.
Entry = tuple[int, int, int]


def all_entries() -> list[Entry]:
    """Every c ν_j and c ν_j |ν_k| of every row (the gz-sim plugin's tags)."""
    return ([(i, j, -1) for i, j in product(range(6), repeat=2)]
            + [(i, j, k) for i, j, k in product(range(6), repeat=3)])


def diagonal_entries() -> list[Entry]:
    """c ν_i and c ν_i |ν_i| of each row i (a diagonal damping block)."""
    return [e for i in range(6) for e in ((i, i, -1), (i, i, i))]


@dataclass(frozen=True)
class Refold:
    """Entries that stand in for some terms of a model over its flown envelope.

    Attributes
    ----------
    entries : list of Entry
        Those with a non-zero value, row by row.
    values : ndarray, shape (m,)
        Their coefficients (the units of the force row over ν_j or ν_j |ν_k|).
    share : ndarray, shape (6,)
        Per force row, 1 − Σ (F − F̂)² / Σ F² over the grid: the share of the refolded
        terms' force the entries reproduce (NaN where those terms exert none).
    rms : ndarray, shape (6,)
        Per force row, the RMS of what the entries miss over the grid (N, N·m).
    """

    entries: list[Entry]
    values: FloatArray
    share: FloatArray
    rms: FloatArray


def refold(model: DampingModel, theta: FloatArray, which: NDArray[np.bool_],
           flown: FloatArray, entries: Sequence[Entry]) -> Refold:
    """Fit ``entries`` to the force of the parameters ``which`` of ``model`` (their
    static part: fluid memory at rest) over the grid of the flown envelope
    (:func:`~dampest_ros.core.identification.dissipative.envelope`, 5⁶ velocities, at
    :data:`SCALES` of its size: the data sit mostly well inside it).

    Parameters
    ----------
    model : DampingModel
    theta : ndarray, shape (p,)
    which : ndarray of bool, shape (p,)
        The parameters to refold.
    flown : ndarray, shape (2, 6)
        The smallest and largest velocities flown (m/s, rad/s).
    entries : sequence of Entry
        What may stand in for them (:func:`all_entries`, :func:`diagonal_entries`).
    """
    nu = envelope(np.asarray(flown, dtype=float), scales=SCALES)
    z = np.zeros((len(nu), len(model.memory_rates)))
    Phi = model.regressor(nu, z if z.shape[1] else None)
    # F = Φ_which θ_which: the force of the refolded terms at every grid velocity
    F = Phi[:, :, which] @ np.asarray(theta, dtype=float)[which]
    kept: list[Entry] = []
    values: list[float] = []
    share, rms = np.full(6, np.nan), np.zeros(6)
    for i in range(6):
        row = [e for e in entries if e[0] == i]
        # columns ν_j or ν_j |ν_k| of row i at every grid velocity
        X = np.stack([nu[:, j] * (np.abs(nu[:, k]) if k >= 0 else 1.0) for _, j, k in row],
                     axis=1) if row else np.zeros((len(nu), 0))
        c = np.linalg.lstsq(X, F[:, i], rcond=None)[0] if row else np.zeros(0)
        miss = F[:, i] - X @ c
        rms[i] = float(np.sqrt(np.mean(miss ** 2)))
        total = float(np.sum(F[:, i] ** 2))
        if total > 0:
            share[i] = 1.0 - float(np.sum(miss ** 2)) / total
        scale = np.abs(X).max(axis=0) if row else np.zeros(0)
        for e, v, s in zip(row, c, scale, strict=True):
            if v * s != 0.0 and abs(v) * s > 1e-12 * max(np.abs(F[:, i]).max(), 1e-300):
                kept.append(e)
                values.append(float(v))
    return Refold(kept, np.array(values), share, rms)
