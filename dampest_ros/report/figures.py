"""Shared pieces of the HTML reports: units of coefficients and axes, the figures every report
draws (damping force, residual spectrum and autocorrelation, coefficients with intervals, free
run, excitation coverage), HTML tables, the style sheet and the page frame. Figures are drawn with
matplotlib's object API on the Agg canvas (no pyplot state, no display).
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from dampest_ros.core.identification import validate
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES

FloatArray = NDArray[np.float64]

FORCE_UNITS = ("N", "N", "N", "N·m", "N·m", "N·m")
VEL_UNITS = ("m/s", "m/s", "m/s", "rad/s", "rad/s", "rad/s")
DPI = 90
#: Most decades a PSD axis shows below its largest value (beyond: filter roll-off and
#: round-off, of no interest).
PSD_DECADES = 8

#: SI dimensions as exponents of (N, m, s, rad): a force row's unit and a velocity's.
_Dims = tuple[int, int, int, int]
_FORCE_DIMS: tuple[_Dims, ...] = ((1, 0, 0, 0),) * 3 + ((1, 1, 0, 0),) * 3
_VEL_DIMS: tuple[_Dims, ...] = ((0, 1, -1, 0),) * 3 + ((0, 0, -1, 1),) * 3
_SUPERSCRIPT = {2: "²", 3: "³", 4: "⁴"}



def _unit_text(dims: _Dims) -> str:
    """``N·s/m``-style text of exponents of (N, m, s, rad); ``1`` when dimensionless."""
    def part(sign: int) -> str:
        return "·".join(sym + _SUPERSCRIPT.get(abs(e), "" if abs(e) == 1 else f"^{abs(e)}")
                        for sym, e in zip(("N", "m", "s", "rad"), dims, strict=True)
                        if e * sign > 0)
    top, bottom = part(1) or "1", part(-1)
    return f"{top}/{bottom}" if bottom else top


def _sub(a: _Dims, b: _Dims) -> _Dims:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2], a[3] - b[3])


def _alpha_dims(alpha: object) -> _Dims | None:
    """Dimensions of a velocity function α(ν) (None: mixes units, e.g. a 6-D mode)."""
    kind, i, j = (getattr(alpha, "kind", ""), int(getattr(alpha, "i", -1)),
                  int(getattr(alpha, "j", -1)))
    if kind == "one":
        return (0, 0, 0, 0)
    if kind in ("abs", "lin", "area") or (kind == "pnorm" and _VEL_DIMS[i] == _VEL_DIMS[j]):
        return _VEL_DIMS[i]
    if kind == "norm":
        return _VEL_DIMS[0]
    if kind == "anorm":
        return _VEL_DIMS[3]
    if kind in ("prod", "absprod"):
        a, b = _VEL_DIMS[i], _VEL_DIMS[j]
        return (a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3])
    return None


def parameter_units(model: DampingModel) -> dict[str, str]:
    """SI unit of every parameter of a damping model, by name.

    A static coefficient θ multiplies α(ν) ν_c in force row r: its unit is
    [F_r] / ([α] [ν_c]) (e.g. X_u N·s/m, X_uu N·s²/m², N_r N·m·s/rad); a memory gain c of
    K(t) = c e^(−λt) acting on ν_d in row d has [F_d] / ([ν_d] s). Bases that mix units
    (a residual mode over several DOFs) are ``SI``.
    """
    units: dict[str, str] = {}
    for term in model.terms:
        if term.kind == "freq":
            for name, d in zip(term.parameter_names, term.state_dofs, strict=True):
                dims = _sub(_sub(_FORCE_DIMS[int(d)], _VEL_DIMS[int(d)]), (0, 0, 1, 0))
                units[name] = _unit_text(dims)
            continue
        if term.kind == "point":
            # an element's drag or lift c ‖v_p‖ v_p,a (its moments follow from the lever arm):
            # N s²/m²; its Magnus force c ω × v_p: N s²/(m rad)
            dims = _sub(_sub(_FORCE_DIMS[0], _VEL_DIMS[0]), _VEL_DIMS[0])
            spin = _sub(_sub(_FORCE_DIMS[0], _VEL_DIMS[3]), _VEL_DIMS[0])
            units.update({n: _unit_text(spin if n.startswith("magnus") else dims)
                          for n in term.parameter_names})
            continue
        for b in term.bases:
            # [F_row] / ([α] [ν_col]) over every entry of every atom; one unit or "SI"
            found: set[_Dims | None] = set()
            for B, alpha in b.atoms:
                rows, cols = np.nonzero(np.asarray(B))
                a = _alpha_dims(alpha)
                found |= {None if a is None else _sub(_sub(_FORCE_DIMS[r], _VEL_DIMS[c]), a)
                          for r, c in zip(rows, cols, strict=True)}
            unit = found.pop() if len(found) == 1 else None
            units[b.name] = _unit_text(unit) if unit is not None else "SI"
    return units


Values = FloatArray | Sequence[float] | Mapping[str, float]


def aligned(values: Values | None, names: Sequence[str]) -> FloatArray | None:
    """Values in ``names`` order (NaN where a mapping lacks a name), or None."""
    if values is None:
        return None
    if isinstance(values, Mapping):
        return np.array([float(values.get(n, np.nan)) for n in names])
    a = np.asarray(values, dtype=float)
    if a.shape != (len(names),):
        raise ValueError(f"expected {len(names)} values (one per parameter), got {a.shape}")
    return a


def grid(n: int, ncols: int = 3) -> tuple[int, int]:
    return max(1, -(-n // ncols)), ncols


def save_figure(fig: Figure, path: Path, bottom: float = 0.08, wspace: float = 0.22,
          hspace: float = 0.3, title_height: float = 0.6) -> str:
    # fixed margins (constrained layout would double the drawing time); title_height inches
    # for the title
    fig.subplots_adjust(left=0.08, right=0.985, bottom=bottom,
                        top=1.0 - title_height / fig.get_figheight(), wspace=wspace,
                        hspace=hspace)
    fig.savefig(path, dpi=DPI, format="png")
    return path.name


def measured_vs_model(t: FloatArray, measured: FloatArray, model: FloatArray,
                      labels: tuple[str, str], names: Sequence[str], units: Sequence[str],
                      title: str, path: Path) -> str:
    """n signals in two columns (six DOFs: surge…heave left, roll…yaw right), each a panel
    of a measured signal and its model's, shapes (N, n), against time t (s), over a panel of
    the residual measured − model in the same unit. Tick labels are plain numbers:
    matplotlib's offset text (×10ⁿ, +c) would sit on the panel above."""
    n = measured.shape[1]
    rows = -(-n // 2)
    fig = Figure(figsize=(11, 9.5 * rows / 3))
    grid_spec = fig.add_gridspec(2 * rows, 2, height_ratios=[3, 1.2] * rows)
    first = fig.add_subplot(grid_spec[0, 0])
    for i in range(n):
        row, col = 2 * (i % rows), i // rows
        last = row == 2 * rows - 2 or i == n - 1
        ax = first if i == 0 else fig.add_subplot(grid_spec[row, col], sharex=first)
        res = fig.add_subplot(grid_spec[row + 1, col], sharex=first)
        ax.plot(t, measured[:, i], lw=1.0, color="0.2", label=labels[0])
        ax.plot(t, model[:, i], lw=1.0, color="tab:red", alpha=0.85, label=labels[1])
        ax.set_ylabel(f"{names[i]} ({units[i]})")
        ax.legend(loc="upper right", fontsize=7, ncols=2, framealpha=0.7)
        ax.tick_params(labelbottom=False)
        res.plot(t, measured[:, i] - model[:, i], lw=0.8, color="tab:blue",
                 label=f"{labels[0]} − {labels[1]}")
        res.axhline(0.0, color="0.5", lw=0.6)
        res.set_ylabel(f"resid. ({units[i]})", fontsize=8)
        res.legend(loc="upper right", fontsize=7, framealpha=0.7)
        res.tick_params(labelbottom=last)
        for a in (ax, res):
            a.ticklabel_format(axis="y", style="plain", useOffset=False)
            a.grid(alpha=0.3)
        if last:
            res.set_xlabel("time (s)")
    fig.suptitle(title)
    return save_figure(fig, path, bottom=0.06, hspace=0.15, wspace=0.25)


def force_figure(t: FloatArray, y: FloatArray, y_hat: FloatArray, path: Path) -> str:
    return measured_vs_model(
        t, y, y_hat, ("measured y", "model Φθ"), FORCE_NAMES, FORCE_UNITS,
        "Damping force: measured y = τ − Mν̇ − C(ν)ν − g(η) vs model Φ(ν)θ", path)


def spectrum_figure(f: FloatArray, p_y: FloatArray, p_r: FloatArray, cutoff: float,
                     path: Path) -> str:
    fig = Figure(figsize=(11, 7))
    axes = fig.subplots(3, 2, sharex=True).T.ravel()
    for i, ax in enumerate(axes):
        ax.loglog(f[1:], p_y[1:, i], lw=1.0, color="0.5", label="measured force")
        ax.loglog(f[1:], p_r[1:, i], lw=1.0, color="tab:red", label="residual")
        if cutoff > 0:
            ax.axvline(cutoff, color="k", ls=":", lw=0.8)
        f_hi = min(float(f[-1]), 5 * cutoff) if cutoff > 0 and len(f) > 1 else float(f[-1])
        band = (f > 0) & (f <= f_hi)
        ax.set_ylim(*psd_limits([p_y[band, i], p_r[band, i]]))
        if cutoff > 0 and len(f) > 1:
            ax.set_xlim(f[1], f_hi)
        ax.set_ylabel(f"{FORCE_NAMES[i]} PSD ({psd_unit(i)})")
        ax.grid(alpha=0.3, which="both")
    axes[2].set_xlabel("frequency (Hz)")
    axes[5].set_xlabel("frequency (Hz)")
    axes[0].legend(loc="lower left", fontsize=8)
    fig.suptitle("Welch PSD of the measured force and of the residual"
                 + (f" (dotted: fit low-pass {cutoff:g} Hz)" if cutoff > 0 else ""))
    return save_figure(fig, path)


def acf_figure(w: validate.Whiteness, path: Path) -> str:
    fig = Figure(figsize=(11, 7))
    axes = fig.subplots(3, 2, sharex=True, sharey=True).T.ravel()
    for i, ax in enumerate(axes):
        ax.vlines(w.lags[1:], 0, w.acf[1:, i], color="tab:blue", lw=1.5)
        ax.axhspan(-w.bound, w.bound, color="tab:green", alpha=0.2, lw=0)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_ylabel(f"ACF {FORCE_NAMES[i]} (unitless)")
        ax.set_title(f"{w.fraction_outside[i]:.0%} of lags outside ±{w.bound:.3f}",
                     fontsize=9)
        ax.grid(alpha=0.3)
    axes[2].set_xlabel("lag (s)")
    axes[5].set_xlabel("lag (s)")
    fig.suptitle("Residual autocorrelation with 95 % whiteness bounds ±1.96/√N (shaded)")
    return save_figure(fig, path)


def psd_limits(curves: Sequence[FloatArray]) -> tuple[float, float]:
    """y limits of a log PSD axis for the given spectra (each the values in the frequency
    band shown): from just under the lowest curve's 5th percentile, at most
    :data:`PSD_DECADES` below the peak, to 3 × the peak."""
    values = np.concatenate([np.asarray(c, dtype=float).ravel() for c in curves])
    values = values[np.isfinite(values) & (values > 0)]
    if values.size == 0:
        return 1e-12, 1.0
    top = float(values.max())
    floor = min(float(np.percentile(np.asarray(c)[np.asarray(c) > 0], 5))
                for c in curves if np.any(np.asarray(c) > 0))
    return max(top * 10.0 ** -PSD_DECADES, 0.5 * floor), 3.0 * top


def psd_unit(i: int) -> str:
    """Unit of the power spectral density of force row i: N²/Hz or (N·m)²/Hz."""
    unit = FORCE_UNITS[i] if i < 3 else f"({FORCE_UNITS[i]})"
    return f"{unit}²/Hz"


def coef_figure(names: Sequence[str], est: FloatArray, ci: FloatArray,
                 held: NDArray[np.bool_], identified: NDArray[np.bool_],
                 prior: FloatArray | None, truth: FloatArray | None,
                 units: Mapping[str, str], path: Path, prior_label: str = "prior",
                 title: str = "Coefficients (SI units on each axis, positive = dissipative)"
                 ) -> str:
    """One panel per parameter (its unit on the y axis): estimate with its 95 % interval,
    prior (called ``prior_label``), truth; a parameter held at its prior shows no estimate,
    one the data do not determine has a red title."""
    nrows, ncols = grid(len(names), 6)
    fig = Figure(figsize=(13, 1.9 * nrows + 0.8))
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False).ravel())
    for j, ax in enumerate(axes):
        if j >= len(names):
            ax.set_visible(False)
            continue
        name = names[j]
        if not held[j] and np.all(np.isfinite(ci[j])):
            ax.errorbar([0], [est[j]], yerr=[[est[j] - ci[j, 0]], [ci[j, 1] - est[j]]],
                        fmt="o", color="tab:blue", capsize=4, label="estimate, 95 %")
        elif not held[j]:
            ax.plot([0], [est[j]], "o", color="tab:blue", label="estimate")
        else:
            ax.text(0.5, 0.5, "held at prior", transform=ax.transAxes, ha="center",
                    va="center", color="tab:red", fontsize=9)
        if prior is not None and np.isfinite(prior[j]):
            ax.plot([-0.6], [prior[j]], "s", color="0.4", label=prior_label)
        if truth is not None and np.isfinite(truth[j]):
            ax.plot([0.6], [truth[j]], "*", color="tab:orange", ms=11, label="truth")
        ax.set_xlim(-1, 1)
        ticks = [(x, lab) for x, lab, shown in ((-0.6, prior_label, prior is not None),
                                                 (0.0, "est.", True),
                                                 (0.6, "truth", truth is not None)) if shown]
        ax.set_xticks([x for x, _ in ticks], [lab for _, lab in ticks], fontsize=7)
        if not ax.lines and not ax.collections:
            ax.set_yticks([])  # nothing to show: no meaningless 0…1 scale
        ax.set_ylabel(f"({units.get(name, 'SI')})", fontsize=8, labelpad=1)
        ax.set_title(name, fontsize=10, color="k" if identified[j] else "tab:red")
        ax.grid(alpha=0.3, axis="y")
        ax.tick_params(labelsize=8)
    handles, labels = [], []
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    if handles:
        fig.legend(handles, labels, loc="lower center", ncols=len(labels), fontsize=9)
    fig.suptitle(title, y=1.0 - 0.1 / fig.get_figheight())  # above the panels' titles
    return save_figure(fig, path, bottom=0.5 / fig.get_figheight() + 0.05, wspace=0.6,
                 hspace=0.45, title_height=0.8)


