"""dampest demo: the online pipeline (sim → preprocess → RLS → controller) in one process,
a convergence table against the truth, the model and the report (issue 4)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rclpy")

from dampest_ros.cli.main import main
from dampest_ros.io.yaml_io import load_model, load_vehicle


def test_demo_40s(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--duration", "40", "--rate-factor", "4", "--out", str(out),
                 "--tracking-seconds", "30"]) == 0
    printed = capsys.readouterr().out
    # the live table at 20 s and the final one with the batch column
    assert re.search(r"t =\s+20\.\d s", printed)
    assert "coefficient   estimate" in printed and "batch error %" in printed
    model = load_model(out / "model.yaml")
    truth = load_vehicle("bluerov2_heavy")
    true = dict(zip(truth.damping.parameter_names, truth.theta, strict=True))
    assert model.parameter_names == truth.damping.parameter_names
    for name in ("X_uu", "Y_vv", "Z_ww", "K_pp", "N_rr"):  # well excited by protocol B
        assert model.theta[model.parameter_names.index(name)] == pytest.approx(true[name],
                                                                               rel=0.03)
        row = re.findall(rf"^\s+{name}\s+(\S+)\s+\S+\s+(\S+)\s+(\S+)", printed, re.M)[-1]
        assert float(row[1]) == pytest.approx(true[name], rel=1e-3)  # truth column
    report = out / "report"
    for f in ("index.html", "convergence_linear.png", "convergence_quadratic.png",
              "tracking.png"):
        assert (report / f).stat().st_size > 1000, f
    # the estimate over time ends at the saved model
    hist = np.loadtxt(report / "convergence.csv", delimiter=",", skiprows=1)
    assert hist.shape[1] == 1 + 2 * 12 and hist[-1, 0] > 39.0 and len(hist) > 40
    np.testing.assert_allclose(hist[-1, 1:13], model.theta, rtol=1e-8)
    # tracking on the simulator: the identified model's feed-forward beats the PI alone
    m = re.search(r"PI (\d\.\d+), PI \+ D\(ν\)ν \+ C\(ν\)ν (\d\.\d+)", printed)
    assert m is not None, printed[-2000:]
    pi, ff = float(m.group(1)), float(m.group(2))
    pace = next(line for line in printed.splitlines() if " simulated in " in line)
    print(f"\n{pace}\ntracking RMS: PI {pi}, with the feed-forward {ff}")
    assert ff < 0.3 * pi
