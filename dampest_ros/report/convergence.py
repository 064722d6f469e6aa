"""The report of an online identification: ``write_convergence_report`` writes the estimate of
each coefficient over time with its ±2σ band and the truth, one figure per damping term, and a
controller's velocity tracking without and with the model's feed-forward.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from dampest_ros.core.physics.rigid_body import DOF_NAMES
from dampest_ros.core.simulation.control import tracking_rms
from dampest_ros.report.figures import (
    VEL_UNITS,
    Values,
    aligned,
    generated_utc,
    grid,
    html_head,
    html_table,
    num,
    save_figure,
    write_index,
)

FloatArray = NDArray[np.float64]


@dataclass
class Tracking:
    """Closed-loop velocity tracking runs on one reference (FRD, m/s and rad/s).

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time (s).
    nu_ref : ndarray, shape (N, 6)
    nu : mapping label → ndarray, shape (N, 6)
        The velocity of each run (e.g. ``PI``, ``PI + D(ν)ν + C(ν)ν``).
    rms : mapping label → (mapping unit → float)
        RMS tracking error of each run after ``skip`` steps, over the DOFs of each velocity
        unit apart (``m/s``, ``rad/s``; :func:`rms_by_unit`): never m/s and rad/s mixed.
    dofs : sequence of int
        The DOFs with a reference (0..5 = u..r).
    skip : int
        Steps of transient left out of the RMS.
    bandwidth : float
        Closed-loop bandwidth of the controller (rad/s).
    """

    t: FloatArray
    nu_ref: FloatArray
    nu: Mapping[str, FloatArray]
    rms: Mapping[str, Mapping[str, float]]
    dofs: Sequence[int]
    skip: int
    bandwidth: float


def rms_by_unit(nu_ref: FloatArray, nu: FloatArray, dofs: Sequence[int], skip: int = 0
                ) -> dict[str, float]:
    """RMS tracking error over the given DOFs, one value per velocity unit.

    Parameters
    ----------
    nu_ref, nu : ndarray, shape (N, 6)
        Reference and flown body velocity (m/s, rad/s).
    dofs : sequence of int
        Columns (0..5 = u..r) with a reference.
    skip : int
        Steps of transient left out.

    Returns
    -------
    dict
        ``{"m/s": RMS over the linear DOFs, "rad/s": RMS over the angular ones}``, only the
        units among ``dofs``.
    """
    units = dict.fromkeys(VEL_UNITS[i] for i in dofs)
    return {u: tracking_rms(nu_ref, nu, [i for i in dofs if VEL_UNITS[i] == u], skip)
            for u in units}


def _rms_text(rms: Mapping[str, float], dofs: Sequence[int]) -> str:
    """'0.0123 m/s (u, w), 0.0456 rad/s (r)'."""
    return ", ".join(f"{v:.4f} {u} ({', '.join(DOF_NAMES[i] for i in dofs if VEL_UNITS[i] == u)})"
                     for u, v in rms.items())


def band_coverage(t: FloatArray, theta: FloatArray, std: FloatArray, truth: FloatArray
                  ) -> FloatArray:
    """How often the ±2σ band held the truth over the last half of an online run.

    Parameters
    ----------
    t : ndarray, shape (K,)
        Times of the recorded estimates (s), increasing.
    theta, std : ndarray, shape (K, p)
        The estimate and its standard deviation at each time.
    truth : ndarray, shape (p,)
        True coefficients (NaN: unknown).

    Returns
    -------
    ndarray, shape (p,)
        Per coefficient, the fraction of the recorded instants with t ≥ (t₀ + t_end)/2 at
        which |θ − truth| ≤ 2σ (NaN where the truth is unknown); about 0.95 when σ is right.
    """
    t, theta, std = (np.asarray(a, dtype=float) for a in (t, theta, std))
    last = t >= 0.5 * (t[0] + t[-1])
    inside = np.abs(theta[last] - truth) <= 2.0 * std[last]
    return np.where(np.isfinite(truth), inside.mean(axis=0), np.nan)


def _convergence_figure(kind: str, names: Sequence[str], t: FloatArray, theta: FloatArray,
                        std: FloatArray, truth: FloatArray | None, units: Mapping[str, str],
                        path: Path) -> str:
    nrows, ncols = grid(len(names), 3)
    fig = Figure(figsize=(11, 2.3 * nrows + 0.9))
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False, sharex=True).ravel())
    late = t >= t[0] + 0.1 * (t[-1] - t[0])  # the prior's wide band would hide the rest
    for j, ax in enumerate(axes):
        if j >= len(names):
            ax.set_visible(False)
            continue
        lo, hi = theta[:, j] - 2 * std[:, j], theta[:, j] + 2 * std[:, j]
        ax.fill_between(t, lo, hi, color="tab:blue", alpha=0.2, lw=0, label="±2σ")
        ax.plot(t, theta[:, j], color="tab:blue", lw=1.2, label="estimate")
        ax.plot(t[:1], theta[:1, j], "o", color="tab:blue", ms=5, label="prior")
        span = [lo[late], hi[late], theta[:1, j]]
        if truth is not None and np.isfinite(truth[j]):
            ax.axhline(truth[j], color="tab:orange", ls="--", lw=1.2, label="truth")
            span.append(np.array([truth[j]]))
        a, b = float(np.min(np.concatenate(span))), float(np.max(np.concatenate(span)))
        pad = 0.15 * (b - a) if b > a else 0.05 * max(abs(a), 1e-6)
        ax.set_ylim(a - pad, b + pad)
        ax.set_ylabel(f"({units.get(names[j], 'SI')})", fontsize=8)
        ax.set_title(names[j], fontsize=10)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=8)
    for ax in axes[-ncols:]:
        ax.set_xlabel("simulation time (s)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncols=len(labels), fontsize=9)
    fig.suptitle(f"{kind} term: RLS estimate over time with ±2σ and the truth (positive = "
                 "dissipative)")
    return save_figure(fig, path, bottom=0.55 / fig.get_figheight() + 0.06, wspace=0.3, hspace=0.4)


def _tracking_figure(tr: Tracking, path: Path) -> str:
    fig = Figure(figsize=(11, 2.3 * len(tr.dofs) + 1.3))
    axes = np.atleast_1d(fig.subplots(len(tr.dofs), 1, sharex=True, squeeze=False).ravel())
    colours = ("tab:red", "tab:blue", "tab:green", "tab:purple")
    for ax, i in zip(axes, tr.dofs, strict=True):
        ax.plot(tr.t, tr.nu_ref[:, i], color="k", ls="--", lw=1.0, label="reference")
        per_dof = []
        for (label, nu), c in zip(tr.nu.items(), colours, strict=False):
            ax.plot(tr.t, nu[:, i], color=c, lw=1.1, label=label)
            e = tr.nu_ref[tr.skip:, i] - nu[tr.skip:, i]
            per_dof.append(f"{label} {np.sqrt(np.mean(e * e)):.4f} {VEL_UNITS[i]}")
        ax.axvspan(tr.t[0], tr.t[tr.skip], color="0.9", lw=0)
        ax.set_ylabel(f"{DOF_NAMES[i]} ({VEL_UNITS[i]})")
        ax.set_title("RMS error: " + ", ".join(per_dof), fontsize=9)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncols=len(labels), fontsize=9)
    total = "; ".join(f"{k}: {_rms_text(v, tr.dofs)}" for k, v in tr.rms.items())
    fig.suptitle(f"Velocity PI (bandwidth {tr.bandwidth:g} rad/s) on the simulator, without "
                 f"and with the model feed-forward (grey: transient, not counted)\nRMS error "
                 f"{total}", fontsize=10)
    return save_figure(fig, path, bottom=0.45 / fig.get_figheight() + 0.05, hspace=0.35,
                 title_height=0.85)


def write_convergence_report(out_dir: str | Path, names: Sequence[str], t: FloatArray,
                             theta: FloatArray, std: FloatArray,
                             groups: Mapping[str, Sequence[str]], truth: Values | None = None,
                             batch: Values | None = None, tracking: Tracking | None = None,
                             summary: Sequence[tuple[str, str]] = (), title: str = "",
                             units: Mapping[str, str] | None = None) -> Path:
    """Write ``index.html``, PNG figures and ``convergence.csv`` for an online identification.

    Parameters
    ----------
    out_dir : str or Path
        Directory (created if needed); existing report files in it are overwritten.
    names : sequence of str, length p
        Parameter names, θ order.
    t : ndarray, shape (K,)
        Times of the recorded estimates (s).
    theta, std : ndarray, shape (K, p)
        The estimate and its standard deviation at each time (SI units).
    groups : mapping term kind → parameter names
        One convergence figure per entry (e.g. ``linear``, ``quadratic``).
    truth, batch : array of shape (p,) or mapping name → value, optional
        True coefficients (simulated data) and a batch estimate to compare the last
        estimate with.
    tracking : Tracking, optional
        Closed-loop runs for the tracking figure.
    summary : sequence of (str, str)
        Rows of the summary table.
    title : str
        Heading of the report.
    units : mapping name → str, optional
        SI unit of each parameter (:func:`parameter_units`), shown on the axes; ``SI``
        where not given.

    Returns
    -------
    Path
        The written ``index.html``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    names = list(names)
    t, theta, std = (np.asarray(a, dtype=float) for a in (t, theta, std))
    if theta.shape != (len(t), len(names)) or std.shape != theta.shape:
        raise ValueError(f"theta and std need shape {(len(t), len(names))}, got "
                         f"{theta.shape} and {std.shape}")
    truth_v, batch_v = aligned(truth, names), aligned(batch, names)
    _write_csv(out / "convergence.csv", names, t, theta, std)
    heading = html.escape(title or "Online identification")
    parts = [
        *html_head(heading),
        f'<p class="meta">generated {generated_utc()} · dampest_ros</p>',
        "<h2>Summary</h2>",
        html_table(["", ""], [[html.escape(k), html.escape(v)] for k, v in summary]),
        f"<h2>Final estimate (t = {t[-1]:.1f} s)</h2>",
        '<p class="note">Recursive least squares on the live samples; damping coefficients '
        "in SI units, positive when dissipative. The batch column is the least-squares fit "
        "on the same samples, all weighted equally. The coverage is the share of the "
        "recorded instants of the second half of the run at which the truth lay within "
        "±2σ of the estimate (about 95 % when σ is right). The estimate over time, from the "
        "prior at t = 0, is in <code>convergence.csv</code>.</p>",
        _final_table(names, t, theta, std, truth_v, batch_v),
        "<h2>Convergence</h2>",
        *_convergence_images(out, names, t, theta, std, groups, truth_v, units or {}),
    ]
    if tracking is not None:
        parts += _tracking_section(tracking, out)
    parts.append("</body></html>")
    return write_index(out, parts)


