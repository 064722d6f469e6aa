"""Logs pooled by dampest identify that are not all of one vehicle: the foreign log is named
and left out unless --keep-all."""

from __future__ import annotations

from pathlib import Path

import pytest

from dampest_ros.cli.main import main
from dampest_ros.io.yaml_io import load_model


def test_a_log_of_another_vehicle_is_named_and_left_out(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Three 60 s BlueROV2 Heavy logs and one of platform_b (a 150 kg ROV), all identified as
    the Heavy: pooled together they gave X_u 113 (truth 13.7), X_uu 130 (141)."""
    logs = []
    for k, vehicle in enumerate(("bluerov2_heavy",) * 3 + ("platform_b",)):
        out = tmp_path / f"dive_{k + 1}"
        assert main(["simulate", "--vehicle", vehicle, "--protocol", "B", "--duration", "60",
                     "--seed", str(k + 1), "--out", str(out)]) == 0
        logs.append(str(out))
    options = ["identify", *logs, "--vehicle", "bluerov2_heavy", "--workers", "1", "--out"]
    capsys.readouterr()
    assert main([*options, str(tmp_path / "pooled.yaml")]) == 0
    err = capsys.readouterr().err
    assert f"left out: {logs[3]}: its estimate is inconsistent with the other logs'" in err
    assert sum("inconsistent" in line for line in err.splitlines()) == 1
    model = load_model(tmp_path / "pooled.yaml")
    assert model.extra["logs"] == logs[:3] and model.extra["logs_left_out"] == [logs[3]]
    assert model.value("X_u") == pytest.approx(13.84, abs=0.01)
    assert model.value("X_uu") == pytest.approx(140.5, abs=0.1)
    assert main([*options, str(tmp_path / "all.yaml"), "--keep-all"]) == 0
    assert f"kept (--keep-all): {logs[3]}" in capsys.readouterr().err
    every = load_model(tmp_path / "all.yaml")
    assert every.value("X_u") == pytest.approx(113.3, abs=0.1)
    assert every.value("X_uu") == pytest.approx(129.8, abs=0.1)
