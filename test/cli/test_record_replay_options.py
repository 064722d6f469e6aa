"""dampest record and dampest replay take ros2 bag's option names where they mean the same,
and turn them into the nodes' parameters (no ROS needed here: the nodes' own tests are in
test/ros)."""

from __future__ import annotations

import pytest

from dampest_ros.cli.main import build_parser, main
from dampest_ros.cli.record import ros_arguments
from dampest_ros.cli.replay import node_parameters


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
