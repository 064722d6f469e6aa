"""dampest gap: acceptance on a simulated bag with hidden effects.

The bag (protocol B, 600 s, default sensor noise) hides a 1 N buoyancy offset and a −10 %
thrust-gain error; the model the user believes (``sim_model.yaml``) also has X_uu = 100
instead of the 141 of the simulated vehicle. The workflow must name all three, add them to
the model and say that nothing further is missing.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pytest

from dampest_ros.cli.inputs import load_model_for
from dampest_ros.cli.main import main
from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.terms import CrossSpec, cross_term
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
    save_model(root / "sim_model.yaml", Model(v.damping.parameter_names, theta,
                                              np.zeros(len(theta)), v.body.M, damping=v.damping))
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


@pytest.fixture(scope="module")
def csv_gap(measured: Path) -> tuple[str, Path]:
    """``gap`` on the CSV of samples with the thruster, buoyancy and damping candidates: what
    it prints and the model it writes."""
    out, printed = measured / "final_csv.yaml", io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["gap", str(measured / "samples.csv"), "--model",
                     str(measured / "sim_model.yaml"), "--vehicle", "bluerov2_heavy",
                     "--candidates", "thrusters,buoyancy,damping", "--out", str(out)]) == 0
    return printed.getvalue(), out


def test_csv_input_skips_the_dead_zone_and_finds_the_same(csv_gap: tuple[str, Path]) -> None:
    printed = csv_gap[0]
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


# --- what gap prints and writes, bad options, several logs ------------------------------


def test_printed_magnitudes_are_what_the_model_file_holds(csv_gap: tuple[str, Path]) -> None:
    """Before: each step printed its own refit (ΔX_uu +40.6 at step 2) while the file held
    the final joint refit of all three effects."""
    printed, out = csv_gap
    final = load_model(out)
    gap = final.extra["gap"]
    x_uu = final.theta[final.parameter_names.index("X_uu")]
    assert f"ΔX_uu = {gap['quadratic_X_uu']['X_uu']:+.4g}" in printed
    assert f"in the model: X_uu 100 → {x_uu:.4g}" in printed
    assert f"ε = {100 * gap['thrust_gain']['epsilon']:+.2f}" in printed
    assert f"ΔB = {gap['buoyancy']['delta_B']:+.3g}" in printed


def test_naming_a_cross_term_the_model_has_updates_it_and_writes_the_files(
        measured: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Before: 'terms: duplicate parameter names', exit 2, neither --out nor --report."""
    v = load_vehicle("bluerov2_heavy")
    model = DampingModel([*v.damping.terms, cross_term([CrossSpec.from_dict(
        {"row": "Y", "col": "v", "alpha": "|r|"})])])
    theta = model.theta_from_dict({**dict(zip(v.damping.parameter_names, v.theta,
                                              strict=True)), "Y_vr": 60.0})
    believed = measured / "cross_model.yaml"
    save_model(believed, Model(model.parameter_names, theta, np.zeros(len(theta)), v.body.M,
                               damping=model))
    out, report = measured / "cross_final.yaml", measured / "cross_report"
    capsys.readouterr()
    assert main(["gap", str(measured / "samples.csv"), "--model", str(believed),
                 "--vehicle", "bluerov2_heavy", "--candidates", "cross.Y_vr,buoyancy,thrusters",
                 "--out", str(out), "--report", str(report)]) == 0
    final = load_model(out)
    assert "cross.Y_vr" in final.extra["gap"]["named"]
    assert final.parameter_names == model.parameter_names  # updated, not added again
    # the simulated vehicle has no Y_v|r|: the update brings it back to about 0
    assert abs(final.theta[final.parameter_names.index("Y_vr")]) < 3.0
    assert (report / "index.html").exists()
    load_model_for(str(out), v)


def test_a_diverging_believed_model_is_explained_and_the_files_are_written(
        measured: Path, capsys: pytest.CaptureFixture[str]) -> None:
    v = load_vehicle("bluerov2_heavy")
    theta = v.damping.theta_from_dict({**dict(zip(v.damping.parameter_names, v.theta,
                                                  strict=True)), "Z_ww": -61.0})
    believed = measured / "zww_model.yaml"
    save_model(believed, Model(v.damping.parameter_names, theta, np.zeros(len(theta)), v.body.M,
                               damping=v.damping))
    out, report = measured / "zww_final.yaml", measured / "zww_report"
    capsys.readouterr()
    assert main(["gap", str(measured / "samples.csv"), "--model", str(believed),
                 "--vehicle", "bluerov2_heavy", "--candidates", "thrusters,buoyancy,damping",
                 "--out", str(out), "--report", str(report)]) == 0
    printed = capsys.readouterr().out
    line = "the believed model diverges: Z_ww < 0 leaves no steady heave speed above 4.46 N"
    assert line in printed
    assert "diverges: Z_ww &lt; 0 leaves no steady heave speed" in (report / "index.html"
                                                                    ).read_text()
    final = load_model(out)
    assert final.theta[final.parameter_names.index("Z_ww")] == pytest.approx(190.0, rel=0.05)
    load_model_for(str(out), v)


