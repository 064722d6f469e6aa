"""Bags that cannot feed identification or replay: one line naming the input and the fix,
exit 2."""

from __future__ import annotations

import shutil
import struct
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap.records import ChunkIndex

from dampest_ros.cli.main import main
from dampest_ros.io.bag import read_bag
from dampest_ros.io.recorder import BagRecorder

IMU, DVL = "sensor_msgs/msg/Imu", "geometry_msgs/msg/TwistWithCovarianceStamped"
STRING = "std_msgs/msg/String"


def error_line(capsys: pytest.CaptureFixture[str]) -> str:
    """The one line a refused command prints on stderr."""
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return err


@pytest.fixture
def string_bag(sim_bag: Path, tmp_path: Path, rebag: Callable[..., Path]) -> Path:
    """The simulated bag with std_msgs/String on imu/data."""
    return rebag(sim_bag, tmp_path / "strings", strings=("/imu/data",))


@pytest.fixture
def swapped_bag(sim_bag: Path, tmp_path: Path, rebag: Callable[..., Path]) -> Path:
    """The simulated bag with the IMU and DVL topic names swapped (types follow the data)."""
    return rebag(sim_bag, tmp_path / "swapped",
                 rename={"/imu/data": "/dvl/twist", "/dvl/twist": "/imu/data"})


@pytest.mark.parametrize("command", [["identify"], ["identify", "--method", "rls"],
                                     ["gap", "--model", "MODEL"]])
