"""dampest demo: the online pipeline (sim → preprocess → RLS → controller) in one process,
started from a wrong prior (half the true coefficients), a convergence table against the
truth, the ±2σ coverage, the model and the report."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("rclpy")

from dampest_ros.cli.main import main
from dampest_ros.io.yaml_io import load_model, load_vehicle
from dampest_ros.report.convergence import band_coverage

NUMBER = r"(-?[\d.]+(?:e[-+]\d+)?|—)"


def rows(table: str) -> dict[str, list[float]]:
    """coefficient → the numbers of its row in a printed table (NaN for —)."""
    out = {}
    for m in re.finditer(rf"^\s+(\w+)((?:\s+{NUMBER})+)\s*$", table, re.M):
        out[m.group(1)] = [np.nan if x == "—" else float(x) for x in m.group(2).split()]
    return out


def test_demo_40s_converges_from_a_wrong_prior(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--duration", "40", "--rate-factor", "4", "--out", str(out),
                 "--tracking-seconds", "30"]) == 0
    printed = capsys.readouterr().out
    truth = load_vehicle("bluerov2_heavy")
    names = truth.damping.parameter_names
    true = dict(zip(names, truth.theta, strict=True))
    nonzero = [n for n in names if true[n] != 0.0]
    assert len(nonzero) == 9
    # the prior: half the truth, given to the estimator as its prior file
    prior = load_model(out / "prior.yaml")
    np.testing.assert_allclose(prior.theta, 0.5 * truth.theta, rtol=1e-12)
    assert np.all(prior.theta_std >= 5.0 * np.abs(prior.theta))
    # tables at t = 0 (the prior: -50 %), 20 s and the end (with batch and coverage columns)
    tables = re.split(r"\n(?=t =\s+[\d.]+ s)", printed)[1:]
    assert re.match(r"t =\s+0\.0 s", tables[0]) and re.match(r"t =\s+20\.\d s", tables[1])
    first, last = rows(tables[0]), rows(tables[-1])
    assert "batch error %" in tables[-1] and "±2σ cover %" in tables[-1]
    for name in nonzero:
        assert first[name][0] == pytest.approx(0.5 * true[name], rel=1e-3)
        assert first[name][3] == pytest.approx(-50.0)  # error %
        assert last[name][2] == pytest.approx(true[name], rel=1e-3)  # truth column
    model = load_model(out / "model.yaml")
    assert model.parameter_names == names
    final = dict(zip(names, model.theta, strict=True))
    for name in nonzero:  # converged: within a few % after 40 s
        assert final[name] == pytest.approx(true[name], rel=0.05), name
    for name in ("X_uu", "Y_vv", "Z_ww", "K_pp", "N_rr"):  # well excited by protocol B
        assert final[name] == pytest.approx(true[name], rel=0.03), name
    # the estimate over time starts at the prior and ends at the saved model
    report = out / "report"
    hist = np.loadtxt(report / "convergence.csv", delimiter=",", skiprows=1)
    assert hist.shape[1] == 1 + 2 * 12 and hist[0, 0] == 0.0 and hist[-1, 0] > 39.0
    assert len(hist) > 40
    np.testing.assert_allclose(hist[0, 1:13], prior.theta, rtol=1e-12)
    np.testing.assert_allclose(hist[-1, 1:13], model.theta, rtol=1e-8)
    # the ±2σ coverage printed is that of the recorded estimate against the truth
    coverage = band_coverage(hist[:, 0], hist[:, 1:13], hist[:, 13:], truth.theta)
    np.testing.assert_allclose([last[n][-1] for n in names], 100 * coverage, atol=0.01)
    m = re.search(r"±2σ coverage of the truth over the second half of the run: (\d+) %",
                  printed)
    assert m is not None and int(m.group(1)) == round(100 * np.mean(coverage))
    for f in ("index.html", "convergence_linear.png", "convergence_quadratic.png",
              "tracking.png"):
        assert (report / f).stat().st_size > 1000, f
    assert "±2σ coverage, last half" in (report / "index.html").read_text()
    # tracking on the simulator: the identified model's feed-forward beats the PI alone, in
    # m/s (u, w) and in rad/s (r) apart (never mixed)
    rms = {u: (float(a), float(b)) for a, b, u in
           re.findall(r"(\d\.\d+) → (\d\.\d+) (m/s|rad/s) \(", printed)}
    assert set(rms) == {"m/s", "rad/s"}, printed[-2000:]
    pace = next(line for line in printed.splitlines() if " simulated in " in line)
    print(f"\n{pace}\ntracking RMS, PI → with the feed-forward: {rms}\n±2σ coverage "
          f"(second half): {np.round(100 * coverage)}")
    assert rms["m/s"][1] < 0.3 * rms["m/s"][0]
    assert rms["rad/s"][1] < 0.5 * rms["rad/s"][0]
    page = (report / "index.html").read_text()
    assert "RMS error (m/s; u, w)" in page and "RMS error (rad/s; r)" in page


def test_live_stopped_with_sigterm_saves_the_run_like_ctrl_c(tmp_path: Path, children: Any
                                                               ) -> None:
    """SIGTERM (what systemd, docker and launch send) ends dampest live as Ctrl-C does: the
    model identified so far is written and the exit status is 0 (it was 143, nothing kept)."""
    import os
    import signal
    import sys
    import time

    out, log = tmp_path / "run", tmp_path / "live.log"
    env = {**os.environ, "ROS_DOMAIN_ID": "94", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    proc = children.start([sys.executable, "-m", "dampest_ros.cli.main", "live",
                           "--duration", "600", "--every", "1", "--out", str(out)], log=log,
                          env=env)
    tables = re.compile(r"^t =\s+[\d.]+ s", re.M)
    deadline = time.monotonic() + 60.0
    # some samples in: the table after 1 s of simulated time, after the prior's at t = 0
    while len(tables.findall(log.read_text())) < 2 and time.monotonic() < deadline:
        assert proc.poll() is None, log.read_text()
        time.sleep(0.2)
    assert children.stop(proc, signal.SIGTERM, timeout=60.0) == 0, log.read_text()
    text = log.read_text()
    assert len(tables.findall(text)) >= 2, text
    assert "interrupted: saving what was identified so far" in text
    model = load_model(out / "model.yaml")
    assert model.version >= 1 and np.all(np.isfinite(model.theta))
