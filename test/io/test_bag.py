"""rosbag2 bags: written by write_bag, read back by rosbags, by the mcap library and by
read_bag, message for message; ROS 1 bags written by rosbags' rosbag1 Writer (messages in the
ROS 1 wire format by rosbags' ROS 1 Noetic typestore), read by the same reader."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from dampest_ros.core.signals.measurements import ImuSeries, Series, TwistSeries
from dampest_ros.io import bag, cdr

Tree = Callable[[Any], Any]
ToRos = Callable[[Series, int], Any]
AssertSame = Callable[[Series, Series], None]


def stamp_ns(s: Series, i: int) -> int:
    return int(cdr.stamps_to_ns(s.stamp[i:i + 1])[0])


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_rosbags_reads_every_message_written(storage: str, tmp_path: Path,
                                             recording: dict[str, Series], typestore: Any,
                                             to_ros: ToRos, tree: Tree) -> None:
    path = bag.write_bag(tmp_path / "run", recording, storage=storage)
    seen: dict[str, int] = {t: 0 for t in recording}
    last = -1
    with AnyReader([path], default_typestore=typestore) as reader:
        assert {c.topic for c in reader.connections} == {"/" + t for t in recording}
        for conn, log_ns, raw in reader.messages():
            topic = conn.topic.lstrip("/")
            s, i = recording[topic], seen[topic]
            assert conn.msgtype == cdr.message_type(s)
            assert tree(reader.deserialize(raw, conn.msgtype)) == tree(to_ros(s, i))
            assert log_ns == stamp_ns(s, i) >= last  # log time = header stamp, interleaved
            last = log_ns
            seen[topic] += 1
    assert seen == {t: len(s) for t, s in recording.items()}


def test_mcap_library_decodes_every_message_written(tmp_path: Path,
                                                    recording: dict[str, Series],
                                                    to_ros: ToRos, tree: Tree) -> None:
    path = bag.write_bag(tmp_path / "run", recording)
    (mcap_file,) = path.glob("*.mcap")
    seen: dict[str, int] = {t: 0 for t in recording}
    with mcap_file.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            topic = channel.topic.lstrip("/")
            s, i = recording[topic], seen[topic]
            assert schema.name == cdr.message_type(s)
            assert tree(decoded) == tree(to_ros(s, i))
            assert message.log_time == stamp_ns(s, i)
            seen[topic] += 1
    assert seen == {t: len(s) for t, s in recording.items()}


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_read_bag_round_trip_is_exact(storage: str, tmp_path: Path,
                                      recording: dict[str, Series],
                                      assert_same: AssertSame,
                                      monkeypatch: pytest.MonkeyPatch) -> None:
    path = bag.write_bag(tmp_path / "run", recording, storage=storage)
    out = bag.read_bag(path)
    assert out.keys() == recording.keys()
    for topic, s in recording.items():
        assert_same(out[topic], s)
    # in chunks that do not divide the counts, and by absolute names
    monkeypatch.setattr(bag, "READ_CHUNK", 7)
    out = bag.read_bag(path, ["/imu/data", "thrusters/state"])
    assert list(out) == ["/imu/data", "thrusters/state"]
    assert_same(out["/imu/data"], recording["imu/data"])
    assert_same(out["thrusters/state"], recording["thrusters/state"])


def test_metadata_offers_the_contract_qos(tmp_path: Path, recording: dict[str, Series]) -> None:
    path = bag.write_bag(tmp_path / "run", recording)
    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    qos = {t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"][0]
           for t in meta["topics_with_message_count"]}
    counts = {t["topic_metadata"]["name"]: t["message_count"]
              for t in meta["topics_with_message_count"]}
    assert counts == {"/" + t: len(s) for t, s in recording.items()}
    for topic in ("/imu/data", "/dvl/twist", "/pressure", "/thrusters/state"):
        assert (qos[topic]["reliability"], qos[topic]["durability"], qos[topic]["depth"]) \
            == ("best_effort", "volatile", 5)
    for topic in ("/truth/odom", "/dampest/velocity", "/dampest/acceleration",
                  "/dampest/wrench"):
        assert (qos[topic]["reliability"], qos[topic]["durability"]) == ("reliable", "volatile")
    # infinite deadline, lifespan and lease as Jazzy's rosbag2 writes them (RMW's INT64_MAX ns)
    for profile in qos.values():
        for key in ("deadline", "lifespan", "liveliness_lease_duration"):
            assert profile[key] == {"sec": 9223372036, "nsec": 854775807}, (key, profile)
    model = bag.offered_qos("vehicle/dampest/model")
    assert (model.reliability.name, model.durability.name, model.depth) == \
        ("RELIABLE", "TRANSIENT_LOCAL", 1)


def test_existing_path_is_never_overwritten(tmp_path: Path,
                                            recording: dict[str, Series]) -> None:
    path = bag.write_bag(tmp_path / "run", recording)
    before = sorted((p.name, p.stat().st_size) for p in path.iterdir())
    with pytest.raises(FileExistsError, match="never overwrites"):
        bag.write_bag(path, {"imu/data": recording["imu/data"]})
    assert sorted((p.name, p.stat().st_size) for p in path.iterdir()) == before


def test_failed_write_leaves_no_half_written_bag(tmp_path: Path,
                                                 recording: dict[str, Series],
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []

    def failing_write(self: Writer, *args: Any) -> None:
        calls.append(1)
        if len(calls) == 100:
            raise OSError("disk full")

    monkeypatch.setattr(Writer, "write", failing_write)
    with pytest.raises(OSError, match="disk full"):
        bag.write_bag(tmp_path / "run", recording)
    assert not (tmp_path / "run").exists()


def test_missing_topic_error_lists_the_bag_topics(tmp_path: Path,
                                                  recording: dict[str, Series]) -> None:
    path = bag.write_bag(tmp_path / "run", {"imu/data": recording["imu/data"],
                                            "pressure": recording["pressure"]})
    with pytest.raises(bag.MissingTopicError) as err:
        bag.read_bag(path, ["imu/data", "dvl/twist"])
    text = str(err.value)
    assert "dvl/twist" in text
    assert "/imu/data (sensor_msgs/msg/Imu)" in text
    assert "/pressure (sensor_msgs/msg/FluidPressure)" in text


@pytest.mark.parametrize("where", [0.0, 0.1, 0.5, 0.98])
def test_corrupt_bag_error_names_the_file(where: float, tmp_path: Path,
                                          recording: dict[str, Series],
                                          assert_same: AssertSame) -> None:
    """Garbage in the data, the indexes or the summary: an error naming the file, or (where
    the garbage hits a part rosbags does not need) every message intact."""
    path = bag.write_bag(tmp_path / "run", recording)
    (mcap_file,) = path.glob("*.mcap")
    data = mcap_file.read_bytes()
    at = int(where * (len(data) - 200))
    mcap_file.write_bytes(data[:at] + b"\x13" * 200 + data[at + 200:])
    try:
        out = bag.read_bag(path)
    except bag.BagError as err:
        assert mcap_file.name in str(err)
    else:
        assert where > 0.9, "corrupt message data must not read silently"
        for topic, s in recording.items():
            assert_same(out[topic], s)


def test_truncated_or_incomplete_bag_error_names_the_file(
        tmp_path: Path, recording: dict[str, Series]) -> None:
    path = bag.write_bag(tmp_path / "run", recording)
    (mcap_file,) = path.glob("*.mcap")
    mcap_file.write_bytes(mcap_file.read_bytes()[:5000])
    with pytest.raises(bag.BagError, match=mcap_file.name):
        bag.read_bag(path)
    (path / "metadata.yaml").unlink()
    with pytest.raises(bag.BagError, match="metadata"):
        bag.bag_summary(path)
    with pytest.raises(FileNotFoundError, match="nowhere"):
        bag.read_bag(tmp_path / "nowhere")


def test_contract_type_and_stamp_checks(tmp_path: Path, recording: dict[str, Series]) -> None:
    with pytest.raises(ValueError, match="sensor_msgs/msg/Imu"):
        bag.write_bag(tmp_path / "a", {"imu/data": recording["dvl/twist"]})
    neg = recording["pressure"]
    neg.stamp = neg.stamp - 10.0
    with pytest.raises(ValueError, match=">= 0"):
        bag.write_bag(tmp_path / "b", {"pressure": neg})
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


@pytest.mark.parametrize("chunk", [bag.READ_CHUNK, 30])
def test_changing_frame_id_and_foreign_types(chunk: int, tmp_path: Path,
                                             make_series: Callable[..., Series],
                                             typestore: Any,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """A bag recorded elsewhere: frame_id changes halfway (inside a read chunk, or between
    two), a std_msgs/String topic."""
    monkeypatch.setattr(bag, "READ_CHUNK", chunk)
    a = make_series(ImuSeries, 30, frame_id="imu_a")
    b = make_series(ImuSeries, 30, frame_id="imu_b", t0=1.0)
    String = typestore.types["std_msgs/msg/String"]
    path = tmp_path / "foreign"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        imu = w.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=typestore)
        model = w.add_connection("/dampest/model", "std_msgs/msg/String", typestore=typestore)
        w.write(model, 0, bytes(typestore.serialize_cdr(String("x: 1"), "std_msgs/msg/String")))
        for s in (a, b):
            for k, raw in enumerate(cdr.encode(s)):
                w.write(imu, stamp_ns(s, k), raw)
    with pytest.warns(UserWarning, match="frame_id"):
        out = bag.read_bag(path)
    assert list(out) == ["imu/data"]  # the String topic has no series: skipped
    imu_out = out["imu/data"]
    assert isinstance(imu_out, ImuSeries) and imu_out.frame_id == "imu_a"
    np.testing.assert_array_equal(imu_out.linear_acceleration,
                                  np.vstack([a.linear_acceleration, b.linear_acceleration]))
    with pytest.raises(TypeError, match="std_msgs/msg/String"):
        bag.read_bag(path, ["dampest/model"])


def test_bag_summary(tmp_path: Path, recording: dict[str, Series]) -> None:
    path = bag.write_bag(tmp_path / "run", recording, storage="sqlite3")
    summary = bag.bag_summary(path)
    assert summary.storage == "sqlite3"
    assert summary.message_count == sum(len(s) for s in recording.values())
    assert summary.topics["/dvl/twist"] == bag.TopicSummary(
        "/dvl/twist", "geometry_msgs/msg/TwistWithCovarianceStamped", 20)
    first = min(float(s.stamp[0]) for s in recording.values())
    last = max(float(s.stamp[-1]) for s in recording.values())
    assert (summary.start, summary.end) == (first, last)


def test_empty_series_topic(tmp_path: Path) -> None:
    path = bag.write_bag(tmp_path / "e", {"dvl/twist": TwistSeries(np.zeros(0))})
    assert len(bag.read_bag(path)["dvl/twist"]) == 0
    assert bag.bag_summary(path).topics["/dvl/twist"].count == 0


def test_bag_source_windows_equal_fresh_reads_and_each_message_is_read_once(
        tmp_path: Path, recording: dict[str, Series], assert_same: AssertSame,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The frame checks' first window, heads from the start, overlapping stretches and the
    small topics whole and in windows, as identify asks for them: each the messages a fresh
    read gives, and the 560 messages of the four topics read once (2 s of log)."""
    path = bag.write_bag(tmp_path / "run", recording)
    asks = [("imu/data", 0.0, 1.0), ("thrusters/state", 0.0, 1.0), ("dvl/twist", 0.0, 1.0),
            ("pressure", 0.0, 1.0), ("dvl/twist", None, None), ("imu/data", None, 0.3),
            ("pressure", None, None), ("imu/data", -0.2, 0.6), ("thrusters/state", -0.2, 0.6),
            ("imu/data", 0.4, 1.6), ("thrusters/state", 0.4, 1.6), ("imu/data", 1.4, 2.5),
            ("thrusters/state", 1.4, 2.5)]
    fresh = [bag.read_bag(path, [t], start=a, stop=b)[t] for t, a, b in asks]
    read: list[int] = []
    real = bag._read

    def counted(*args: Any) -> dict[str, bag.Logged]:
        out = real(*args)
        read.append(sum(len(x.log_ns) for x in out.values()))
        return out

    monkeypatch.setattr(bag, "_read", counted)
    with bag.BagSource(path, together=["imu/data", "thrusters/state"],
                       whole=["/dvl/twist", "pressure"]) as src:
        for (topic, a, b), want in zip(asks, fresh, strict=True):
            assert_same(src.series(topic, a, b), want)
    assert len(fresh[-2]) == 120 and len(fresh[2]) == 10  # 200 Hz over [1.4, 2.0); 10 Hz
    assert sum(read) == 400 + 100 + 20 + 40