def test_wrong_type_on_a_role_names_topic_types_and_option(
        command: list[str], string_bag: Path, sim_bag: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    argv = [a.replace("MODEL", str(sim_bag / "truth_model.yaml")) for a in command]
    assert main([argv[0], str(string_bag), "--vehicle", "bluerov2_heavy", *argv[1:]]) == 2
    assert error_line(capsys) == (
        f"dampest {argv[0]}: error: bag {string_bag}: topic imu/data (imu) carries {STRING}, "
        f"not the {IMU} identification needs; give the imu topic with --imu-topic TOPIC")


def test_swapped_imu_and_dvl_refused_with_the_options_that_fix_it(
        swapped_bag: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["identify", str(swapped_bag), "--vehicle", "bluerov2_heavy"]) == 2
    assert error_line(capsys) == (
        f"dampest identify: error: bag {swapped_bag}: "
        f"topic imu/data (imu) carries {DVL}, not the {IMU} identification needs; "
        "give the imu topic with --imu-topic dvl/twist; "
        f"topic dvl/twist (dvl) carries {IMU}, not the {DVL} identification needs; "
        "give the dvl topic with --dvl-topic imu/data")


def test_inspect_checks_types_against_identification(
        string_bag: Path, swapped_bag: Path, sim_bag: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(sim_bag)]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == (
        "ready for identification: IMU, DVL and thruster topics present")
    assert main(["inspect", str(string_bag)]) == 1
    assert capsys.readouterr().out.splitlines()[-1] == (
        f"not ready for identification: topic imu/data (imu) carries {STRING}, not the {IMU} "
        "identification needs; give the imu topic with --imu-topic TOPIC")
    assert main(["inspect", str(swapped_bag)]) == 1
    last = capsys.readouterr().out.splitlines()[-1]
    assert last.startswith("not ready for identification: topic imu/data (imu) carries")
    assert "--imu-topic dvl/twist" in last and "--dvl-topic imu/data" in last
    # ... and the swapped topics named as the options say make it ready
    assert main(["inspect", str(swapped_bag), "--imu-topic", "dvl/twist",
                 "--dvl-topic", "imu/data"]) == 0
    assert "ready for identification" in capsys.readouterr().out


def test_inspect_of_a_bag_without_readable_topics(
        tmp_path: Path, string_cdr: Callable[[str], bytes],
        capsys: pytest.CaptureFixture[str]) -> None:
    """Was a KeyError traceback: rosbags reads every topic for an empty selection."""
    with BagRecorder(tmp_path / "strings_only") as rec:
        conn = rec.add_connection("/imu/data", STRING)
        rec.write(conn, 1_000_000_000, string_cdr("hello"))
    assert main(["inspect", str(tmp_path / "strings_only")]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"{tmp_path / 'strings_only'} (mcap): 1 messages, 0.0 s from t=1.000"
    assert out[-1] == (
        "not ready for identification: missing ['dvl/twist', 'thrusters/state'] (use "
        "--imu-topic etc. with dampest identify if they have other names, --wrench-topic if τ "
        f"is logged as a body wrench); topic imu/data (imu) carries {STRING}, not the {IMU} "
        "identification needs; give the imu topic with --imu-topic TOPIC")


def test_replay_of_a_truncated_bag_gives_the_reindex_hint(
        sim_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "cut"
    bag.mkdir()
    for f in sim_bag.iterdir():
        data = f.read_bytes()
        (bag / f.name).write_bytes(data[:len(data) // 2] if f.suffix == ".mcap" else data)
    assert main(["replay", str(bag)]) == 2
    line = error_line(capsys)
    assert line.startswith(f"dampest replay: error: BAG: cannot read bag {bag} (")
    assert line.endswith(f"if its recording was interrupted, 'dampest reindex {bag}' "
                         "rebuilds metadata.yaml and recovers it up to its last complete chunk")


@pytest.mark.parametrize("rate", ["0", "-1", "nan"])
def test_replay_rate_out_of_range(rate: str, sim_bag: Path,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(sim_bag), "--rate", rate]) == 2
    reason = ("must be finite" if rate == "nan"
              else "must be in [0.01, 1000.0]")
    assert error_line(capsys) == (
        f"dampest replay: error: --rate: rate {reason}, got {float(rate)!r}")


def damaged(src: Path, dst: Path) -> tuple[Path, bytearray, ChunkIndex]:
    """A copy of bag ``src`` at ``dst``: its storage file, that file's bytes (to damage, then
    write back) and the index of its middle chunk."""
    shutil.copytree(src, dst)
    (mcap,) = dst.glob("*.mcap")
    with mcap.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return mcap, bytearray(mcap.read_bytes()), summary.chunk_indexes[
        len(summary.chunk_indexes) // 2]


def first_message(data: bytearray, chunk: ChunkIndex) -> tuple[int, int]:
    """File offset of the first message record of an uncompressed chunk, and its offset
    among the chunk's records."""
    records = chunk.chunk_start_offset + 9 + 8 + 8 + 8 + 4 + 4 + 8  # no compression name
    pos = records
    while data[pos] != 0x05:
        pos += 9 + struct.unpack_from("<Q", data, pos + 1)[0]
    return pos, pos - records


def reindexed(bag: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, int]:
    """dampest reindex BAG: its exit status, its last line, and the messages read_bag then
    reads from the bag."""
    status = main(["reindex", str(bag)])
    last = capsys.readouterr().out.strip().splitlines()[-1]
    return status, last, sum(len(s) for s in read_bag(bag).values())


def reindex_hint(bag: Path) -> str:
    return (f"'dampest reindex {bag}' rebuilds its index from the intact chunks and reports "
            "what is lost")


@pytest.mark.parametrize("command", [["identify"], ["identify", "--method", "rls"],
                                     ["gap", "--model", "MODEL"]])
def test_a_flipped_record_in_an_unchecked_chunk_ends_the_command(
        command: list[str], sim_bag: Path, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """rosbags writes chunk CRC 0 (not checked): a message record whose opcode was flipped
    was skipped, and identify wrote a model from a bag missing it (exit 0)."""
    bag = tmp_path / "flipped"
    mcap, data, chunk = damaged(sim_bag, bag)
    at, inside = first_message(data, chunk)
    length = struct.unpack_from("<Q", data, at + 1)[0]
    data[at] = 0x07
    mcap.write_bytes(data)
    argv = [a.replace("MODEL", str(sim_bag / "truth_model.yaml")) for a in command]
    assert main([argv[0], str(bag), "--vehicle", "bluerov2_heavy", *argv[1:]]) == 2
    assert error_line(capsys) == (
        f"dampest {argv[0]}: error: cannot read bag {bag} (metadata.yaml, sim.mcap, "
        f"truth_model.yaml): a damaged storage file (sim.mcap, chunk at byte "
        f"{chunk.chunk_start_offset} (log time {chunk.message_start_time / 1e9:.3f} s, 2637 "
        f"messages unreadable): a damaged record at byte {inside} (opcode 0x07, length "
        f"{length})); {reindex_hint(bag)}")
    # reindex drops the one unreadable message and says so
    assert reindexed(bag, capsys) == (1, (
        f"wrote {bag / 'metadata.yaml'}: 9844 messages; unreadable: 1 messages counted by the "
        "indexes, 0 bytes"), 9844)


def test_replay_stops_at_a_flipped_record_in_an_unchecked_chunk(
        sim_bag: Path, tmp_path: Path) -> None:
    """Was: replay_node read through rosbags alone, which skips a record of an unknown opcode
    in a chunk without CRC: the bag played "whole" without the message, exit 0."""
    import os
    import subprocess
    import sys

    bag = tmp_path / "flipped"
    mcap, data, chunk = damaged(sim_bag, bag)
    at, inside = first_message(data, chunk)
    data[at] = 0x07
    mcap.write_bytes(data)
    env = {**os.environ, "ROS_DOMAIN_ID": "92", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    run = subprocess.run([sys.executable, "-m", "dampest_ros.cli.main", "replay", str(bag),
                          "--rate", "50", "--wait-for-subscribers", "0"], env=env,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 1, run.stderr
    assert (f"a damaged record at byte {inside} (opcode 0x07" in run.stderr
            and reindex_hint(bag) in run.stderr), run.stderr
    assert "Traceback" not in run.stderr


def test_replay_of_a_ros1_bag_says_how_to_play_it(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """Was: a traceback from rosbags' rosbag2 reader (the node's error handling re-raised it)."""
    from rosbags.rosbag1 import Writer as Ros1Writer

    path = tmp_path / "run.bag"
    with Ros1Writer(path) as w:
        w.add_connection("/imu/data", IMU)
    assert main(["replay", str(path)]) == 2
    line = error_line(capsys)
    assert "is a ROS 1 bag: replay plays rosbag2 bags" in line, line


def test_a_message_that_does_not_deserialise_is_named_and_dropped_by_reindex(
        sim_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """CDR garbage (an encapsulation kind of 7) in a chunk without CRC: identify said only
    'cannot decode', and reindex called the bag complete (exit 0) although reading it still
    failed."""
    bag = tmp_path / "garbage"
    mcap, data, chunk = damaged(sim_bag, bag)
    at, _ = first_message(data, chunk)
    data[at + 9 + 22 + 1] = 7
    mcap.write_bytes(data)
    assert main(["identify", str(bag), "--vehicle", "bluerov2_heavy"]) == 2
    line = error_line(capsys)
    assert ("a damaged storage file (1 of 5000 messages of /imu/data logged from 0.000 s to "
            "24.995 s do not deserialise as sensor_msgs/msg/Imu, the first at log time "
            f"{chunk.message_start_time / 1e9:.3f} s: SerdeError: ") in line
    assert line.endswith(reindex_hint(bag))
    assert reindexed(bag, capsys) == (1, (
        f"wrote {bag / 'metadata.yaml'}: 9844 messages; unreadable: 1 messages counted by the "
        "indexes, 0 bytes"), 9844)


def damage_summary(data: bytearray, chunk: ChunkIndex, kind: str) -> None:
    """Shift the chunk index of ``chunk`` by 10 s, or count 5 messages fewer for the first
    channel in the statistics."""
    (pos,) = struct.unpack_from("<Q", data, len(data) - 8 - 4 - 8 - 8)  # summary start
    while True:
        op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
        body = pos + 9
        if kind == "chunk index" and op == 0x08 and struct.unpack_from(
                "<Q", data, body + 16)[0] == chunk.chunk_start_offset:
            struct.pack_into("<QQ", data, body, chunk.message_start_time + 10**10,
                             chunk.message_end_time + 10**10)
            return
        if kind == "statistics" and op == 0x0B:
            cid, count = struct.unpack_from("<HQ", data, body + 46)
            struct.pack_into("<HQ", data, body + 46, cid, count - 5)
            return
        pos = body + length


@pytest.mark.parametrize("kind", ["chunk index", "statistics"])
def test_a_damaged_summary_is_refused_and_reindex_repairs_it(
        kind: str, sim_bag: Path, tmp_path: Path, rebag: Callable[..., Path],
        capsys: pytest.CaptureFixture[str]) -> None:
    """Our recorder's bag (chunk CRCs) with a damaged summary: identify used what the index
    showed (exit 0), and reindex called the file complete (exit 0) while read_bag still
    failed."""
    bag = tmp_path / "summary"
    mcap, data, chunk = damaged(rebag(sim_bag, tmp_path / "recorded"), bag)
    damage_summary(data, chunk, kind)
    mcap.write_bytes(data)
    assert main(["identify", str(bag), "--vehicle", "bluerov2_heavy"]) == 2
    line = error_line(capsys)
    assert line.startswith(f"dampest identify: error: cannot read bag {bag} (metadata.yaml, "
                           f"{mcap.name}): a damaged storage file ({mcap.name}")
    assert line.endswith(reindex_hint(bag))
    what = ("the chunk record and its index disagree" if kind == "chunk index" else
            "its summary is inconsistent: its 15 chunk indexes (its statistics 15) count "
            "/truth/odom 1501 (its statistics 1496)")
    assert what in line
    assert reindexed(bag, capsys) == (0, (
        f"wrote {bag / 'metadata.yaml'}: 9845 messages; unreadable: 0 messages counted by the "
        "indexes, 0 bytes"), 9845)


def test_metadata_counts_that_disagree_with_the_storage(
        sim_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A metadata.yaml counting 7 messages fewer: identify did not notice."""
    bag = tmp_path / "counts"
    shutil.copytree(sim_bag, bag)
    info = yaml.safe_load((bag / "metadata.yaml").read_text())
    topics = info["rosbag2_bagfile_information"]["topics_with_message_count"]
    topics[0]["message_count"] -= 7
    (bag / "metadata.yaml").write_text(yaml.safe_dump(info))
    assert main(["identify", str(bag), "--vehicle", "bluerov2_heavy"]) == 2
    assert error_line(capsys) == (
        f"dampest identify: error: cannot read bag {bag} (metadata.yaml, sim.mcap, "
        "truth_model.yaml): metadata.yaml counts other messages than its storage files: "
        f"/truth/odom 1494 (the storage holds 1501); 'dampest reindex {bag}' rebuilds "
        "metadata.yaml from the storage files")
    assert reindexed(bag, capsys)[::2] == (0, 9845)
