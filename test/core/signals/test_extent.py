"""What a fit needs of samples it does not hold (dampest_ros.core.signals.extent)."""

from __future__ import annotations

import numpy as np
import pytest

from dampest_ros.core.signals.extent import (
    Extent,
    largest,
    percentile_of_largest,
    top_count,
)
from dampest_ros.core.signals.samples import Samples


def samples_of(nu: np.ndarray, tau: np.ndarray, t0: float = 0.0, rate: float = 50.0
               ) -> Samples:
    """Samples of one segment with velocities ``nu`` and forces ``tau``, shape (n, 6)."""
    n = len(nu)
    return Samples(t0 + np.arange(n) / rate, nu, np.zeros((n, 6)), tau, np.zeros((n, 3)),
                   np.zeros(n), np.zeros(n, dtype=np.int64))


@pytest.mark.parametrize("n", [*range(1, 120), 1000, 12345])
def test_the_percentile_from_the_largest_is_numpys_to_the_bit(n: int) -> None:
    """From each part's top_count(n) largest values (in no order, parts of any sizes, ties
    when rounded), the 99th percentile per column equals numpy.percentile over all n."""
    rng = np.random.default_rng(n)
    values = np.abs(rng.standard_normal((n, 12))) * rng.choice([1.0, 1e-3, 1e3], 12)
    if n % 3 == 0:
        values = np.round(values, 1)  # ties
    k = top_count(n)
    parts = np.array_split(values, rng.integers(1, 6))
    tops = [np.partition(p, len(p) - k, axis=0)[len(p) - k:] if k < len(p) else p
            for p in parts if len(p)]
    np.testing.assert_array_equal(percentile_of_largest(np.concatenate(tops), n),
                                  np.percentile(values, 99, axis=0))


def test_joined_extents_are_the_extent_of_the_samples_put_together() -> None:
    """Three logs, the last one much faster and pushed harder: the 99th percentiles of the
    three together lie in the third's largest values, more of them than its own 1 %; the
    joined extent equals that of the concatenated samples exactly (count, rate, segments'
    times, extremes, percentiles)."""
    rng = np.random.default_rng(3)
    logs = [samples_of(rng.standard_normal((n, 6)) * s, rng.standard_normal((n, 6)) * 10 * s,
                       t0=100.0 * k)
            for k, (n, s) in enumerate([(3000, 0.1), (2000, 0.1), (400, 5.0)])]
    whole = Samples.concatenate(logs)
    count = top_count(len(whole))
    assert count > top_count(len(logs[2]))
    joined = Extent.join([Extent.of(g) for g in logs], [largest(g, count) for g in logs])
    want = Extent.of(whole)
    assert joined.n == want.n == 5400 and joined.rate == want.rate == pytest.approx(50.0)
    np.testing.assert_array_equal(joined.spans, want.spans)
    assert joined.spans.shape == (3, 2) and joined.spans[2, 0] == 200.0
    for field in ("low", "high", "speed", "force"):
        np.testing.assert_array_equal(getattr(joined, field), getattr(want, field))
    np.testing.assert_array_equal(want.speed, np.percentile(np.abs(whole.nu), 99, axis=0))
    np.testing.assert_array_equal(want.force, np.percentile(np.abs(whole.tau), 99, axis=0))
    np.testing.assert_array_equal(want.flown, [whole.nu.min(axis=0), whole.nu.max(axis=0)])
    assert want.duration == pytest.approx(5400 / 50.0)
