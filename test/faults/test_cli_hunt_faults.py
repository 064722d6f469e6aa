"""Command-line faults found by trying the commands as a user would: each ends in one line
naming the option or file and the fix, exit status 2, and nothing half-written."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import pytest

import dampest_ros.cli.inspect as inspect_cli
from dampest_ros.cli.main import main

V = ["--vehicle", "bluerov2_heavy"]


def one_line(capsys: pytest.CaptureFixture[str], argv: list[str], *wanted: str) -> str:
    """Run ``argv``: exit status 2 and one line on stderr holding each of ``wanted``."""
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unexpected" not in err, err
    assert all(w in err for w in wanted), err
    return err


@pytest.fixture(scope="module")
def model(sim_bag: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("model") / "model.yaml"
    assert main(["identify", str(sim_bag), *V, "--out", str(out)]) == 0
    return out


def test_validate_infinite_free_run(sim_bag: Path, model: Path,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    one_line(capsys, ["validate", str(model), str(sim_bag), *V, "--free-run", "inf"],
             "--free-run: must be a finite number of seconds > 0, got inf")


def test_simulate_nan_amplitude(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    one_line(capsys, ["simulate", "--duration", "5", "--amplitude", "nan", "--out",
                      str(tmp_path / "b")], "--amplitude: must be a finite scale > 0")
    assert not (tmp_path / "b").exists()


def test_arm_simulate_zero_rate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    one_line(capsys, ["arm", "simulate", "--random", "1", "--duration", "2", "--rate", "0",
                      "--out", str(tmp_path / "b")], "--rate must be 1000 Hz divided by")


def test_a_bag_given_as_the_model(sim_bag: Path, capsys: pytest.CaptureFixture[str]) -> None:
    one_line(capsys, ["validate", str(sim_bag), str(sim_bag), *V],
             f"{sim_bag}: is a directory, not a model file")


def test_a_binary_vehicle_file(sim_bag: Path, tmp_path: Path,
                               capsys: pytest.CaptureFixture[str]) -> None:
    vehicle = tmp_path / "auv.yaml"
    vehicle.write_bytes(bytes(range(128, 256)))
    one_line(capsys, ["identify", str(sim_bag), "--vehicle", str(vehicle)],
             f"{vehicle}: not a text file", "expected a vehicle YAML file")


@pytest.mark.parametrize("kind", ["binary", "directory"])
def test_import_of_a_binary_file_or_a_directory(
        sim_bag: Path, tmp_path: Path, kind: str, capsys: pytest.CaptureFixture[str]) -> None:
    source = next(sim_bag.glob("*.mcap")) if kind == "binary" else sim_bag
    one_line(capsys, ["import", str(source), "--format", "gz", "--out",
                      str(tmp_path / "m.yaml")],
             f"{source}: not valid XML" if kind == "binary" else f"{source} is a directory")


def test_simulate_csv_into_a_directory_writes_no_bag(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    one_line(capsys, ["simulate", "--duration", "30", "--out", str(tmp_path / "b"), "--csv",
                      str(tmp_path)], f"--csv {tmp_path}: is a directory")
    assert not (tmp_path / "b").exists()


def test_validate_out_under_a_file(sim_bag: Path, model: Path, tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "afile").write_text("")
    one_line(capsys, ["validate", str(model), str(sim_bag), *V, "--out",
                      str(tmp_path / "afile" / "f.csv")], "afile is a file, not a directory")


@pytest.mark.parametrize("command", ["identify", "gap"])
def test_negative_max_gap_names_the_option(sim_bag: Path, model: Path, command: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    argv = ([command, str(sim_bag), *V] if command == "identify"
            else [command, str(sim_bag), "--model", str(model), *V])
    one_line(capsys, [*argv, "--max-gap", "-1"], "--max-gap: -1 s: must be ≥ 0")


def test_an_error_without_a_message_is_named(monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    def run(args: argparse.Namespace) -> int:
        raise TimeoutError

    monkeypatch.setattr(inspect_cli, "run", run)
    capsys.readouterr()
    assert main(["inspect", "x"]) == 2
    assert "error: unexpected TimeoutError" in capsys.readouterr().err


def test_columns_given_for_a_bag_is_refused(sim_bag: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """Was: --columns, which renames a CSV's columns, ignored without a word for a bag."""
    line = one_line(capsys, ["identify", str(sim_bag), "--vehicle", "bluerov2_heavy",
                             "--columns", "map.yaml"], "--columns: renames the columns of a CSV "
                                                       "log;", "is a bag")
    assert "--imu-topic" in line


def test_output_cut_short_by_the_reader_ends_quietly(sim_bag: Path, children: Any) -> None:
    """Was: 'dampest inspect BAG | head -1' ended with 'error: [Errno 32] Broken pipe',
    exit 2. Now quiet, status 141 (128 + SIGPIPE) as shells expect."""
    import subprocess
    import sys

    proc = children.start([sys.executable, "-m", "dampest_ros.cli.main", "inspect",
                           str(sim_bag)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # the reader goes away before the first line (head -0)
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) in (0, 141), err
    assert "Broken pipe" not in err and "error" not in err, err
