"""Recorder and reindex faults: bit rot, a bag still being recorded, a full disk,
partial files; every case asserts what is reported and what is kept."""

from __future__ import annotations

import errno
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader

from dampest_ros.cli.main import main
from dampest_ros.io import bag
from dampest_ros.io import reindex as reindexing
from dampest_ros.io.recorder import LOCK_NAME, RESERVE_NAME, BagRecorder, StorageError
from dampest_ros.io.reindex import reindex

Msg = tuple[str, str, int, bytes]  # topic, type, log time (ns), CDR bytes


@pytest.fixture(scope="module")
def messages(sim_bag: Path) -> list[Msg]:
    """The 9845 messages of the simulated bag."""
    with Reader(sim_bag) as r:
        return [(c.topic, c.msgtype, t, bytes(d)) for c, t, d in r.messages()]


def record(path: Path, messages: list[Msg], handed: list[Msg] | None = None,
           **kw: Any) -> BagRecorder:
    """Open a recorder and write ``messages`` (not closed); each message is appended to
    ``handed`` before it is written."""
    rec = BagRecorder(path, **kw).open()
    conns: dict[str, int] = {}
    for m in messages:
        topic, msgtype, t, data = m
        if topic not in conns:
            conns[topic] = rec.add_connection(topic, msgtype, bag.offered_qos(topic))
        if handed is not None:
            handed.append(m)
        rec.write(conns[topic], t, data)
    return rec


def stored(path: Path) -> list[tuple[str, int, bytes]]:
    """Topic, log time and bytes of every message of a bag, as rosbags reads them."""
    with Reader(path) as r:
        return [(c.topic, t, bytes(d)) for c, t, d in r.messages()]


def leftovers(path: Path) -> list[str]:
    """Lock, reserve, journals and partial files in a bag directory."""
    return sorted(p.name for p in path.iterdir()
                  if p.name in (LOCK_NAME, RESERVE_NAME)
                  or p.suffix in (".tmp", ".recovering", ".journal"))