def _write_csv(path: Path, names: list[str], t: FloatArray, theta: FloatArray,
               std: FloatArray) -> None:
    """Write the estimate over time as CSV: columns ``t`` (s), the p parameters and their
    ``_std``; ``t`` has shape (K,), ``theta`` and ``std`` shape (K, p)."""
    header = ",".join(["t"] + names + [f"{n}_std" for n in names])
    np.savetxt(path, np.column_stack([t, theta, std]), delimiter=",", header=header,
               comments="", fmt="%.9g")


def _convergence_images(out: Path, names: list[str], t: FloatArray, theta: FloatArray,
                        std: FloatArray, groups: Mapping[str, Sequence[str]],
                        truth_v: FloatArray | None, units: Mapping[str, str]) -> list[str]:
    """Draw one convergence figure per term kind of ``groups`` into ``out``; their ``<img>``
    tags.

    ``t`` has shape (K,) (s), ``theta`` and ``std`` shape (K, p), ``truth_v`` shape (p,);
    ``units`` gives each parameter's SI unit.
    """
    figs = []
    for kind, members in groups.items():
        idx = [names.index(n) for n in members]
        png = _convergence_figure(kind, members, t, theta[:, idx], std[:, idx],
                                  truth_v[idx] if truth_v is not None else None,
                                  units, out / f"convergence_{kind}.png")
        figs.append(f'<img src="{png}" alt="{html.escape(kind)} coefficients over time">')
    return figs


