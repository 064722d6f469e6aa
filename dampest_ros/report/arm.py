"""The figures of an arm identification report (``dampest arm identify --report``): the
joint trajectory, the measured joint torque against the model's with the residual, and the
base parameters with their σ against the nominal (the URDF's and the MuJoCo model's joint
terms). Every axis carries its unit.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from dampest_ros.report.figures import coef_figure, measured_vs_model, save_figure

FloatArray = NDArray[np.float64]

#: The unit of a full parameter by its name's last part (``elbow_joint.mx`` → kg·m): a base
#: parameter has the unit of the full parameter it keeps (what it folds in comes with
#: lengths that make the units agree).
PARAMETER_UNITS = {"m": "kg", "mx": "kg·m", "my": "kg·m", "mz": "kg·m", "Ixx": "kg·m²",
                   "Ixy": "kg·m²", "Iyy": "kg·m²", "Ixz": "kg·m²", "Iyz": "kg·m²",
                   "Izz": "kg·m²", "Ia": "kg·m²", "Fv": "N·m·s/rad", "Fc": "N·m", "off": "N·m"}


def trajectory_figure(t: FloatArray, q: FloatArray, joints: Sequence[str], path: Path) -> str:
    """The joint positions q (N, n) in rad against time t (N,) in s, one panel per joint.

    Returns
    -------
    str
        The file name written.
    """
    rows = -(-len(joints) // 2)
    fig = Figure(figsize=(11, 1.9 * rows + 0.8))
    axes = fig.subplots(rows, 2, sharex=True, squeeze=False).T.ravel()
    for j, ax in enumerate(axes):
        if j >= len(joints):
            ax.set_visible(False)
            continue
        ax.plot(t - t[0], q[:, j], lw=0.8, color="tab:blue")
        ax.set_ylabel(f"{joints[j]} (rad)", fontsize=8)
        ax.grid(alpha=0.3)
    for ax in axes[rows - 1::rows]:
        ax.set_xlabel("time (s)")
    fig.suptitle("Joint trajectory (filtered positions q)")
    return save_figure(fig, path, bottom=0.6 / fig.get_figheight())


def torque_figure(t: FloatArray, measured: FloatArray, model: FloatArray,
                  joints: Sequence[str], path: Path) -> str:
    """Filtered measured joint torque and the model's Y_b θ (N, n) in N·m against time t
    (N,) in s, each over its residual."""
    return measured_vs_model(t - t[0], measured, model, ("measured τ", "model Y_b θ"), joints,
                             ["N·m"] * len(joints),
                             "Joint torque: measured (filtered) vs the WLS model", path)


def parameter_figure(names: Sequence[str], theta: FloatArray, std: FloatArray,
                     nominal: FloatArray, path: Path) -> str:
    """The base parameters (b,) with their 95 % intervals (θ ± 1.96 σ) against the nominal
    values, one panel each in the unit of the full parameter it keeps."""
    theta, std = np.asarray(theta, dtype=float), np.asarray(std, dtype=float)
    ci = np.column_stack([theta - 1.96 * std, theta + 1.96 * std])
    units = {n: PARAMETER_UNITS[n.rsplit(".", 1)[-1]] for n in names}
    every = np.ones(len(names), dtype=bool)
    return coef_figure(list(names), theta, ci, ~every, every, np.asarray(nominal, dtype=float),
                       None, units, path, prior_label="nominal",
                       title="Base parameters: WLS estimate with 95 % interval vs nominal")