def test_read_bag_reports_progress_to_the_end(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                              recording: dict[str, Series]) -> None:
    bag.write_bag(tmp_path / "b", recording)
    monkeypatch.setattr(bag, "READ_CHUNK", 7)
    calls: list[tuple[int, int]] = []
    bag.read_bag(tmp_path / "b", progress=lambda done, total: calls.append((done, total)))
    total = sum(len(s) for s in recording.values())
    assert calls[-1] == (total, total)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)
    assert len(calls) > 2


# --- ROS 1 bags ------------------------------------------------------------------------------


def write_ros1(path: Path, recording: dict[str, Series], typestore: Any, to_ros: ToRos,
               compression: str = "none") -> Path:
    """``recording`` as a ROS 1 bag written by rosbags alone: each message built by the test
    conftest's reference conversion, serialised by rosbags' ROS 1 Noetic typestore with its
    header seq counting up as a ROS 1 publisher's does; log time = header stamp."""
    noetic = get_typestore(Stores.ROS1_NOETIC)
    writer = Ros1Writer(path)
    if compression != "none":
        writer.set_compression(Ros1Writer.CompressionFormat[compression.upper()])
    with writer:
        for topic, s in recording.items():
            msgtype = cdr.message_type(s)
            conn = writer.add_connection("/" + topic, msgtype, typestore=noetic)
            for i in range(len(s)):
                ros2 = typestore.serialize_cdr(to_ros(s, i), msgtype)
                msg = noetic.deserialize_ros1(typestore.cdr_to_ros1(ros2, msgtype), msgtype)
                msg.header.seq = i
                writer.write(conn, stamp_ns(s, i), bytes(noetic.serialize_ros1(msg, msgtype)))
    return path