def _final_table(names: list[str], t: FloatArray, theta: FloatArray, std: FloatArray,
                 truth_v: FloatArray | None, batch_v: FloatArray | None) -> str:
    """The table of the final estimate: value and std, error against the truth, whether the
    truth lies within ±2σ, the ±2σ coverage over the last half (:func:`band_coverage`), and
    the batch estimate with its error.

    ``t`` has shape (K,) (s), ``theta`` and ``std`` shape (K, p), ``truth_v`` and ``batch_v``
    shape (p,).
    """
    head = ["parameter", "estimate", "std", "truth", "error %", "truth within ±2σ",
            "±2σ coverage, last half"]
    coverage = (band_coverage(t, theta, std, truth_v) if truth_v is not None
                else np.full(len(names), np.nan))
    if batch_v is not None:
        head += ["batch (same samples)", "batch error %"]
    rows = []
    for j, name in enumerate(names):
        tr = truth_v[j] if truth_v is not None else np.nan
        err = (theta[-1, j] - tr) / tr * 100 if tr and np.isfinite(tr) else np.nan
        inside = abs(theta[-1, j] - tr) <= 2 * std[-1, j] if np.isfinite(tr) else None
        row = [html.escape(name), num(theta[-1, j]), num(std[-1, j], 3), num(tr),
               num(err, 3), "—" if inside is None else ("yes" if inside else "<b>no</b>"),
               "—" if np.isnan(coverage[j]) else f"{100 * coverage[j]:.0f} %"]
        if batch_v is not None:
            b_err = (batch_v[j] - tr) / tr * 100 if tr and np.isfinite(tr) else np.nan
            row += [num(batch_v[j]), num(b_err, 3)]
        rows.append(row)
    return html_table(head, rows)


