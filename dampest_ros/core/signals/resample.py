"""Irregular sample times onto a uniform grid: gaps, jitter and linear interpolation.

Logged streams are not a perfect clock. One rule serves every reader that needs uniformly
sampled data (the arm's joint streams, the single-file CSV log):

- a step longer than :data:`GAP_PERIODS` sample periods (the median step), or not forward,
  is a **gap** (lost messages, a pause): nothing is filtered or interpolated across it, the
  stretches on either side are processed on their own;
- inside a gap-free stretch, stamps whose steps all lie within :data:`JITTER` of the median
  are kept as they are; otherwise the stretch is **resampled** by linear interpolation onto
  a uniform grid from its first stamp with its mean step (zero-mean jitter: the mean step is
  the period), never with a rate read from one step.
"""

from __future__ import annotations

from itertools import pairwise
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: A step longer than this many sample periods (the median step), or not forward, is a gap.
#: Shorter irregular steps are jitter, which :func:`on_grid` resamples away.
GAP_PERIODS = 1.75
#: Steps within this share of the median step are a uniform clock (kept as logged).
JITTER = 0.01


def step_gaps(dt: FloatArray, period: float) -> NDArray[np.int64]:
    """Indices i of the steps ``dt`` (shape (N−1,), s) that are gaps: not forward, or over
    :data:`GAP_PERIODS` × ``period`` (s)."""
    return np.flatnonzero((dt <= 0.0) | (dt > GAP_PERIODS * period))


def gaps(t: FloatArray, period: float | None = None) -> NDArray[np.int64]:
    """Where samples have a gap: the indices i whose step t[i+1] − t[i] is not forward or
    exceeds :data:`GAP_PERIODS` periods.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times (s).
    period : float, optional
        Sample period (s); default the median step.

    Returns
    -------
    ndarray of int, shape (G,)
    """
    dt = np.diff(np.asarray(t, dtype=float))
    if period is None:
        period = float(np.median(dt))
    return step_gaps(dt, period)


def increasing_runs(t: FloatArray) -> list[NDArray[np.int64]]:
    """The indices of ``t`` (shape (N,), s) split where it does not increase (a clock that
    jumped back): each run increases."""
    return np.split(np.arange(len(t)), np.flatnonzero(np.diff(t) <= 0.0) + 1)


def interpolate(t_new: FloatArray, t: FloatArray, x: FloatArray) -> FloatArray:
    """Columns of ``x`` (shape (N, n), sampled at increasing ``t``, s) linearly interpolated
    at ``t_new`` (shape (M,)); shape (M, n)."""
    return np.stack([np.interp(t_new, t, x[:, j]) for j in range(x.shape[1])], axis=1)


def on_grid(t: FloatArray, x: FloatArray, period: float | None = None
            ) -> tuple[FloatArray, FloatArray, NDArray[np.int64], float]:
    """A gap-free stretch on a uniform grid.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Increasing sample times (s) without gaps, N ≥ 2.
    x : ndarray, shape (N, n)
        Columns sampled at ``t``.
    period : float, optional
        Grid period (s); default the stretch's mean step (t[-1] − t[0]) / (N − 1).

    Returns
    -------
    t_grid : ndarray, shape (M,)
        ``t`` itself when every step is within :data:`JITTER` of the median (and no period
        is imposed), else t[0] + k · period up to t[-1].
    x_grid : ndarray, shape (M, n)
        ``x`` linearly interpolated there.
    nearest : ndarray of int, shape (M,)
        The input row nearest each grid point.
    period : float
        The grid's period (s).
    """
    dt = np.diff(t)
    median = float(np.median(dt))
    if period is None and np.all(np.abs(dt / median - 1.0) <= JITTER):
        return t, x, np.arange(len(t), dtype=np.int64), median
    step = (t[-1] - t[0]) / (len(t) - 1) if period is None else period
    grid = t[0] + step * np.arange(int(np.floor((t[-1] - t[0]) / step * (1 + 1e-12))) + 1)
    i = np.clip(np.searchsorted(t, grid), 1, len(t) - 1)
    nearest = np.where(grid - t[i - 1] <= t[i] - grid, i - 1, i).astype(np.int64)
    return grid, interpolate(grid, t, x), nearest, step


def stretch_bounds(t: FloatArray, breaks: NDArray[np.bool_] | None = None
                   ) -> NDArray[np.int64]:
    """Row bounds [0, …, N] of the gap-free stretches of ``t`` (shape (N,), s): split at the
    gaps of :func:`gaps` and after every row i with ``breaks[i]`` (shape (N−1,), e.g. a
    change of a logged segment index)."""
    cut = np.zeros(max(len(t) - 1, 0), dtype=bool)
    cut[gaps(t)] = True
    if breaks is not None:
        cut |= breaks
    return np.concatenate([[0], np.flatnonzero(cut) + 1, [len(t)]]).astype(np.int64)


class Uniform(NamedTuple):
    """A log on one uniform clock (:func:`resample_uniform`).

    Attributes
    ----------
    t : ndarray, shape (M,)
        Time (s).
    x : ndarray, shape (M, n)
        The columns at ``t``.
    segment : ndarray of int, shape (M,)
        Index of the gap-free stretch of each row, from 0.
    period : float
        The clock's period (s).
    resampled : bool
        Whether the rows were interpolated (False: the input's uniform rows).
    gaps : int
        Gaps found where no break was given.
    """

    t: FloatArray
    x: FloatArray
    segment: NDArray[np.int64]
    period: float
    resampled: bool
    gaps: int


def resample_uniform(t: FloatArray, x: FloatArray,
                     breaks: NDArray[np.bool_] | None = None) -> Uniform:
    """A whole log on one uniform clock, stretch by stretch.

    Every gap-free stretch (:func:`stretch_bounds`) of two rows or more goes onto a grid of
    one period, the mean step inside the stretches (so that filters see one rate across the
    log): unchanged when the log's steps are uniform within :data:`JITTER`, else resampled by
    :func:`on_grid`. Single rows between gaps are dropped.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Increasing sample times (s).
    x : ndarray, shape (N, n)
        Columns sampled at ``t``.
    breaks : ndarray of bool, shape (N−1,), optional
        Further places to split (after row i).

    Returns
    -------
    Uniform

    Raises
    ------
    ValueError
        When no two consecutive rows are without a gap between them.
    """
    bounds = stretch_bounds(t, breaks)
    spans = [(a, b) for a, b in pairwise(bounds.tolist()) if b - a >= 2]
    if not spans:
        raise ValueError("no two consecutive samples without a gap between them")
    steps = sum(b - a - 1 for a, b in spans)
    period = sum(float(t[b - 1] - t[a]) for a, b in spans) / steps
    dt = np.concatenate([np.diff(t[a:b]) for a, b in spans])
    median = float(np.median(dt))
    uniform = bool(np.all(np.abs(dt / median - 1.0) <= JITTER))
    parts = [on_grid(t[a:b], x[a:b], None if uniform else period)[:2] for a, b in spans]
    segment = np.repeat(np.arange(len(parts), dtype=np.int64), [len(p[0]) for p in parts])
    return Uniform(np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
                   segment, median if uniform else period, not uniform,
                   len(np.setdiff1d(gaps(t), np.flatnonzero(breaks) if breaks is not None
                                    else [])))
