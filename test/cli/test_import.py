"""dampest import: every export format read back from the command line (format detected or
given), and a malformed or foreign file as one line with exit status 2."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dampest_ros.cli.main import main
from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.vehicle import damping_from_spec
from dampest_ros.io.yaml_io import load_model, load_vehicle, save_model

#: Linear with couplings, quadratic and signed forward-speed cross terms: all UUV carries.
SPEC: dict[str, Any] = {
    "linear": {"X_u": 13.7, "Y_v": 4.0, "Z_w": 33.0, "K_p": 0.3, "M_q": 0.8, "N_r": 0.5,
               "X_w": 0.2, "Y_r": 0.15},
    "quadratic": {"X_uu": 141.0, "Y_vv": 217.0, "Z_ww": 190.0, "K_pp": 1.19, "M_qq": 0.47,
                  "N_rr": 1.5},
    "cross": [{"row": "Z", "col": "w", "alpha": "u", "value": 0.7}]}


@pytest.fixture
def model_path(tmp_path: Path) -> Path:
    heavy = load_vehicle("bluerov2_heavy")
    model, theta = damping_from_spec(SPEC)
    return save_model(tmp_path / "model.yaml", Model(
        model.parameter_names, theta, np.zeros(model.n_params), heavy.body.M, damping=model))


def one_line(capsys: pytest.CaptureFixture[str], argv: list[str], *wanted: str) -> str:
    """Run ``argv``: exit status 2 and one line on stderr holding each of ``wanted``."""
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unexpected" not in err and "Traceback" not in err, err
    assert all(w in err for w in wanted), err
    return err


@pytest.mark.parametrize("fmt", ["gz", "urdf", "uuv"])
def test_export_then_import_with_the_format_detected(tmp_path: Path, model_path: Path,
                                                     fmt: str,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    sdf, back = tmp_path / f"hydro.{fmt}.xml", tmp_path / "back.yaml"
    assert main(["export", str(model_path), "--format", fmt, "--vehicle", "bluerov2_heavy",
                 "--out", str(sdf)]) == 0
    capsys.readouterr()
    assert main(["import", str(sdf), "--vehicle", "bluerov2_heavy", "--out", str(back)]) == 0
    assert f"({fmt})" in capsys.readouterr().out
    mf, got = load_model(model_path), load_model(back)
    kept = dict(zip(got.parameter_names, got.theta, strict=True))
    # the URDF block holds the diagonal terms only (the export lists the others)
    carried = (set(mf.parameter_names) if fmt != "urdf" else
               set(SPEC["quadratic"]) | {"X_u", "Y_v", "Z_w", "K_p", "M_q", "N_r"})
    assert set(kept) == carried
    for name, value in zip(mf.parameter_names, mf.theta, strict=True):
        if name in carried:
            assert kept[name] == pytest.approx(value, rel=1e-12, abs=1e-12), name
    np.testing.assert_allclose(got.M, mf.M, rtol=0, atol=1e-12)
    assert got.extra["source"] == f"dampest import {sdf} ({fmt})"


def test_uuv_import_notes_the_vehicle_values(tmp_path: Path, model_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    sdf = tmp_path / "uuv.sdf"
    assert main(["export", str(model_path), "--format", "uuv", "--vehicle", "bluerov2_heavy",
                 "--out", str(sdf)]) == 0
    capsys.readouterr()
    assert main(["import", str(sdf), "--format", "uuv", "--out", str(tmp_path / "m.yaml"),
                 "--vehicle", "bluerov2_heavy"]) == 0
    err = capsys.readouterr().err
    assert "note: volume 0.0134 m^3, centre of buoyancy r_b = [0, 0, -0.01] m (FRD)" in err


@pytest.mark.parametrize(("content", "wanted"), [
    ("<robot><link name='base_link'/></robot>",
     ("holds no hydrodynamics dampest can import", "UUV Simulator <hydrodynamic_model>")),
    ("<plugin name='uuv_plugin'><link name='a'><hydrodynamic_model><type>fossen</type>"
     "<linear_damping>-1 -2 -3</linear_damping></hydrodynamic_model></link></plugin>",
     ("<linear_damping>: needs 6 or 36 numbers (HMFossen), got 3",)),
    ("<plugin name='uuv_plugin'><link name='a'><hydrodynamic_model><type>fossen</type>"
     "<linear_damping>-1 -2 -3 -4 -5 $(arg x)</linear_damping></hydrodynamic_model></link>"
     "</plugin>", ("not a number: '$(arg'",)),
    ("<plugin name='uuv_plugin'><link name='a'><hydrodynamic_model><type>box</type>"
     "</hydrodynamic_model></link></plugin>", ("type 'box': only type fossen",)),
    ("<sdf><model", ("not valid XML",)),
    ("<robot><hydrodynamics><linear_damping Xu='-1'/></hydrodynamics><gazebo><plugin "
     "filename='gz-sim-hydrodynamics-system'><link_name>a</link_name><xU>-1</xU></plugin>"
     "</gazebo></robot>", ("choose one with --format gz or --format urdf",)),
])
def test_malformed_or_foreign_file_is_one_line_and_exit_2(
        tmp_path: Path, content: str, wanted: tuple[str, ...],
        capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "vehicle.sdf"
    f.write_text(content)
    out = tmp_path / "m.yaml"
    one_line(capsys, ["import", str(f), "--vehicle", "bluerov2_heavy", "--out", str(out)],
             "dampest import: error:", *wanted)
    assert not out.exists()


def test_a_format_the_file_does_not_hold_is_one_line(tmp_path: Path, model_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    sdf = tmp_path / "gz.sdf"
    assert main(["export", str(model_path), "--format", "gz", "--out", str(sdf)]) == 0
    one_line(capsys, ["import", str(sdf), "--format", "uuv", "--vehicle", "bluerov2_heavy",
                      "--out", str(tmp_path / "m.yaml")], "no UUV Simulator <hydrodynamic_model>")
