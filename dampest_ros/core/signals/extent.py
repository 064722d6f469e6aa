"""What a fit needs of samples it does not hold: their count, clock, speeds and forces.

A pooled fit sums the statistics of logs that stay on the workers that read them; what it
needs of the samples themselves (how many, their segments' times, the flown envelope and the
99th percentiles of |ν_i| and |τ_i|) is an :class:`Extent`. Extents join exactly: counts,
times and extremes directly, and the percentiles from each log's largest values
(:func:`largest`; the k largest of all logs are among the k largest of each), so that a
pooled extent equals that of the logs' samples put together, to the bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dampest_ros.core.signals.samples import FloatArray, Samples

#: The percentile of |ν_i| and |τ_i| an extent holds (robust to single spikes).
PERCENTILE = 99.0


@dataclass(frozen=True)
class Extent:
    """Count, clock, envelope and percentiles of a set of samples.

    Attributes
    ----------
    n : int
        Number of samples.
    rate : float
        Sample rate of the first segment (Hz; 0 for fewer than two samples).
    spans : ndarray, shape (S, 2)
        First and last time of each segment, in order (s).
    low, high : ndarray, shape (6,)
        Smallest and largest ν per DOF (m/s, rad/s).
    speed : ndarray, shape (6,)
        :data:`PERCENTILE` of |ν_i| per DOF (m/s, rad/s).
    force : ndarray, shape (6,)
        :data:`PERCENTILE` of |τ_i| per DOF (N, N·m).
    """

    n: int
    rate: float
    spans: FloatArray
    low: FloatArray
    high: FloatArray
    speed: FloatArray
    force: FloatArray

    @classmethod
    def of(cls, samples: Samples) -> Extent:
        """The extent of ``samples`` (at least one)."""
        n = len(samples)
        top = percentile_of_largest(largest(samples, top_count(n)), n)
        spans = np.array([[samples.t[sl][0], samples.t[sl][-1]] for sl in samples.segments()],
                         dtype=float).reshape(-1, 2)
        return cls(n, samples.rate, spans, samples.nu.min(axis=0), samples.nu.max(axis=0),
                   top[:6], top[6:])

    @classmethod
    def join(cls, parts: Sequence[Extent], tops: Sequence[FloatArray]) -> Extent:
        """The extent of parts' samples put together, in order.

        Parameters
        ----------
        parts : sequence of Extent
            Each part's (:meth:`of`; its percentiles are not used), at least one.
        tops : sequence of ndarray, shape (k_b, 12)
            Each part's :func:`largest` with k = :func:`top_count` of the joined count.
        """
        n = sum(e.n for e in parts)
        top = percentile_of_largest(np.concatenate(tops), n)
        return cls(n, parts[0].rate, np.concatenate([e.spans for e in parts]),
                   np.min([e.low for e in parts], axis=0), np.max([e.high for e in parts], axis=0),
                   top[:6], top[6:])

    @property
    def flown(self) -> FloatArray:
        """Smallest and largest ν per DOF, shape (2, 6) (m/s, rad/s)."""
        return np.stack([self.low, self.high])

    @property
    def duration(self) -> float:
        """The samples' time (s): count over rate (0 without a rate)."""
        return self.n / self.rate if self.rate else 0.0


def top_count(n: int) -> int:
    """How many of the largest of ``n`` values give their :data:`PERCENTILE` (≥ 1): those
    from the lower neighbour of its index (n − 1)·q/100 up, as :func:`numpy.percentile`
    interpolates."""
    return n - int(np.floor((n - 1) * (PERCENTILE / 100)))


def largest(samples: Samples, k: int) -> FloatArray:
    """The min(k, N) largest |ν_i| and |τ_i| per column, shape (min(k, N), 12), in no order."""
    values = np.abs(np.concatenate([samples.nu, samples.tau], axis=1))
    return np.partition(values, len(values) - k, axis=0)[len(values) - k:] \
        if k < len(values) else values


def percentile_of_largest(tops: FloatArray, n: int) -> FloatArray:
    """:data:`PERCENTILE` of n values per column from (at least) their :func:`top_count`
    largest, shape (m, c) → (c,); the same, bit for bit, as :func:`numpy.percentile`'s
    linear interpolation over all n."""
    k = top_count(n)
    m = len(tops)
    top = np.sort(np.partition(tops, m - k, axis=0)[m - k:], axis=0)  # ranks n − k … n − 1
    vi = (n - 1) * (PERCENTILE / 100)  # numpy's virtual index, n − k + (its fraction g)
    if vi >= n - 1:  # one value: the largest
        return top[-1].copy()
    a, b, g = top[0], top[1], vi - np.floor(vi)
    # numpy's lerp: a + (b − a) g, or b − (b − a)(1 − g) from g = 1/2 on
    return np.where(g >= 0.5, b - (b - a) * (1 - g), a + (b - a) * g)