def _tracking_section(tracking: Tracking, out: Path) -> list[str]:
    """The velocity-tracking heading, note, RMS table (one column per velocity unit) and
    figure (drawn into ``out``)."""
    dofs = ", ".join(DOF_NAMES[i] for i in tracking.dofs)
    by_unit = list(dict.fromkeys(u for r in tracking.rms.values() for u in r))
    return [
        "<h2>Velocity tracking with the identified model</h2>",
        '<p class="note">The per-DOF velocity PI of <code>controller_node</code> flies sine '
        f"references in {html.escape(dofs)} on the simulator (the true vehicle), alone "
        "and with the feed-forward D(ν<sub>ref</sub>)ν<sub>ref</sub> + "
        "C(ν<sub>ref</sub>)ν<sub>ref</sub> of the final model. RMS over the DOFs of "
        "each unit apart (m/s and rad/s are not added) after the first "
        f"{tracking.t[tracking.skip] - tracking.t[0]:.0f} s.</p>",
        html_table(["controller", *(f"RMS error ({u}; " + ", ".join(
            DOF_NAMES[i] for i in tracking.dofs if VEL_UNITS[i] == u) + ")"
            for u in by_unit)],
               [[html.escape(k), *(num(v.get(u, np.nan), 4) for u in by_unit)]
                for k, v in tracking.rms.items()]),
        f'<img src="{_tracking_figure(tracking, out / "tracking.png")}" '
        'alt="velocity tracking">',
    ]
