"""dampest gap's report figure: units on every axis, a PSD axis of a few decades."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from dampest_ros.cli.main import main
from dampest_ros.report.figures import PSD_DECADES

REPO = Path(__file__).resolve().parents[2]


def test_residual_figure_axes_have_units_and_a_sensible_psd_range(
        tmp_path: Path, saved_figures: list[Figure],
        axis_unit_problems: Callable[[list[Figure]], list[str]]) -> None:
    sample = REPO / "bags" / "sample"
    assert main(["gap", str(sample), "--model", str(sample / "truth_model.yaml"),
                 "--vehicle", "bluerov2_heavy", "--report", str(tmp_path / "report"),
                 "--max-steps", "0", "--split", "0.5"]) == 0
    (fig,) = saved_figures
    assert axis_unit_problems([fig]) == []
    psd = [ax for ax in fig.axes if ax.get_yscale() == "log"]
    assert len(psd) == 6 and psd[0].get_ylabel() == "PSD (N²/Hz)"
    assert psd[3].get_ylabel() == "PSD ((N·m)²/Hz)"
    for ax in psd:
        lo, hi = ax.get_ylim()
        assert 1.0 < np.log10(hi / lo) <= PSD_DECADES + np.log10(3.0) + 1e-9