def free_run_figure(t: FloatArray, nu: FloatArray, sim: FloatArray, path: Path) -> str:
    return measured_vs_model(
        t, nu, sim, ("measured ν", "free run"), DOF_NAMES, VEL_UNITS,
        "Free-run simulation driven by the measured τ and attitude vs measured ν", path)


def coverage_figure(nu: FloatArray, path: Path) -> str:
    fig = Figure(figsize=(11, 5.5))
    axes = fig.subplots(2, 3).ravel()
    for i, ax in enumerate(axes):
        ax.hist(nu[:, i], bins=60, color="tab:blue", alpha=0.8)
        lo, hi = np.percentile(nu[:, i], [1, 99]) if len(nu) else (0.0, 0.0)
        ax.axvline(lo, color="k", ls=":", lw=0.8)
        ax.axvline(hi, color="k", ls=":", lw=0.8)
        ax.set_xlabel(f"{DOF_NAMES[i]} ({VEL_UNITS[i]})")
        ax.set_ylabel("samples (count)")
        ax.set_title(f"1–99 %: [{lo:.3g}, {hi:.3g}]", fontsize=9)
        ax.grid(alpha=0.3)
    fig.suptitle("Excitation coverage: distribution of each velocity component")
    return save_figure(fig, path, bottom=0.1, hspace=0.5)


