"""Streaming MCAP recorder and reindex: bags read back with rosbags and with mcap + mcap_ros2;
a recording cut at any byte is recovered up to its last complete chunk."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.stream_reader import breakup_chunk
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader

from dampest_ros.core.signals.measurements import ImuSeries, JointSeries, Series
from dampest_ros.io import bag, cdr
from dampest_ros.io.bag_metadata import make_qos
from dampest_ros.io.recorder import BagRecorder, RecorderError
from dampest_ros.io.reindex import reindex

Msg = tuple[str, int, bytes]  # topic, log time (ns), CDR bytes


@pytest.fixture
def series(make_series: Any) -> dict[str, Series]:
    """20 s of IMU at 200 Hz and thruster states at 50 Hz."""
    return {"imu/data": make_series(ImuSeries, 4000, rate=200.0, frame_id="imu_link"),
            "thrusters/state": make_series(JointSeries, 1000, rate=50.0, frame_id="")}


@pytest.fixture
def messages(series: dict[str, Series]) -> list[Msg]:
    """The messages of ``series`` interleaved in time order."""
    out = [("/" + t, int(ns), raw) for t, s in series.items()
           for ns, raw in zip(cdr.stamps_to_ns(s.stamp), cdr.encode(s), strict=True)]
    return sorted(out, key=lambda m: m[1])


def record(path: Path, messages: list[Msg], *, close: bool = True, **kw: Any) -> BagRecorder:
    rec = BagRecorder(path, **kw).open()
    conns = {t: rec.add_connection(t, "sensor_msgs/msg/Imu" if "imu" in t
                                   else "sensor_msgs/msg/JointState", bag.offered_qos(t))
             for t in dict.fromkeys(m[0] for m in messages)}
    for topic, ns, raw in messages:
        rec.write(conns[topic], ns, raw, publish_time=ns + 7)
    if close:
        rec.close()
    return rec


def raw_messages(path: Path) -> list[Msg]:
    with Reader(path) as reader:
        return [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]


def test_recorded_bag_reads_back_with_rosbags_and_mcap(tmp_path: Path, messages: list[Msg],
                                                       series: dict[str, Series],
                                                       assert_same: Any, to_ros: Any,
                                                       tree: Any) -> None:
    path = tmp_path / "run"
    rec = record(path, messages, chunk_size=16 * 1024, max_bag_size=400_000)
    files = sorted(path.glob("*.mcap"))
    assert [f.name for f in files] == [f"run_{k}.mcap" for k in range(len(files))]
    assert len(files) == 5  # 1.87 MB of messages (IMU 340 B, JointState 400 B)
    assert rec.chunks > 80
    assert all(f.stat().st_size < 400_000 + 8_000 for f in files)  # + summary

    # rosbags: every message, bit for bit, in order, with the offered QoS in the metadata
    assert raw_messages(path) == [(t, ns, raw) for t, ns, raw in messages]
    summary = bag.bag_summary(path)
    assert {t: s.count for t, s in summary.topics.items()} == {"/imu/data": 4000,
                                                               "/thrusters/state": 1000}
    assert summary.start == series["imu/data"].stamp[0]
    assert summary.end == pytest.approx(19.995, abs=1e-9)
    with Reader(path) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert qos == {t: [bag.offered_qos(t)] for t in qos}
    out = bag.read_bag(path)
    for topic, s in series.items():
        assert_same(out[topic], s)
    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    assert sum(f["message_count"] for f in meta["files"]) == 5000
    assert meta["relative_file_paths"] == [f.name for f in files]

    # mcap + mcap_ros2: decoded values equal the messages, log and publish times kept
    seen = {t: 0 for t in series}
    for f in files:
        with f.open("rb") as h:
            reader = make_reader(h, decoder_factories=[DecoderFactory()])
            for schema, channel, message, decoded in reader.iter_decoded_messages():
                topic = channel.topic.lstrip("/")
                assert schema.encoding == "ros2msg"
                assert channel.metadata["topic_type_hash"].startswith("RIHS01_")
                assert tree(decoded) == tree(to_ros(series[topic], seen[topic]))
                assert message.publish_time == message.log_time + 7
                seen[topic] += 1
    assert seen == {"imu/data": 4000, "thrusters/state": 1000}


def test_split_by_duration(tmp_path: Path, messages: list[Msg]) -> None:
    path = tmp_path / "run"
    record(path, messages, max_bag_duration=4.0)
    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    spans = [f["duration"]["nanoseconds"] for f in meta["files"]]
    counts = [f["message_count"] for f in meta["files"]]
    assert len(spans) == 5 and max(spans) < 4e9
    assert counts == [1000] * 5  # 4 s of 200 + 50 Hz each
    assert len(raw_messages(path)) == 5000


def test_never_overwrites_and_rejects_misuse(tmp_path: Path, messages: list[Msg]) -> None:
    path = tmp_path / "run"
    path.mkdir()
    (path / "keep.txt").write_text("data")
    with pytest.raises(FileExistsError, match="never overwrites"):
        BagRecorder(path).open()
    assert [p.name for p in path.iterdir()] == ["keep.txt"]
    rec = BagRecorder(tmp_path / "other")
    with pytest.raises(RecorderError, match="not open"):
        rec.add_connection("/a", "std_msgs/msg/String")
    rec.open()
    conn = rec.add_connection("a", "std_msgs/msg/String", make_qos())
    assert rec.connection("/a") == conn
    with pytest.raises(RecorderError, match="already recorded"):
        rec.add_connection("/a", "std_msgs/msg/String")
    with pytest.raises(RecorderError, match="unknown connection"):
        rec.write(conn + 1, 0, b"")
    with pytest.raises(ValueError, match="compression"):
        BagRecorder(tmp_path / "x", compression="gzip")
    rec.close()
    assert bag.bag_summary(tmp_path / "other").message_count == 0


def test_chunk_interval_reaches_the_disk_without_close(tmp_path: Path,
                                                       messages: list[Msg]) -> None:
    """A slow topic: the chunk in progress is written once it is chunk_interval old."""
    now = [0.0]
    rec = BagRecorder(tmp_path / "run", chunk_interval=1.0, clock=lambda: now[0]).open()
    conn = rec.add_connection("/imu/data", "sensor_msgs/msg/Imu")
    for _, ns, raw in [m for m in messages if m[0] == "/imu/data"][:10]:
        rec.write(conn, ns, raw)
    assert rec.chunks == 0
    now[0] = 1.5
    rec.flush_if_due()
    assert rec.chunks == 1
    (path,) = (tmp_path / "run").glob("*.mcap")
    copy = tmp_path / "copy"
    copy.mkdir()
    shutil.copy(path, copy / path.name)  # what a kill now would leave
    report = reindex(copy)
    assert report.messages == 10 and not report.files[0].complete
    rec.close()


def complete_chunk_counts(path: Path) -> list[tuple[int, int]]:
    """(end offset, message count) of each chunk of an intact file, from its summary index
    and the chunk records themselves (independent of the recorder's recovery code)."""
    out = []
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
        assert summary is not None
        for index in summary.chunk_indexes:
            f.seek(index.chunk_start_offset + 9)  # opcode + record length
            chunk = Chunk.read(ReadDataStream(f))
            n = sum(1 for r in breakup_chunk(chunk) if type(r).__name__ == "Message")
            out.append((index.chunk_start_offset + index.chunk_length, n))
    return out


def test_reindex_recovers_a_recording_cut_anywhere(tmp_path: Path, messages: list[Msg],
                                                   series: dict[str, Series]) -> None:
    """Cut the last file at random bytes, delete metadata.yaml: reindex keeps every message
    of every complete chunk before the cut; rosbags, read_bag and mcap_ros2 read the result."""
    src = tmp_path / "src"
    record(src, messages, chunk_size=8 * 1024, max_bag_size=1_000_000)
    last = sorted(src.glob("*.mcap"))[-1]
    before = sum(f["message_count"] for f in yaml.safe_load(
        (src / "metadata.yaml").read_text())["rosbag2_bagfile_information"]["files"][:-1])
    chunks = complete_chunk_counts(last)
    assert len(chunks) > 40
    size = last.stat().st_size
    rng = np.random.default_rng(7)
    cuts = [*rng.integers(0, size, 6).tolist(), chunks[0][0], chunks[5][0] - 1, size - 1]
    for k, cut in enumerate(cuts):
        path = tmp_path / f"cut{k}"
        shutil.copytree(src, path)
        (path / "metadata.yaml").unlink()
        with (path / last.name).open("r+b") as f:
            f.truncate(cut)
        with pytest.raises(bag.BagError, match="dampest reindex"):
            bag.read_bag(path)

        report = reindex(path)
        expected = before + sum(n for end, n in chunks if end <= cut)
        assert report.messages == expected, (cut, report)
        print(f"cut at {cut}/{size} B: {report.messages} messages recovered, {expected} in "
              f"complete chunks, lost tail {report.files[-1].lost_bytes} B")
        assert report.messages >= 0.99 * expected
        damaged = report.files[-1]
        assert not damaged.complete and damaged.lost_bytes < 8 * 1024 + 2_000
        assert all(f.complete for f in report.files[:-1])

        got = raw_messages(path)
        assert got == [(t, ns, raw) for t, ns, raw in messages[:expected]]
        out = bag.read_bag(path)
        n_imu = sum(1 for t, _, _ in messages[:expected] if t == "/imu/data")
        assert len(out["imu/data"]) == n_imu
        np.testing.assert_array_equal(out["imu/data"].angular_velocity,
                                      series["imu/data"].angular_velocity[:n_imu])
        assert bag.bag_summary(path).message_count == expected
        if damaged.recovered and damaged.messages:
            assert (path / (last.name + ".damaged")).stat().st_size == cut
            with (path / last.name).open("rb") as f:
                decoded = list(make_reader(f, decoder_factories=[DecoderFactory()])
                               .iter_decoded_messages())
            assert len(decoded) == damaged.messages
            imu = [d for _, c, _, d in decoded if c.topic == "/imu/data"]
            start = n_imu - len(imu)
            np.testing.assert_array_equal(
                [[d.angular_velocity.x, d.angular_velocity.y, d.angular_velocity.z]
                 for d in imu], series["imu/data"].angular_velocity[start:n_imu])


def test_reindex_of_a_recording_never_closed(tmp_path: Path, messages: list[Msg]) -> None:
    """The process dies without close(): flushed chunks are all there."""
    rec = record(tmp_path / "run", messages, close=False, chunk_size=8 * 1024)
    written = rec.message_count
    assert written == len(messages)
    (mcap_file,) = (tmp_path / "run").glob("*.mcap")
    copy = tmp_path / "killed"
    copy.mkdir()
    shutil.copy(mcap_file, copy / mcap_file.name)
    rec.close()
    report = reindex(copy)
    lost = written - report.messages
    assert 0 <= lost <= 8 * 1024 // 300  # at most the chunk in progress
    assert raw_messages(copy) == messages[:report.messages]


def test_reindex_of_a_complete_bag_reproduces_its_metadata(tmp_path: Path,
                                                           messages: list[Msg]) -> None:
    path = tmp_path / "run"
    record(path, messages, max_bag_size=500_000)
    original = yaml.safe_load((path / "metadata.yaml").read_text())
    (path / "metadata.yaml").unlink()
    report = reindex(path)
    assert all(f.complete and not f.recovered for f in report.files)
    assert yaml.safe_load((path / "metadata.yaml").read_text()) == original
    assert not list(path.glob("*.damaged"))
    with pytest.raises(FileNotFoundError, match=r"no \.mcap"):
        reindex(tmp_path)
