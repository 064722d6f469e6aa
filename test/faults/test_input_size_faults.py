"""Files size-checked before they are read: a CSV log over the limit is refused with one line
naming its size, the limit and what to do (was: read until 8–16 GB of memory for 2 GB)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from dampest_ros.cli.main import main


def sparse_csv(path: Path, mb: float) -> Path:
    """A CSV log with a header, one row and a hole up to ``mb`` MB."""
    path.write_text("time,u,v,w,p,q,r\n0,0,0,0,0,0,0\n")
    os.truncate(path, int(mb * 1e6))
    return path


def test_a_csv_over_the_size_limit_is_refused_before_it_is_read(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DAMPEST_MAX_CSV_MB", "2")
    big = sparse_csv(tmp_path / "big.csv", 3.0)
    assert main(["identify", str(big), "--vehicle", "bluerov2_heavy"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"dampest identify: error: {big}: 3 MB, over the 2 MB limit for a CSV log "
                   "(reading takes several times its size in memory); split it into shorter "
                   "logs, or convert it to a bag, or raise the limit with DAMPEST_MAX_CSV_MB=N "
                   "if the memory is there")


def test_a_first_line_without_end_is_not_read_whole(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A file of zeros (a preallocated log never written): its 'header' was read whole."""
    blank = tmp_path / "blank.csv"
    blank.touch()
    os.truncate(blank, 500_000)
    assert main(["inspect", str(blank)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"dampest inspect: error: {blank}: the first line is over 65536 characters: "
                   "not a CSV header (a binary file, or one without line ends?)")