def num(x: float, digits: int = 4) -> str:
    if not np.isfinite(x):
        return "—" if np.isnan(x) else ("∞" if x > 0 else "−∞")
    return f"{x:.{digits}g}"


def html_table(header: Sequence[str], rows: Sequence[Sequence[str]],
           classes: Sequence[str] | None = None) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = []
    for k, row in enumerate(rows):
        cls = f' class="{classes[k]}"' if classes and classes[k] else ""
        body.append(f"<tr{cls}>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1200px;
margin:2em auto;padding:0 1em;color:#222;line-height:1.45}
h1{margin-bottom:.1em}.meta{color:#666;margin-top:0}
table{border-collapse:collapse;margin:.6em 0 1.2em;font-size:.92em}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right}
th{background:#f2f2f2}td:first-child,th:first-child{text-align:left}
tr.flag td{background:#fff1f0}td.reason{text-align:left;max-width:34em;font-size:.9em}
img{max-width:100%;border:1px solid #ddd;margin:.3em 0 1em}
.note{color:#555;font-size:.92em;max-width:60em}
"""


def html_head(heading: str) -> list[str]:
    """The lines of a report page up to its ``<h1>``: doctype, title and :data:`CSS`.

    ``heading`` is HTML (escaped by the caller); it is both the title and the ``<h1>``.
    """
    return ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
            f"<title>{heading}</title><style>{CSS}</style></head><body>", f"<h1>{heading}</h1>"]


def generated_utc() -> str:
    """The current time for a report's header, e.g. ``2024-05-01 12:00:00 UTC``."""
    return datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


def write_index(out: Path, parts: Sequence[str]) -> Path:
    """Write the lines ``parts`` as ``out/index.html`` (UTF-8) and return its path."""
    index = out / "index.html"
    index.write_text("\n".join(parts), encoding="utf-8")
    return index
