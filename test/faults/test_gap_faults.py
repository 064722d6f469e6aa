"""dampest gap on logs that hold nothing to compare: one line, exit 2 (was: an all-zero log
analysed as if it were data, a 1e308 cell ending in 'free run failed' and exit 0)."""

from __future__ import annotations

from pathlib import Path

import pytest

from dampest_ros.cli.main import main


@pytest.fixture(scope="module")
def csv_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """20 s of the BlueROV2 Heavy as a CSV log, and its damping as a model file (the
    simulator's truth, which carries the vehicle's identity)."""
    d = tmp_path_factory.mktemp("gap")
    assert main(["simulate", "--vehicle", "bluerov2_heavy", "--protocol", "B", "--duration",
                 "20", "--seed", "1", "--csv", str(d / "log.csv"), "--out", str(d / "bag")]) == 0
    return d / "log.csv", d / "bag" / "truth_model.yaml"


def edited(src: Path, dst: Path, edit: str) -> Path:
    """``src`` with every cell but time 0 (``edit='zero'``), or u of data row 500 1e308."""
    header, *rows = src.read_text().splitlines()
    u = header.split(",").index("u")
    out = [header]
    for k, row in enumerate(rows):
        cells = row.split(",")
        if edit == "zero":
            cells = [cells[0]] + ["0"] * (len(cells) - 1)
        elif k == 500:
            cells[u] = "1e308"
        out.append(",".join(cells))
    dst.write_text("\n".join(out) + "\n")
    return dst


def gap_error(log: Path, model: Path, capsys: pytest.CaptureFixture[str]) -> str:
    capsys.readouterr()
    assert main(["gap", str(log), "--model", str(model), "--vehicle", "bluerov2_heavy"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


def test_gap_refuses_an_all_zero_log(csv_log: tuple[Path, Path], tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    log = edited(csv_log[0], tmp_path / "zero.csv", "zero")
    assert gap_error(log, csv_log[1], capsys) == (
        f"dampest gap: error: {log}: velocity ν is constant over the whole log ([0.0, 0.0, "
        "0.0, 0.0, 0.0, 0.0]): nothing moved, or the columns or topics were never filled")


def test_gap_refuses_a_log_with_a_1e308_cell(csv_log: tuple[Path, Path], tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    log = edited(csv_log[0], tmp_path / "huge.csv", "huge")
    assert gap_error(log, csv_log[1], capsys) == (
        f"dampest gap: error: {log}: velocity ν u is 1e+308 at t = 12.03 s (1 samples not "
        "finite or over 1000): a damaged cell in the log? fix or drop those rows")
