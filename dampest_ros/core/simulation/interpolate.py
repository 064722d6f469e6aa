"""Interpolation of a trajectory between its integration steps (the sensor models and the
live simulation sample it at their own rates): cubic Hermite through values and slopes,
linear, and normalised linear interpolation (nlerp) of sign-continuous quaternions."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass(frozen=True)
class Knots:
    """Where query times fall among the trajectory steps: t = t[i] + s h, s ∈ [0, 1]."""

    i: IntArray  # (M,) left step
    j: IntArray  # (M,) right step (= i when the trajectory has one sample)
    s: FloatArray  # (M, 1) normalised position in the step
    h: FloatArray  # (M, 1) step length (s)


def locate(t: FloatArray, ts: FloatArray) -> Knots:
    """Steps containing the query times ``ts`` (clamped to [t[0], t[-1]])."""
    ts = np.clip(ts, t[0], t[-1])
    if len(t) == 1:
        zero = np.zeros(len(ts), dtype=np.intp)
        return Knots(zero, zero, np.zeros((len(ts), 1)), np.ones((len(ts), 1)))
    i = np.clip(np.searchsorted(t, ts, side="right") - 1, 0, len(t) - 2)
    h = t[i + 1] - t[i]
    # s = (t − t_i) / h
    s = (ts - t[i]) / h
    return Knots(i, i + 1, s[:, None], h[:, None])


def hermite(k: Knots, y: FloatArray, yd: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Cubic Hermite interpolant through values ``y`` and slopes ``yd`` (both (N, d)).

    Returns the interpolated values and their time derivatives, both (M, d).
    """
    s, h = k.s, k.h
    y0, y1, d0, d1 = y[k.i], y[k.j], yd[k.i], yd[k.j]
    h01 = s * s * (3.0 - 2.0 * s)
    h10 = s * (s - 1.0) ** 2
    h11 = s * s * (s - 1.0)
    # y(s) = y0 + h01 (y1 − y0) + h (h10 d0 + h11 d1), using h00 = 1 − h01
    value = y0 + h01 * (y1 - y0) + h * (h10 * d0 + h11 * d1)
    # dy/dt = h01' (y1 − y0) / h + h10' d0 + h11' d1, with ' = d/ds
    slope = (6.0 * s * (1.0 - s)) * (y1 - y0) / h + (3.0 * s * s - 4.0 * s + 1.0) * d0 \
        + (3.0 * s * s - 2.0 * s) * d1
    return value, slope


def linear(k: Knots, y: FloatArray) -> FloatArray:
    """Linear interpolation of ``y`` (N, d) → (M, d)."""
    # y(s) = y0 + s (y1 − y0)
    return y[k.i] + k.s * (y[k.j] - y[k.i])


def nlerp(k: Knots, q: FloatArray) -> FloatArray:
    """Normalised linear interpolation of sign-continuous quaternions (N, 4) → (M, 4)
    (:func:`dampest_ros.core.physics.frames.continuous`)."""
    qs = linear(k, q)
    # q(s) = ((1 − s) q0 + s q1) / ‖·‖
    return qs / np.linalg.norm(qs, axis=1, keepdims=True)