def test_bit_rot_in_a_chunk_is_reported_in_bytes_and_messages(
        tmp_path: Path, messages: list[Msg], capsys: pytest.CaptureFixture[str]) -> None:
    """4 KB of random bytes inside a chunk: was 'complete, 0 bytes lost'."""
    path = tmp_path / "rot"
    record(path, messages, chunk_size=64 * 1024).close()
    (mcap,) = path.glob("*.mcap")
    with mcap.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunk = summary.chunk_indexes[len(summary.chunk_indexes) // 2]
    in_chunk = sum(len(o) for o in _message_index_counts(mcap, chunk))
    with mcap.open("r+b") as f:
        f.seek(chunk.chunk_start_offset + 200)
        f.write(np.random.default_rng(4).bytes(4096))
    assert main(["reindex", str(path)]) == 1  # was 0
    out = capsys.readouterr().out.splitlines()
    kept = len(messages) - in_chunk
    assert out[-1] == (f"wrote {path / 'metadata.yaml'}: {kept} messages; unreadable: "
                       f"{in_chunk} messages counted by the indexes, {chunk.chunk_length} "
                       "bytes")
    assert " recovered " in out[2] and "damaged chunk" in out[2]
    assert bag.bag_summary(path).message_count == kept
    assert len(bag.read_bag(path)["imu/data"]) > 0
    assert (path / (mcap.name + ".damaged")).exists() and leftovers(path) == []
    print(f"4 KB of bit rot in one chunk: {in_chunk} messages, {chunk.chunk_length} B lost; "
          f"{kept} of {len(messages)} kept")


def _message_index_counts(mcap: Path, chunk: Any) -> list[list[Any]]:
    """The message index entries of a chunk, per channel (they follow the chunk)."""
    from mcap.data_stream import ReadDataStream
    from mcap.records import MessageIndex

    out = []
    with mcap.open("rb") as f:
        for offset in chunk.message_index_offsets.values():
            f.seek(offset + 9)  # opcode and record length
            out.append(MessageIndex.read(ReadDataStream(f)).records)
    return out


def test_reindex_exit_status_says_whether_every_byte_was_read(
        tmp_path: Path, messages: list[Msg], capsys: pytest.CaptureFixture[str]) -> None:
    """Exit 0 for an intact bag; 1 for a file cut 100 bytes into a chunk (what a SIGKILL
    during a chunk write leaves), with the 100 bytes printed."""
    path = tmp_path / "cut"
    record(path, messages, chunk_size=64 * 1024).close()
    assert main(["reindex", str(path)]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == (
        f"wrote {path / 'metadata.yaml'}: {len(messages)} messages; unreadable: 0 messages "
        "counted by the indexes, 0 bytes")
    (mcap,) = path.glob("*.mcap")
    with mcap.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    k = len(chunks) // 2
    before = sum(sum(len(o) for o in _message_index_counts(mcap, c)) for c in chunks[:k])
    os.truncate(mcap, chunks[k].chunk_start_offset + 100)
    assert main(["reindex", str(path)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[-1] == (f"wrote {path / 'metadata.yaml'}: {before} messages; unreadable: 0 "
                       "messages counted by the indexes, 100 bytes")
    assert leftovers(path) == [] and stored(path) == [
        (topic, t, d) for topic, _, t, d in messages[:before]]


def test_reindex_refuses_a_bag_being_recorded_and_so_does_a_second_recorder(
        tmp_path: Path, messages: list[Msg], capsys: pytest.CaptureFixture[str]) -> None:
    """Was: the live file renamed .damaged, the recorder writing on into it (58 % kept)."""
    path = tmp_path / "live"
    rec = record(path, messages[:3000])
    (mcap,) = path.glob("*.mcap")
    assert main(["reindex", str(path)]) == 2
    line = capsys.readouterr().err.strip()
    assert line == (f"dampest reindex: error: {path} is being recorded by a recorder (pid "
                    f"{os.getpid()}) (lock {path / LOCK_NAME}): reindex would rewrite the file "
                    "being written; stop the recorder first (Ctrl-C or SIGTERM close the bag "
                    "and write its metadata.yaml, no reindex needed)")
    with pytest.raises(FileExistsError, match="being recorded by a recorder"):
        BagRecorder(path).open()
    assert sorted(p.name for p in path.iterdir()) == sorted([mcap.name, LOCK_NAME,
                                                             RESERVE_NAME,
                                                             mcap.name + ".journal"])
    rec.close()
    assert leftovers(path) == []
    assert bag.bag_summary(path).message_count == 3000
    assert reindex(path).messages == 3000


def test_reindex_removes_partial_files_and_a_stale_lock(tmp_path: Path, messages: list[Msg],
                                                        capsys: pytest.CaptureFixture[str]
                                                        ) -> None:
    """What a SIGKILL leaves: a lock nobody holds, the reserve, a .recovering and a .tmp."""
    path = tmp_path / "killed"
    record(path, messages[:2000]).close()
    for name in (LOCK_NAME, RESERVE_NAME, "killed_0.mcap.recovering", "metadata.yaml.tmp"):
        (path / name).write_bytes(b"partial")
    assert main(["reindex", str(path)]) == 0
    assert capsys.readouterr().out.splitlines()[0] == (
        "removed partial files left by a killed recorder or reindex: .dampest.reserve, "
        "killed_0.mcap.recovering, metadata.yaml.tmp")  # (the stale lock is taken, then removed)
    assert leftovers(path) == [] and bag.bag_summary(path).message_count == 2000


def full_disk(monkeypatch: pytest.MonkeyPatch, path: Path, limit: int, *,
              reserve_helps: bool = True) -> Callable[[], int]:
    """Storage writes fail with ENOSPC once ``limit`` bytes are in the bag's files (while the
    reserve exists when ``reserve_helps``: removing it frees the room); returns the bytes
    written so far."""
    written = [0]
    real = os.pwrite

    def pwrite(fd: int, data: Any, offset: int) -> int:
        full = written[0] + len(data) > limit
        if full and (not reserve_helps or (path / RESERVE_NAME).exists()):
            half = max(limit - written[0], 0) // 2  # a partial write, then the error
            if half:
                written[0] += real(fd, bytes(data[:half]), offset)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = real(fd, data, offset)
        written[0] += n
        return n

    monkeypatch.setattr(os, "pwrite", pwrite)  # (the os module recorder writes with)
    return lambda: written[0]


def test_disk_full_stops_cleanly_with_every_message_kept(
        tmp_path: Path, messages: list[Msg], monkeypatch: pytest.MonkeyPatch) -> None:
    """Was: ENOSPC traceback, no metadata.yaml."""
    path = tmp_path / "full"
    full_disk(monkeypatch, path, 1_000_000)
    with pytest.raises(StorageError) as err:
        record(path, messages, chunk_size=64 * 1024)
    kept = bag.bag_summary(path).message_count
    assert str(err.value) == (f"No space left on device while recording {path}: recording "
                              f"stopped, the bag is closed with all its {kept} messages")
    assert 1000 < kept < len(messages)
    assert stored(path) == [(topic, t, d) for topic, _, t, d in messages[:kept]]
    assert (path / "metadata.yaml").exists() and leftovers(path) == []


def test_disk_full_even_after_the_reserve_keeps_every_message_for_reindex(
        tmp_path: Path, messages: list[Msg], monkeypatch: pytest.MonkeyPatch) -> None:
    """The complete chunks are in the file, the chunk that could not be written is in the
    journal (the journal's writes are not refused here): reindex recovers every message
    the recorder was given."""
    path = tmp_path / "full"
    full_disk(monkeypatch, path, 1_000_000, reserve_helps=False)
    handed: list[Msg] = []
    with pytest.raises(StorageError, match=f"free space, then 'dampest reindex {path}'"):
        record(path, messages, handed, chunk_size=64 * 1024)
    assert leftovers(path) == ["full_0.mcap.journal"]
    assert not (path / "metadata.yaml").exists()
    monkeypatch.undo()  # space freed
    report = reindex(path)
    # the failed write was cut off: the file ends at a record boundary
    assert report.files[0].recovered and report.files[0].error == "EndOfFile"
    assert report.files[0].lost_bytes == 0 and 0 < report.files[0].journal < 1000
    assert 1000 < report.messages == len(handed) < len(messages)
    assert stored(path) == [(topic, t, d) for topic, _, t, d in handed]
    assert leftovers(path) == []


def test_reindex_that_fails_leaves_no_partial_file(tmp_path: Path, messages: list[Msg],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Was: a 0-byte .recovering after ENOSPC during reindex in place."""
    path = tmp_path / "cut"
    record(path, messages[:4000], chunk_size=16 * 1024).close()
    (mcap,) = path.glob("*.mcap")
    (path / "metadata.yaml").unlink()
    os.truncate(mcap, mcap.stat().st_size // 2)
    before = mcap.read_bytes()

    def no_space(*args: Any, **kw: Any) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(reindexing, "McapWriter", no_space)
    with pytest.raises(OSError, match="No space left"):
        reindex(path)
    assert sorted(p.name for p in path.iterdir()) == [mcap.name]
    assert mcap.read_bytes() == before
    monkeypatch.undo()
    assert reindex(path).messages > 1000


def test_chunks_reach_the_file_within_a_quarter_second(tmp_path: Path,
                                                       messages: list[Msg]) -> None:
    """The recorder node calls flush_if_due every flush_period / 4: a message is in the
    file at most 0.25 s after it was written (the default flush_period, 0.2 s)."""
    now = [0.0]
    rec = BagRecorder(tmp_path / "run", clock=lambda: now[0]).open()
    conn = rec.add_connection("/imu/data", "sensor_msgs/msg/Imu")
    imu = [m for m in messages if m[0] == "/imu/data"]
    (mcap,) = (tmp_path / "run").glob("*.mcap")
    on_disk = mcap.stat().st_size
    for k, (_, _, t, data) in enumerate(imu[:40]):  # one message per 0.05 s timer tick
        rec.write(conn, t, data)
        written_at = now[0]
        while mcap.stat().st_size == on_disk:
            now[0] += 0.05
            rec.flush_if_due()
        on_disk = mcap.stat().st_size
        assert now[0] - written_at <= 0.25 + 1e-9, k
    rec.close()


def killed_copy(path: Path, to: Path, journal_from: Path | None = None) -> Path:
    """The bag directory as a SIGKILL would leave it now: its files as they are on disk
    (the journal taken from ``journal_from`` when given)."""
    to.mkdir()
    for f in path.iterdir():
        (to / f.name.replace(path.name, to.name)).write_bytes(f.read_bytes())
    if journal_from is not None:
        (journal,) = journal_from.glob("*.journal")
        (to / journal.name.replace(journal_from.name, to.name)).write_bytes(
            journal.read_bytes())
    return to


def test_a_killed_recorder_keeps_every_message_it_was_given(tmp_path: Path,
                                                          messages: list[Msg]) -> None:
    """Was: the chunk in progress lost (up to 0.25 s of messages). Its messages are in the
    journal: reindex recovers all 5000 (none lost, exit status 0); a journal cut inside its
    last record gives all but that message; a journal whose chunk did reach the file (killed
    between the chunk's write and the journal's restart) adds nothing twice."""
    now = [0.0]  # no flush by age: chunks by size only
    rec = record(tmp_path / "run", messages[:5000], chunk_size=64 * 1024, clock=lambda: now[0])
    killed = killed_copy(tmp_path / "run", tmp_path / "k1")
    report = reindex(killed)
    assert report.messages == 5000 and report.lost_bytes == 0 and report.lost_messages == 0
    assert 0 < report.files[0].journal < 5000
    assert stored(killed) == [(topic, t, d) for topic, _, t, d in messages[:5000]]
    assert leftovers(killed) == []

    torn = killed_copy(tmp_path / "run", tmp_path / "k2")
    (journal,) = torn.glob("*.journal")
    os.truncate(journal, journal.stat().st_size - 5)
    assert reindex(torn).messages == 4999
    assert stored(torn) == [(topic, t, d) for topic, _, t, d in messages[:4999]]

    stale = killed_copy(tmp_path / "run", tmp_path / "before_flush")
    rec.flush()  # the chunk reaches the file; the copy's journal is the one from before
    both = killed_copy(tmp_path / "run", tmp_path / "k3", journal_from=stale)
    report = reindex(both)
    assert report.messages == 5000 and report.files[0].journal == 0
    assert stored(both) == [(topic, t, d) for topic, _, t, d in messages[:5000]]
    rec.close()
    assert leftovers(tmp_path / "run") == []
