"""HTML report (dampest_ros.report) of a short simulated identification."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.figure import Figure

from dampest_ros.core.identification.batch import fit
from dampest_ros.core.physics import frames
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.simulation.excitation import make_excitation
from dampest_ros.core.simulation.simulate import run
from dampest_ros.io.yaml_io import load_vehicle
from dampest_ros.report.convergence import Tracking, rms_by_unit, write_convergence_report
from dampest_ros.report.figures import PSD_DECADES, parameter_units
from dampest_ros.report.identify import write_report

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def batch_report(tmp_path_factory: pytest.TempPathFactory,
                 figure_recorder: Callable[[pytest.MonkeyPatch], list[Figure]]
                 ) -> tuple[Path, list[Figure]]:
    """The identification report of 60 s of protocol B (seed 2) fitted from a prior 1.2 ×
    the truth, K_pp held at its prior with a reason: its index.html and the figures it
    saved (Figure.savefig wrapped while it is written)."""
    vehicle = load_vehicle("bluerov2_heavy")
    traj = run(vehicle, make_excitation("B", vehicle, 60.0, seed=2))
    euler = frames.euler_from_matrix(frames.quat_to_matrix(traj.quaternion))
    samples = Samples(traj.t, traj.nu, traj.nu_dot, traj.tau, euler, traj.position[:, 2],
                      np.zeros(len(traj), dtype=np.int64))
    prior = 1.2 * vehicle.theta
    result = fit(samples, vehicle.damping, vehicle.body, prior=prior)
    # one parameter held at its prior: shown with its reason, not as a number
    held = np.array([n == "K_pp" for n in result.names])
    result = dataclasses.replace(result, flags={"K_pp": "low speed only: test reason"},
                                 held=held)
    truth = dict(zip(vehicle.damping.parameter_names, vehicle.theta, strict=True))
    with pytest.MonkeyPatch.context() as mp:
        saved = figure_recorder(mp)
        index = write_report(tmp_path_factory.mktemp("batch") / "report", samples,
                             vehicle.damping, vehicle.body, result, prior=prior, truth=truth,
                             title="BlueROV2 Heavy <test>", source="sim/b60.csv",
                             tau_hold="zero")
    return index, saved


def test_report_files_names_and_pngs(batch_report: tuple[Path, list[Figure]]) -> None:
    vehicle = load_vehicle("bluerov2_heavy")
    index, out = batch_report[0], batch_report[0].parent
    assert index.name == "index.html" and index.is_file()
    text = index.read_text(encoding="utf-8")
    for name in vehicle.damping.parameter_names:
        assert f"<td>{name}</td>" in text, name
    assert "BlueROV2 Heavy &lt;test&gt;" in text and "sim/b60.csv" in text
    assert re.search(r"generated \d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC", text)
    row = next(r for r in text.split("<tr") if "<td>K_pp</td>" in r)
    assert "held at prior" in row and "test reason" in row
    pngs = re.findall(r'<img src="([^"]+)"', text)
    assert len(pngs) == 6
    for name in pngs:
        path = out / name
        assert path.parent == out and path.is_file(), name  # relative links
        data = path.read_bytes()
        assert len(data) > 1000 and data[:8] == PNG_MAGIC, name


# --- units on every axis ----------------------------------------------------------------------

def test_every_axis_of_the_report_has_a_unit(
        batch_report: tuple[Path, list[Figure]],
        axis_unit_problems: Callable[[list[Figure]], list[str]]) -> None:
    figures = batch_report[1]
    assert len(figures) == 6
    assert axis_unit_problems(figures) == []
    coef = next(f for f in figures if "Coefficients" in f.texts[0].get_text())
    labels = {ax.get_title(): ax.get_ylabel() for ax in coef.axes if ax.get_visible()}
    assert labels["X_u"] == "(N·s/m)" and labels["N_rr"] == "(N·m·s²/rad²)"
    # measured vs model over a residual panel in the same unit, each with a legend, and
    # no offset text (×10ⁿ, +c) that would sit on the panel above
    for title, unit in (("Damping force", "N"), ("Free-run", "m/s")):
        fig = next(f for f in figures if f.texts[0].get_text().startswith(title))
        assert len(fig.axes) == 12 and all(ax.get_legend() is not None for ax in fig.axes)
        residuals = [ax for ax in fig.axes if ax.get_ylabel().startswith("resid.")]
        assert len(residuals) == 6 and residuals[0].get_ylabel() == f"resid. ({unit})"
        fig.canvas.draw()
        assert all(ax.yaxis.get_offset_text().get_text() == "" for ax in fig.axes)
    # the PSD axis spans at most PSD_DECADES (8) decades below the force's peak, not 20,
    # and reaches down to the residual
    spectrum = next(f for f in figures if "PSD" in f.texts[0].get_text())
    assert spectrum.axes[0].get_ylabel() == "X PSD (N²/Hz)"
    for ax in spectrum.axes:
        lo, hi = ax.get_ylim()
        assert 1.0 < np.log10(hi / lo) <= PSD_DECADES + np.log10(3.0) + 1e-9
        residual = np.asarray(ax.get_lines()[1].get_ydata(), dtype=float)
        assert lo <= np.percentile(residual[residual > 0], 5) or \
            np.log10(hi / lo) > PSD_DECADES


def test_convergence_report_axes_and_tracking_rms_per_unit(
        tmp_path: Path, saved_figures: list[Figure],
        axis_unit_problems: Callable[[list[Figure]], list[str]]) -> None:
    vehicle = load_vehicle("bluerov2_heavy")
    names = vehicle.damping.parameter_names
    t = np.linspace(0.0, 100.0, 51)
    theta = vehicle.theta * (1 - 0.5 * np.exp(-t / 20.0))[:, None]
    std = 0.1 * np.abs(vehicle.theta) * np.exp(-t / 40.0)[:, None]
    # tracking: the reference in u, w (m/s) and r (rad/s); errors 0.01 m/s, 0.1 rad/s
    tt = np.linspace(0.0, 19.9, 200)
    ref = np.zeros((200, 6))
    ref[:, [0, 2, 5]] = np.sin(tt)[:, None]
    flown = ref.copy()
    flown[:, [0, 2]] += 0.01
    flown[:, 5] += 0.1
    rms = rms_by_unit(ref, flown, (0, 2, 5), skip=10)
    assert rms == pytest.approx({"m/s": 0.01, "rad/s": 0.1})
    tracking = Tracking(tt, ref, {"PI": flown}, {"PI": rms}, (0, 2, 5), 10, 2.0)
    groups = {term.kind: term.parameter_names for term in vehicle.damping.terms}
    figures = saved_figures
    index = write_convergence_report(tmp_path / "online", names, t, theta, std, groups,
                                     truth=vehicle.theta, tracking=tracking,
                                     units=parameter_units(vehicle.damping))
    assert len(figures) == len(groups) + 1
    assert axis_unit_problems(figures) == []
    text = index.read_text(encoding="utf-8")
    assert "RMS error (m/s; u, w)" in text and "RMS error (rad/s; r)" in text
    assert "<td>0.01</td><td>0.1</td>" in text


@pytest.mark.parametrize(("start", "xs"), [([0.0, 600.0, 1500.0], [0.0, 600.0, 1500.0]),
                                           ([5.0, 5.0, 7.0], [0.0, 1.0, 2.0])])
def test_drift_plot_puts_each_log_at_its_own_x_with_a_legend(
        tmp_path: Path, start: list[float], xs: list[float]) -> None:
    """Start times as x; the log index when two logs start together (simulated logs all
    start at 0); one colour and legend entry per log, and the pooled line."""
    from types import SimpleNamespace

    from dampest_ros.cli.pool import plot_drift

    rng = np.random.default_rng(0)
    d = SimpleNamespace(names=["X_u", "X_uu"], logs=["a", "b", "c"], start=np.array(start),
                        theta=rng.normal(size=(3, 2)), std=np.full((3, 2), 0.1),
                        moved=[False, True])
    shown: list[Figure] = []
    orig = Figure.savefig

    def keep(fig: Figure, *args: Any, **kwargs: Any) -> None:
        shown.append(fig)
        orig(fig, *args, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Figure, "savefig", keep)
        plot_drift(tmp_path / "drift.png", d, SimpleNamespace(theta=np.zeros(2)),  # type: ignore[arg-type]
                   {"X_u": "N·s/m", "X_uu": "N·s²/m²"})
    assert (tmp_path / "drift.png").read_bytes()[:8] == PNG_MAGIC
    (fig,) = shown
    ax = fig.axes[0]
    assert [float(c.get_children()[0].get_xdata()[0]) for c in ax.containers] == xs
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["pooled", "a", "b", "c"]
    assert fig.axes[1].get_title() == "X_uu (changed)"
