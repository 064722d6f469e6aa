"""Malformed --ros-args: one logged line naming the argument and how to write it, exit
status 2, for every node (rcl refused them before the node's error handling, with a
traceback of RCLInvalidROSArgsError and status 1)."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

pytest.importorskip("rclpy")

NODES = ("sim_node", "preprocess_node", "estimator_node", "arm_estimator_node",
         "model_server_node", "controller_node", "arm_feedforward_node", "recorder_node",
         "replay_node")


def refusal(node: str, args: list[str], capfd: pytest.CaptureFixture[str]) -> str:
    """Run ``node`` with ``--ros-args args``; the one line it logs (status 2 asserted)."""
    main = importlib.import_module(f"dampest_ros.ros.{node}").main
    with pytest.raises(SystemExit) as done:
        main([node, "--ros-args", *args])
    assert done.value.code == 2
    # rcl's complaint about the rosout publisher of a node an earlier test of this process
    # made under the same name (its context is gone) is not the node's output
    lines = [x for x in capfd.readouterr().err.splitlines()
             if x.strip() and not x.startswith("Failed to publish log message to rosout")]
    assert len(lines) == 1, lines
    m = re.fullmatch(rf"\[ERROR\] \[[0-9.]+\] \[{node}\]: cannot start: invalid ROS argument: "
                     r"(.*)", lines[0])
    assert m is not None and "/project/src" not in lines[0], lines[0]
    return m.group(1)


@pytest.mark.parametrize("node", NODES)
def test_a_trailing_p_is_refused_by_every_node(node: str,
                                              capfd: pytest.CaptureFixture[str]) -> None:
    assert refusal(node, ["-p"], capfd) == ("Couldn't parse trailing -p flag. No parameter "
                                            "override rule found; write -p NAME:=VALUE")


def test_an_empty_parameter_value(capfd: pytest.CaptureFixture[str]) -> None:
    assert refusal("estimator_node", ["-p", "x:="], capfd).startswith(
        "Couldn't parse parameter override rule: '-p x:='; write -p NAME:=VALUE with a YAML "
        "value")


def test_a_bad_remap(capfd: pytest.CaptureFixture[str]) -> None:
    assert refusal("arm_estimator_node", ["-r", "a"], capfd) == (
        "Couldn't parse remap rule: '-r a'; write -r FROM:=TO, e.g. "
        "-r joint_states:=/arm/joint_states or -r __ns:=/vehicle")


def test_a_missing_params_file(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nope.yaml"
    assert refusal("sim_node", ["--params-file", str(missing)], capfd) == (
        f"Couldn't parse params file: '--params-file {missing}'. Error: Error opening YAML "
        "file; give an existing ROS 2 parameters file (/**: ros__parameters: NAME: VALUE; "
        "every parameter with its default: config/sim_node.params.yaml)")


def test_a_broken_params_file_names_its_line(tmp_path: Path,
                                             capfd: pytest.CaptureFixture[str]) -> None:
    broken = tmp_path / "p.yaml"
    broken.write_text("/**:\n  ros__parameters:\n    rate: {a: }\n")
    assert refusal("replay_node", ["--params-file", str(broken)], capfd).startswith(
        f"Couldn't parse params file: '--params-file {broken}'. Error: No value at line 3; "
        "give an existing ROS 2 parameters file")


def test_a_params_file_flag_without_a_file(capfd: pytest.CaptureFixture[str]) -> None:
    assert refusal("controller_node", ["--params-file"], capfd) == (
        "Couldn't parse trailing --params-file flag. No file path provided; write "
        "--params-file FILE")


def test_a_bad_log_level(capfd: pytest.CaptureFixture[str]) -> None:
    assert refusal("model_server_node", ["--log-level", "loud"], capfd).endswith(
        "write --log-level LEVEL (debug, info, warn, error or fatal) or --log-level "
        "NAME:=LEVEL")
