"""dampest record and dampest replay take ros2 bag's option names where they mean the same,
and turn them into the nodes' parameters (no ROS needed here: the nodes' own tests are in
test/ros)."""

from __future__ import annotations

from pathlib import Path

import pytest

from dampest_ros.cli.main import build_parser, main
from dampest_ros.cli.record import node_parameters as node_parameters_of_record
from dampest_ros.cli.record import ros_arguments
from dampest_ros.cli.replay import check_storage, node_parameters

SAMPLE = Path(__file__).resolve().parents[2] / "bags" / "sample"


def test_replay_clock_defaults_to_40_hz_and_acked_is_in_milliseconds() -> None:
    parse = build_parser().parse_args
    assert node_parameters(parse(["replay", "b"]))["wait_for_acked"] == 5.0
    params = node_parameters(parse(["replay", "b", "--clock", "--wait-for-all-acked", "250",
                                    "--exclude-topics", "dampest/model", "diagnostics"]))
    assert params["clock"] and params["clock_rate"] == 40.0
    assert params["wait_for_acked"] == 0.25
    assert params["exclude_topics"] == ["dampest/model", "diagnostics"]
    assert node_parameters(parse(["replay", "b", "--clock", "200"]))["clock_rate"] == 200.0
    assert node_parameters(parse(["replay", "b", "--wait-for-all-acked", "-1"]))[
        "wait_for_acked"] == 0.0  # do not wait
    assert node_parameters(parse(["replay", "b", "--wait-for-all-acked", "0"]))[
        "wait_for_acked"] == 3600.0  # until acknowledged, at most the node's hour


def test_replay_acked_below_minus_one_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", "b", "--wait-for-all-acked", "-5"]) == 2
    assert capsys.readouterr().err.startswith(
        "dampest replay: error: --wait-for-all-acked: -5 ms: must be -1")


def test_record_exclude_regex_reaches_the_node() -> None:
    args = build_parser().parse_args(["record", "-o", "t", "--all", "-x", "^/truth/"])
    argv = ros_arguments(args)
    assert 'exclude_regex:="^/truth/"' in argv and 'topics:=["all"]' in argv


@pytest.mark.parametrize("options", [["--compression-mode", "file"],
                                     ["--compression-mode", "message",
                                      "--compression-format", "zstd"],
                                     ["--compression-format", "zstd"]])
def test_record_rosbag2_compression_is_refused_with_the_chunk_compression(
        options: list[str], tmp_path: object, capsys: pytest.CaptureFixture[str]) -> None:
    """rosbag2's file/message compression is not written; the one line names
    --compression zstd, before any node starts."""
    assert main(["record", "-o", f"{tmp_path}/bag", *options]) == 2
    err = capsys.readouterr().err
    assert "--compression zstd compresses the MCAP chunks" in err and err.count("\n") == 1


def test_record_regex_reaches_the_node_alone_or_with_topics() -> None:
    """-e REGEX alone records only what it matches (no default topics); with topics, both."""
    parse = build_parser().parse_args
    alone = node_parameters_of_record(parse(["record", "-o", "t", "-e", "^/(imu|dvl)/"]))
    assert alone["regex"] == "^/(imu|dvl)/" and alone["topics"] == [""]
    both = node_parameters_of_record(parse(["record", "-o", "t", "--regex", "^/dvl/",
                                            "pressure"]))
    assert both["regex"] == "^/dvl/" and both["topics"] == ["pressure"]
    assert "topics" not in node_parameters_of_record(parse(["record", "-o", "t"]))


@pytest.mark.parametrize("argv, says", [
    (["-s", "sqlite3"], "-s/--storage sqlite3: dampest record writes MCAP only"),
    (["--storage", "nosuch"], "-s/--storage nosuch: dampest record writes MCAP only"),
    (["--all", "-e", "imu"], "give topics (or -e/--regex) or --all, not both"),
])
def test_record_refuses_other_storages_and_all_with_a_regex_in_one_line(
        argv: list[str], says: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["record", "-o", str(tmp_path / "bag"), *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"dampest record: error: {says}") and err.count("\n") == 1, err
    assert not (tmp_path / "bag").exists()


def test_record_storage_mcap_is_the_default_and_accepted() -> None:
    parse = build_parser().parse_args
    assert parse(["record", "-s", "mcap"]).storage == parse(["record"]).storage == "mcap"


def test_record_bad_regex_names_the_option(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("rclpy")
    assert main(["record", "-o", str(tmp_path / "bag"), "-e", "imu(("]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dampest record: error: -e/--regex: not a regular expression: ")
    assert err.count("\n") == 1, err


def test_replay_storage_is_checked_against_the_bag(capsys: pytest.CaptureFixture[str]
                                                   ) -> None:
    pytest.importorskip("rclpy")
    parse = build_parser().parse_args
    check_storage(parse(["replay", str(SAMPLE), "-s", "mcap"]))  # what it is: accepted
    check_storage(parse(["replay", str(SAMPLE)]))                # detected
    assert main(["replay", str(SAMPLE), "--storage", "sqlite3"]) == 2
    err = capsys.readouterr().err
    assert err == (f"dampest replay: error: -s/--storage sqlite3: {SAMPLE} is stored as mcap; "
                   "give -s mcap, or drop -s (the storage is detected)\n")
    with pytest.raises(SystemExit) as exc:  # not a storage replay reads: argparse's line
        parse(["replay", str(SAMPLE), "-s", "ros1"])
    assert exc.value.code == 2
    assert "argument -s/--storage: invalid choice: 'ros1'" in capsys.readouterr().err
