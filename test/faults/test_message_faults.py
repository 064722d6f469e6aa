"""Messages that named nothing: a damaged MCAP chunk is named with its bag and the repair."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from dampest_ros.cli.main import main


def damaged_copy(src: Path, dst: Path) -> Path:
    """A copy of bag ``src`` whose middle chunk's CRC no longer matches its records."""
    dst.mkdir()
    for f in src.iterdir():
        (dst / f.name).write_bytes(f.read_bytes())
    mcap = next(dst.glob("*.mcap"))
    with mcap.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunk = summary.chunk_indexes[len(summary.chunk_indexes) // 2]
    data = bytearray(mcap.read_bytes())
    at = chunk.chunk_start_offset + 1 + 8 + 24  # opcode, length, times, uncompressed size
    data[at:at + 4] = b"\xff" * 4
    mcap.write_bytes(bytes(data))
    return dst


def test_a_damaged_chunk_names_the_bag_and_dampest_reindex(
        sim_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Was: 'cannot read bag …: Chunk checksum mismatch.' (or 'Python int too large to
    convert to C ssize_t'), without the way to recover what is intact."""
    bag = damaged_copy(sim_bag, tmp_path / "damaged")
    assert main(["identify", str(bag), "--vehicle", "bluerov2_heavy"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("(log time 16.020 s, 2637 messages unreadable): ReaderError: Chunk "
                        f"checksum mismatch.); "
                        f"'dampest reindex {bag}' rebuilds its index from the intact chunks "
                        "and reports what is lost"), err
    assert len(err.splitlines()) == 1


def test_a_replay_cut_short_by_a_damaged_chunk_ends_with_status_1(
        sim_bag: Path, tmp_path: Path, children: Any) -> None:
    """Was: the playback stopped at the damaged chunk with an error line, and dampest replay
    exited 0 as if the bag had been played whole."""
    import os
    import sys

    bag = damaged_copy(sim_bag, tmp_path / "damaged")
    env = {**os.environ, "ROS_DOMAIN_ID": "92", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    run = children.run([sys.executable, "-m", "dampest_ros.cli.main", "replay", str(bag),
                        "--rate", "50", "--wait-for-subscribers", "0"], env=env,
                       capture_output=True, text=True, timeout=120)
    assert run.returncode == 1, run.stderr
    assert f"'dampest reindex {bag}' rebuilds its index" in run.stderr
    assert "Traceback" not in run.stderr