@pytest.mark.parametrize(("option", "value"), [("--split", "1.5"), ("--min-heldout", "2"),
                                               ("--max-steps", "-1"), ("--split", "nan")])
def test_bad_options_are_one_line_and_exit_2(measured: Path, option: str, value: str,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["gap", str(measured / "samples.csv"), "--model",
                 str(measured / "sim_model.yaml"), "--vehicle", "bluerov2_heavy",
                 option, value]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"dampest gap: error: {option}: ") and err.count("\n") == 1, err


def test_several_logs_are_screened_pooled(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """Two 150 s bags (seeds 5, 6) with the same hidden buoyancy offset (+10 N), read on two
    Dask workers and pooled one after the other in time: the offset is named first, on
    samples of both; a third log that is not a bag is left out with its reason."""
    bags = []
    for seed in (5, 6):
        bag = tmp_path / f"dive_{seed}"
        assert main(["simulate", "--vehicle", "bluerov2_heavy", "--protocol", "B",
                     "--duration", "150", "--seed", str(seed), "--out", str(bag),
                     "--effects", "{buoyancy_offset: 10.0}"]) == 0
        bags.append(str(bag))
    broken = tmp_path / "dive_broken"
    broken.mkdir()
    (broken / "metadata.yaml").write_text("not: a bag\n")
    out = tmp_path / "final.yaml"
    capsys.readouterr()
    assert main(["gap", *bags, str(broken), "--model",
                 str(tmp_path / "dive_5" / "truth_model.yaml"), "--vehicle", "bluerov2_heavy",
                 "--max-steps", "2", "--out", str(out), "--workers", "2"]) == 0
    printed = capsys.readouterr()
    assert "2 logs pooled" in printed.err
    assert f"left out: {broken}:" in printed.err and "Traceback" not in printed.err
    first = printed.out.splitlines()[0]
    n = int(first.split(": ", 1)[1].split()[0])
    assert n > 2 * 0.9 * 150 * 50  # samples of both logs (50 Hz, a few dropped at the ends)
    model = load_model(out)
    assert model.extra["gap"]["named"][0] == "buoyancy"
    assert model.extra["source"].startswith(f"dampest gap {bags[0]}, {bags[1]}, {broken}")
    assert model.extra["logs"] == bags and model.extra["logs_left_out"] == [str(broken)]


def test_a_named_current_is_refitted_at_the_relative_velocity_and_written(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A bag with a hidden 0.25 m/s current towards 306.9° against the exact model: the
    current is named first, the model is refitted at ν_r jointly with it (no terms added:
    the exact model's fit there), --out holds that refit and its held-out scores, and the
    report shows the residual per DOF before → after each step and the refit, with units."""
    assert main(["simulate", "--vehicle", "bluerov2_heavy", "--protocol", "B", "--duration",
                 "200", "--seed", "3", "--out", str(tmp_path / "bag"),
                 "--effects", "{current: [0.15, -0.2, 0.0]}"]) == 0
    v = load_vehicle("bluerov2_heavy")
    save_model(tmp_path / "exact.yaml", Model(v.damping.parameter_names, v.theta,
                                              np.zeros(len(v.theta)), v.body.M,
                                              damping=v.damping))
    capsys.readouterr()
    out, report = tmp_path / "final.yaml", tmp_path / "report"
    assert main(["gap", str(tmp_path / "bag"), "--model", str(tmp_path / "exact.yaml"),
                 "--vehicle", "bluerov2_heavy", "--candidates", "current,buoyancy",
                 "--out", str(out), "--report", str(report)]) == 0
    printed = capsys.readouterr().out
    assert "refitted at the relative velocity" in printed and "R² refit at ν_r" in printed
    final = load_model(out)
    gap = final.extra["gap"]
    assert gap["named"][0] == "current", gap["named"]
    north, east, _ = gap["refit"]["current_ned"]
    assert np.hypot(north, east) == pytest.approx(0.25, rel=0.05)
    assert np.degrees(np.arctan2(east, north)) % 360 == pytest.approx(306.87, abs=3.0)
    after = np.array(gap["refit"]["rmse_heldout_after"])
    assert np.all(after <= np.array(gap["refit"]["rmse_heldout_before"]))
    # the exact model's terms fit ν_r: selection there adds none
    assert gap["refit"]["added_terms"] == ["none"]
    assert "no terms added: the model's terms fit ν_r" in printed
    # the written θ is the refit's, with its own σ
    assert final.parameter_names == v.damping.parameter_names
    assert np.all(final.theta_std > 0)
    page = (report / "index.html").read_text()
    assert "X held-out RMS (N)" in page and "N held-out RMS (N·m)" in page
    assert "refitted at ν_r" in page
