"""Synchronised samples of ν, ν̇, τ and attitude: what identification consumes.

Produced by :mod:`dampest_ros.core.signals.preprocess` from sensor topics, read from CSV, or
published sample by sample by the preprocessing node. FRD body frame, NED world (Fossen).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
#: Samples per chunk of the regressor Φ (n, 6, p) in batch passes: ~10 MB for p = 24, whatever
#: the length of the log.
CHUNK = 8000


def wire_stamp(t: float) -> int:
    """The integer nanoseconds that a header stamp of t seconds carries (nearest)."""
    return round(t * 1e9)


@dataclass
class Samples:
    """Uniformly sampled segments of vehicle data.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time (s).
    nu : ndarray, shape (N, 6)
        Body velocity over ground [u, v, w, p, q, r] (m/s, rad/s).
    nu_dot : ndarray, shape (N, 6)
        Its derivative (m/s², rad/s²).
    tau : ndarray, shape (N, 6)
        Generalised thruster force (N, N·m).
    euler : ndarray, shape (N, 3)
        Roll, pitch, yaw (rad), ZYX, body FRD → NED.
    depth : ndarray, shape (N,)
        Depth (m).
    segment : ndarray of int, shape (N,)
        Segment index; each segment is uniformly sampled and gap-free.
    """

    t: FloatArray
    nu: FloatArray
    nu_dot: FloatArray
    tau: FloatArray
    euler: FloatArray
    depth: FloatArray
    segment: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def __post_init__(self) -> None:
        n = len(self.t)
        for name in ("nu", "nu_dot", "tau", "euler", "depth", "segment"):
            a = getattr(self, name)
            if a.shape[0] != n:
                raise ValueError(f"samples.{name} has {a.shape[0]} rows, t has {n}")

    @property
    def rate(self) -> float:
        """Sample rate (Hz) of the first segment."""
        return 1.0 / float(self.t[1] - self.t[0]) if len(self) > 1 else 0.0

    def segments(self) -> Iterator[slice]:
        """Slices of the contiguous segments, in order."""
        if len(self) == 0:
            return
        edges = np.flatnonzero(np.diff(self.segment)) + 1
        bounds = np.r_[0, edges, len(self)]
        for a, b in pairwise(bounds):
            yield slice(int(a), int(b))

    def take(self, index: slice | NDArray[np.int64] | NDArray[np.bool_]) -> Samples:
        """Rows ``index`` as new Samples."""
        return Samples(self.t[index], self.nu[index], self.nu_dot[index], self.tau[index],
                       self.euler[index], self.depth[index], self.segment[index])

    @staticmethod
    def concatenate(parts: list[Samples]) -> Samples:
        """Join sample sets, renumbering segments so they stay distinct."""
        seg, offset = [], 0
        for p in parts:
            seg.append(p.segment - (p.segment.min() if len(p) else 0) + offset)
            offset = int(seg[-1].max()) + 1 if len(p) else offset
        t, nu, nu_dot, tau, euler, depth = (np.concatenate([getattr(p, f) for p in parts])
                                            for f in ("t", "nu", "nu_dot", "tau", "euler",
                                                      "depth"))
        return Samples(t, nu, nu_dot, tau, euler, depth, np.concatenate(seg).astype(np.int64))