@pytest.mark.parametrize("compression", ["none", "lz4", "bz2"])
def test_ros1_bag_reads_exactly_like_the_rosbag2_bag(
        compression: str, tmp_path: Path, recording: dict[str, Series], typestore: Any,
        to_ros: ToRos, assert_same: AssertSame, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every series bit for bit, whole and in read chunks that do not divide the counts;
    the summary and BagSource's windows as for the rosbag2 bag of the same messages."""
    ros1 = write_ros1(tmp_path / "run.bag", recording, typestore, to_ros, compression)
    ros2 = bag.write_bag(tmp_path / "run", recording)
    assert bag.is_bag(ros1) and bag.is_bag(ros2) and not bag.is_bag(tmp_path / "x.csv")
    out = bag.read_bag(ros1)
    assert out.keys() == recording.keys()
    for topic, s in recording.items():
        assert_same(out[topic], s)
    monkeypatch.setattr(bag, "READ_CHUNK", 7)
    out = bag.read_bag(ros1, ["/imu/data", "thrusters/state"])
    assert_same(out["/imu/data"], recording["imu/data"])
    assert_same(out["thrusters/state"], recording["thrusters/state"])
    a, b = bag.bag_summary(ros1), bag.bag_summary(ros2)
    assert (a.storage, b.storage) == ("ros1", "mcap")
    assert (a.topics, a.start, a.end) == (b.topics, b.start, b.end)
    assert a.topics["/imu/data"] == bag.TopicSummary("/imu/data", "sensor_msgs/msg/Imu", 400)
    window = bag.BagSource(ros1, together=["imu/data"]).series("/imu/data", 0.5, 1.25)
    assert len(window) == 150  # 200 Hz, [0.5, 1.25) s
    assert_same(window, bag.BagSource(ros2).series("imu/data", 0.5, 1.25))


@pytest.mark.parametrize("keep", [0.0, 0.1, 0.5, 0.9, 0.999])
def test_truncated_ros1_bag_error_names_the_file(keep: float, tmp_path: Path,
                                                 recording: dict[str, Series], typestore: Any,
                                                 to_ros: ToRos) -> None:
    """A ROS 1 bag cut short (its index is at the end), or not a bag at all: BagError
    naming the file and the cause, whether the summary or the messages are asked for."""
    path = write_ros1(tmp_path / "run.bag", recording, typestore, to_ros)
    data = path.read_bytes()
    path.write_bytes(data[:int(keep * len(data))] if keep else b"not a bag\n")
    for read in (bag.bag_summary, bag.read_bag):
        with pytest.raises(bag.BagError, match=r"cannot read bag .*run\.bag: .*ROS 1") as err:
            read(path)
        assert "\n" not in str(err.value)
