"""Bags that cannot feed identification or replay: one line naming the input and the fix,
exit 2."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from dampest_ros.cli.main import main
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
