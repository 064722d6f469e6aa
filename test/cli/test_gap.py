"""dampest gap: acceptance on a simulated bag with hidden effects (issue 6).

The bag (protocol B, 600 s, default sensor noise) hides a 1 N buoyancy offset and a −10 %
thrust-gain error; the model the user believes (``sim_model.yaml``) also has X_uu = 100
instead of the 141 of the simulated vehicle. The workflow must name all three, add them to
the model and say that nothing further is missing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dampest_ros.cli.main import main
from dampest_ros.io.yaml_io import load_model, load_vehicle, save_model


@pytest.fixture(scope="module")
def measured(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Bag + CSV with hidden buoyancy offset and thrust-gain error; the believed model."""
    root = tmp_path_factory.mktemp("gap")
    assert main([
        "simulate", "--vehicle", "bluerov2_heavy", "--protocol", "B", "--duration", "600",
        "--seed", "2", "--out", str(root / "bag"), "--csv", str(root / "samples.csv"),
        "--effects", "{buoyancy_offset: 1.0, thrust_gain_error: -0.1}"]) == 0
    v = load_vehicle("bluerov2_heavy")
    theta = v.theta.copy()
    theta[v.damping.parameter_names.index("X_uu")] = 100.0
    save_model(root / "sim_model.yaml", v.damping.parameter_names, theta,
               np.zeros(len(theta)), v.body.M, damping=v.damping)
    return root


def test_bag_names_the_three_missing_effects_and_writes_the_report(
        measured: Path, capsys: pytest.CaptureFixture[str]) -> None:
    report, out = measured / "report", measured / "final.yaml"
    capsys.readouterr()
    assert main(["gap", str(measured / "bag"), "--model", str(measured / "sim_model.yaml"),
                 "--vehicle", "bluerov2_heavy", "--report", str(report),
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    for words in ("thrust-gain error", "buoyancy/weight offset", "quadratic damping in u",
                  "no further missing effect found", "where the residual is concentrated",
                  "held-out residual RMS per DOF", "free run"):
        assert words in printed, words
    final = load_model(out)
    gap = final.extra["gap"]
    assert sorted(gap["named"]) == ["buoyancy", "quadratic.X_uu", "thrust_gain"]
    assert gap["buoyancy"]["delta_B"] == pytest.approx(1.0, rel=0.2)
    assert gap["thrust_gain"]["epsilon"] == pytest.approx(-0.1, rel=0.2)
    # the missing quadratic drag is added to the model's coefficient
    x_uu = final.theta[final.parameter_names.index("X_uu")]
    assert x_uu == pytest.approx(141.0, rel=0.05)
    assert final.damping is not None
    assert final.damping.parameter_names == final.parameter_names
    # report: page, one residual figure per step, the final model
    page = (report / "index.html").read_text()
    assert "Sim-to-real gap" in page and "no further missing effect found" in page
    for k in (1, 2, 3):
        assert (report / f"step{k}.png").stat().st_size > 10_000
        assert f"step{k}.png" in page
    assert load_model(report / "final_model.yaml").parameter_names == final.parameter_names


def test_csv_input_skips_the_dead_zone_and_finds_the_same(
        measured: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["gap", str(measured / "samples.csv"), "--model",
                 str(measured / "sim_model.yaml"), "--vehicle", "bluerov2_heavy",
                 "--candidates", "thrusters,buoyancy,damping"]) == 0
    printed = capsys.readouterr().out
    assert "skipped deadzone" in printed and "rotor speeds" in printed
    assert "thrust-gain error" in printed and "buoyancy/weight offset" in printed
    assert "no further missing effect found" in printed


def test_unknown_candidate_is_an_error(measured: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["gap", str(measured / "samples.csv"), "--model",
                 str(measured / "sim_model.yaml"), "--vehicle", "bluerov2_heavy",
                 "--candidates", "warp_drive"]) == 2
    err = capsys.readouterr().err
    assert "warp_drive" in err and "current" in err
