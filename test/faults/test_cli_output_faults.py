"""Outputs the command line cannot write, binary model files, more workers than logs and
logs in memory: one line naming what the user gave and the fix, exit status 2, nothing
half-written."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

import dampest_ros.cli.pool as pool
from dampest_ros.cli.main import main

V = ["--vehicle", "bluerov2_heavy"]


@pytest.fixture(scope="module")
def model(sim_bag: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("model") / "model.yaml"
    assert main(["identify", str(sim_bag), *V, "--out", str(out)]) == 0
    return out


def commands(bag: Path, model: Path, option: str, path: str) -> list[list[str]]:
    """Every command that writes a file with ``option``, writing it to ``path``."""
    table = {"--out": [["identify", str(bag), *V], ["validate", str(model), str(bag), *V],
                       ["gap", str(bag), "--model", str(model), *V],
                       ["export", str(model), "--format", "urdf", "--force"],
                       ["import", str(model), "--format", "urdf"],
                       ["arm", "design", "--iterations", "0"]],
             "--csv": [["simulate", "--duration", "30", "--out", str(Path(path).parent / "b")]],
             "--drift-plot": [["identify", str(bag), str(bag), *V]]}
    return [[*c, option, path] for c in table[option]]


@pytest.mark.parametrize("option", ["--out", "--csv", "--drift-plot"])
@pytest.mark.parametrize("where", ["directory", "missing"])
def test_an_unwritable_output_file_is_named_with_the_fix(
        sim_bag: Path, model: Path, tmp_path: Path, option: str, where: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "exists" if where == "directory" else tmp_path / "missing" / "f.yaml"
    (tmp_path / "exists").mkdir()
    for argv in commands(sim_bag, model, option, str(target)):
        capsys.readouterr()
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"{option} {target}: " in err, (argv, err)
        assert ".tmp" not in err and ("mkdir -p" in err if where == "missing"
                                      else "is a directory" in err), err
        assert sorted(p.name for p in tmp_path.rglob("*")) == ["exists"], argv


def test_a_report_directory_that_is_a_file_is_refused_before_any_work(
        sim_bag: Path, model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    afile = tmp_path / "afile"
    afile.write_text("mine")
    for argv in (["identify", str(sim_bag), *V, "--out", str(tmp_path / "m.yaml")],
                 ["gap", str(sim_bag), "--model", str(model), *V]):
        for report in (afile, afile / "r"):
            capsys.readouterr()
            assert main([*argv, "--report", str(report)]) == 2
            err = capsys.readouterr().err
            assert err.count("\n") == 1 and f"--report {report}: " in err, err
    assert sorted(tmp_path.iterdir()) == [afile] and afile.read_text() == "mine"


@pytest.mark.parametrize("content", ["random", "mcap"])
def test_a_binary_model_file_is_named_with_what_a_model_file_is(
        sim_bag: Path, tmp_path: Path, content: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    path = (tmp_path / "model.bin" if content == "random"
            else next(sim_bag.glob("*.mcap")))
    if content == "random":
        path.write_bytes(np.random.default_rng(1).bytes(3000))
    for argv in (["validate", str(path), str(sim_bag), *V],
                 ["export", str(path), "--format", "gz"],
                 ["gap", str(sim_bag), "--model", str(path), *V]):
        capsys.readouterr()
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"{path}: not a text file" in err, err
        assert "a model file (the ROS 2 parameters YAML" in err


def test_more_workers_than_logs_are_capped_at_once_with_a_note(
        sim_bag: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    started: list[int] = []

    def cluster(workers: int, processes: bool = True) -> Any:
        started.append(workers)
        raise RuntimeError("no cluster in this test")

    monkeypatch.setattr(pool, "local_cluster", cluster)
    monkeypatch.setattr(pool.os, "cpu_count", lambda: 8)
    capsys.readouterr()
    assert main(["identify", str(sim_bag), str(sim_bag), *V, "--workers", "64"]) == 2
    assert started == [2]
    assert "note: --workers 64 capped to 2 (one per log and per CPU: 2 logs, 8 CPUs)" \
        in capsys.readouterr().err


def test_a_log_in_memory_is_read_by_threads_of_this_process(
        sim_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import fsspec

    fs = fsspec.filesystem("memory")
    fs.put(str(sim_bag), "/h10_faults/dive", recursive=True)
    try:
        capsys.readouterr()
        assert main(["identify", "memory://h10_faults/dive", *V, "--workers", "1", "--out",
                     str(tmp_path / "m.yaml")]) == 0
        assert "is in memory, which worker processes do not share" in capsys.readouterr().err
    finally:
        fs.rm("/h10_faults", recursive=True)


def test_a_log_missing_from_memory_says_memory_is_not_shared() -> None:
    from dampest_ros.io.remote import local_log

    with pytest.raises(FileNotFoundError, match="not shared with other processes"), \
            local_log("memory://h10_faults/nothing"):
        pass
