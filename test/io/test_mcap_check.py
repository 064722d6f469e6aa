"""Checked MCAP reading: messages of chunks whose log times overlap come out in the order
rosbags' own reader gives, whole or in a window."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from dampest_ros.core.signals.measurements import PressureSeries
from dampest_ros.io import cdr, mcap_check


def test_overlapping_chunks_merge_in_log_time_order(tmp_path: Path) -> None:
    """60 000 pressure messages on two topics written out of log-time order (every 7th
    logged 30 s later): chunks of 1 MB whose time ranges overlap; every message read once,
    in rosbags' order, and a window is its slice."""
    n = 60_000
    log_ns = np.arange(n, dtype=np.int64) * 1_000_000 + 1
    log_ns[::7] += 30_000_000_000
    stamp = log_ns / 1e9
    msgs = cdr.encode(PressureSeries(stamp, "p", 1e5 + np.arange(n), 1.0))
    path = tmp_path / "bag"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = [w.add_connection(t, "sensor_msgs/msg/FluidPressure", typestore=cdr.typestore())
                 for t in ("/a", "/b")]
        for i, (t, m) in enumerate(zip(log_ns.tolist(), msgs, strict=True)):
            w.write(conns[i % 3 == 0], t, m)
    with Reader(path) as r:
        storage = r.storage.storages[0]  # type: ignore[attr-defined]
        chunks = sorted((c.message_start_time, c.message_end_time) for c in storage.chunks)
        assert len(chunks) >= 3 and chunks[1][0] < chunks[0][1]  # they overlap
        want = [(c.topic, t, bytes(d)) for c, t, d in r.messages()]
        got = [(c.topic, t, d) for c, t, d in mcap_check.messages(storage, r.connections)]
        assert len(got) == n and got == want
        lo, hi = 20_000_000_000, 45_000_000_000
        window = [(c.topic, t, d) for c, t, d in
                  mcap_check.messages(storage, r.connections, lo, hi)]
        assert window == [m for m in want if lo <= m[1] < hi]
