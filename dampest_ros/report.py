"""HTML reports: plots and tables in one directory.

``write_report`` (a batch identification) writes ``index.html`` and PNG figures (relative
links, so the directory can be copied or zipped as is): measured vs predicted damping force,
residual spectrum and autocorrelation with whiteness bounds, coefficients with 95 % intervals
vs a prior (and a truth when known), a free-run velocity overlay, excitation coverage, and
the tables of coefficients and metrics (:mod:`dampest_ros.core.validate`).

``write_convergence_report`` (an online identification) writes the estimate of each
coefficient over time with its ±2σ band and the truth, one figure per damping term, and a
controller's velocity tracking without and with the model's feed-forward.

Figures are drawn with matplotlib's object API on the Agg canvas (no pyplot state, no
display); never imports rclpy.
"""

from __future__ import annotations

import html
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from dampest_ros.core import validate
from dampest_ros.core.batch import Fit
from dampest_ros.core.control import tracking_rms
from dampest_ros.core.damping import DampingModel
from dampest_ros.core.rigid_body import DOF_NAMES, FORCE_NAMES, RigidBody
from dampest_ros.core.samples import Samples

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


def _aligned(values: Values | None, names: Sequence[str]) -> FloatArray | None:
    """Values in ``names`` order (NaN where a mapping lacks a name), or None."""
    if values is None:
        return None
    if isinstance(values, Mapping):
        return np.array([float(values.get(n, np.nan)) for n in names])
    a = np.asarray(values, dtype=float)
    if a.shape != (len(names),):
        raise ValueError(f"expected {len(names)} values (one per parameter), got {a.shape}")
    return a


def _grid(n: int, ncols: int = 3) -> tuple[int, int]:
    return max(1, -(-n // ncols)), ncols


def _save(fig: Figure, path: Path, bottom: float = 0.08, wspace: float = 0.22,
          hspace: float = 0.3, title_height: float = 0.6) -> str:
    # fixed margins (constrained layout would double the drawing time); title_height inches
    # for the title
    fig.subplots_adjust(left=0.08, right=0.985, bottom=bottom,
                        top=1.0 - title_height / fig.get_figheight(), wspace=wspace,
                        hspace=hspace)
    fig.savefig(path, dpi=DPI, format="png")
    return path.name


def _force_figure(t: FloatArray, y: FloatArray, y_hat: FloatArray, path: Path) -> str:
    fig = Figure(figsize=(11, 7.5))
    axes = fig.subplots(3, 2, sharex=True).T.ravel()
    for i, ax in enumerate(axes):
        ax.plot(t, y[:, i], lw=1.0, color="0.2", label="measured y")
        ax.plot(t, y_hat[:, i], lw=1.0, color="tab:red", alpha=0.85, label="predicted Φθ")
        ax.set_ylabel(f"{FORCE_NAMES[i]} ({FORCE_UNITS[i]})")
        ax.grid(alpha=0.3)
    axes[2].set_xlabel("time (s)")
    axes[5].set_xlabel("time (s)")
    axes[0].legend(loc="upper right", fontsize=8)
    fig.suptitle("Damping force: measured y = τ − Mν̇ − C(ν)ν − g(η) vs model Φ(ν)θ")
    return _save(fig, path)


def _spectrum_figure(f: FloatArray, p_y: FloatArray, p_r: FloatArray, cutoff: float,
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
    return _save(fig, path)


def _acf_figure(w: validate.Whiteness, path: Path) -> str:
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
    return _save(fig, path)


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


def _coef_figure(names: Sequence[str], est: FloatArray, ci: FloatArray,
                 held: NDArray[np.bool_], identified: NDArray[np.bool_],
                 prior: FloatArray | None, truth: FloatArray | None,
                 units: Mapping[str, str], path: Path) -> str:
    """One panel per parameter (its unit on the y axis): estimate with its 95 % interval,
    prior, truth; a parameter held at its prior shows no estimate, one the data do not
    determine has a red title."""
    nrows, ncols = _grid(len(names), 6)
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
            ax.plot([-0.6], [prior[j]], "s", color="0.4", label="prior")
        if truth is not None and np.isfinite(truth[j]):
            ax.plot([0.6], [truth[j]], "*", color="tab:orange", ms=11, label="truth")
        ax.set_xlim(-1, 1)
        ticks = [(x, lab) for x, lab, shown in ((-0.6, "prior", prior is not None),
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
    fig.suptitle("Coefficients (SI units on each axis, positive = dissipative)")
    return _save(fig, path, bottom=0.5 / fig.get_figheight() + 0.05, wspace=0.6,
                 hspace=0.45)


def _free_run_figure(t: FloatArray, nu: FloatArray, sim: FloatArray, path: Path) -> str:
    fig = Figure(figsize=(11, 7.5))
    axes = fig.subplots(3, 2, sharex=True).T.ravel()
    for i, ax in enumerate(axes):
        ax.plot(t, nu[:, i], lw=1.0, color="0.2", label="measured ν")
        ax.plot(t, sim[:, i], lw=1.0, color="tab:red", alpha=0.85, label="free run")
        ax.set_ylabel(f"{DOF_NAMES[i]} ({VEL_UNITS[i]})")
        ax.grid(alpha=0.3)
    axes[2].set_xlabel("time (s)")
    axes[5].set_xlabel("time (s)")
    axes[0].legend(loc="upper right", fontsize=8)
    fig.suptitle("Free-run simulation driven by the measured τ and attitude vs measured ν")
    return _save(fig, path)


def _coverage_figure(nu: FloatArray, path: Path) -> str:
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
    return _save(fig, path, bottom=0.1, hspace=0.5)


def _num(x: float, digits: int = 4) -> str:
    if not np.isfinite(x):
        return "—" if np.isnan(x) else ("∞" if x > 0 else "−∞")
    return f"{x:.{digits}g}"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]],
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


def write_report(out_dir: str | Path, samples: Samples, model: DampingModel, body: RigidBody,
                 fit: Fit, prior: Values | None = None, truth: Values | None = None,
                 title: str = "", *, source: str = "", cutoff: float = 2.0,
                 tau_hold: str = "linear", force_seconds: float = 60.0,
                 free_run_seconds: float = 120.0,
                 heldout: Mapping[str, FloatArray] | None = None,
                 heldout_note: str = "") -> Path:
    """Write ``index.html`` and its PNG figures for one identification.

    Parameters
    ----------
    out_dir : str or Path
        Directory (created if needed); existing report files in it are overwritten.
    samples : Samples
        The data the model was identified from (or held-out data to validate on).
    model : DampingModel
        Term structure of ``fit``.
    body : RigidBody
        M and restoring data used by the fit.
    fit : Fit
        Result of :func:`dampest_ros.core.batch.fit`; ``fit.flags`` marks unidentified
        parameters, which are shown as such, not as numbers.
    prior : array of shape (p,) or mapping name → value, optional
        Prior / nominal coefficients to compare with.
    truth : array of shape (p,) or mapping name → value, optional
        True coefficients (simulated data).
    title : str
        Heading of the report.
    source : str
        Name of the input (bag directory or CSV file), shown in the header.
    cutoff : float
        The fit's parallel low-pass (Hz), so that predicted and measured force are compared
        as the fit saw them; 0: unfiltered.
    tau_hold : {'linear', 'zero'}
        τ between samples in the free run (see :func:`dampest_ros.core.validate.free_run`).
    force_seconds, free_run_seconds : float
        Length of the force plot and of the free run (s), from the start of the longest
        segment.
    heldout : mapping of str to ndarray, each shape (6,), optional
        :func:`dampest_ros.core.validate.metrics` of the damping force on data the fit did
        not use (``nse`` is shown as R², ``rmse`` in N and N·m).
    heldout_note : str
        What was held out, in words.

    Returns
    -------
    Path
        The written ``index.html``.
    """
    t_start = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    names = list(fit.names)
    theta = np.asarray(fit.theta, dtype=float)
    prior_v, truth_v = _aligned(prior, names), _aligned(truth, names)
    rate = samples.rate
    N = len(samples)

    # --- validation numbers ----------------------------------------------------------------
    y, y_hat = validate.predicted_force(samples, model, body, theta, cutoff)
    r = y - y_hat
    met = validate.metrics(y, y_hat, samples.nu_dot, rate)
    # the fit low-passed y and Φ at `cutoff`: decimate the residual to ≈ 2·cutoff so that
    # the whiteness test asks whether what is left in the fitted band is white
    dec = max(1, int(rate // (2 * cutoff))) if cutoff > 0 else 1
    white = validate.residual_whiteness(r[::dec], rate / dec, max_lag=min(5.0, N / rate / 4))
    f, p_r = validate.residual_spectrum(r, rate)
    _, p_y = validate.residual_spectrum(y, rate)
    try:
        frf: validate.FrfError | None = validate.frf_error(
            samples, y, y_hat, rate, f_max=cutoff if cutoff > 0 else None)
    except ValueError:
        frf = None
    rows = validate.longest_segment(samples, free_run_seconds)
    sim = validate.free_run(samples, model, body, theta, rows, tau_hold)
    fr_met = validate.metrics(samples.nu[rows], np.where(np.isfinite(sim), sim, np.inf))
    neg_share, min_power = validate.energy_consistency(samples, model, theta)

    # --- figures ---------------------------------------------------------------------------
    seg = validate.longest_segment(samples, force_seconds)
    t0 = float(samples.t[seg.start])
    figs = {
        "force": _force_figure(samples.t[seg] - t0, y[seg], y_hat[seg], out / "force.png"),
        "spectrum": _spectrum_figure(f, p_y, p_r, cutoff, out / "residual_spectrum.png"),
        "acf": _acf_figure(white, out / "residual_acf.png"),
        "coef": _coef_figure(names, theta, fit.interval(), fit.held, fit.identified, prior_v,
                             truth_v, parameter_units(model), out / "coefficients.png"),
        "free_run": _free_run_figure(samples.t[rows] - float(samples.t[rows.start]),
                                     samples.nu[rows], sim, out / "free_run.png"),
        "coverage": _coverage_figure(samples.nu, out / "coverage.png"),
    }

    # --- tables ----------------------------------------------------------------------------
    ci = fit.interval()
    std = fit.std
    header = ["parameter", "estimate", "std", "95 % low", "95 % high", "prior"]
    if truth_v is not None:
        header += ["truth", "truth in 95 %"]
    header.append("note")
    coef_rows, coef_cls = [], []
    for j, name in enumerate(names):
        flagged = not fit.identified[j]
        row = [html.escape(name)]
        if fit.held[j]:
            row += ["held at prior", "", "", ""]
        else:
            row += [_num(theta[j]), _num(std[j], 3), _num(ci[j, 0]), _num(ci[j, 1])]
        row.append(_num(prior_v[j]) if prior_v is not None else "—")
        if truth_v is not None:
            row.append(_num(truth_v[j]))
            inside = (not flagged and np.isfinite(truth_v[j])
                      and ci[j, 0] <= truth_v[j] <= ci[j, 1])
            row.append("" if flagged else ("yes" if inside else "<b>no</b>"))
        why = fit.flags.get(name) or fit.constrained.get(name, "")
        row.append(f'<span class="reason">{html.escape(why)}</span>')
        coef_rows.append(row)
        coef_cls.append("flag" if flagged else "")

    force_rows = []
    for i in range(6):
        g = frf.median_gain_db[i] if frf is not None else np.nan
        ph = frf.median_phase_deg[i] if frf is not None else np.nan
        force_rows.append([
            f"{FORCE_NAMES[i]} ({FORCE_UNITS[i]})", _num(met["rmse"][i]),
            _num(met["nrmse"][i], 3), _num(met["nse"][i], 5), _num(met["peak_error"][i]),
            _num(met["steady_bias"][i], 3), f"{met['steady_fraction'][i]:.0%}",
            _num(fit.cv_rmse[i]), _num(g, 3), _num(ph, 3),
            f"{white.fraction_outside[i]:.0%}"])
    vel_rows = [[f"{DOF_NAMES[i]} ({VEL_UNITS[i]})", _num(fr_met["rmse"][i], 3),
                 _num(fr_met["nrmse"][i], 3), _num(fr_met["nse"][i], 4),
                 _num(fr_met["peak_error"][i], 3)] for i in range(6)]

    n_seg = int(np.unique(samples.segment).size)
    duration = N / rate if rate else 0.0
    fr_len = (rows.stop - rows.start - 1) / rate if rate else 0.0
    summary = _table(["", ""], [
        ["input", html.escape(source or "—")],
        ["samples", f"{N} at {rate:.4g} Hz ({duration:.1f} s in {n_seg} segment(s))"],
        ["method", html.escape(fit.method)],
        ["regression low-pass", f"{cutoff:g} Hz" if cutoff > 0 else "none"],
        ["condition number (scaled)", _num(fit.cond, 3)],
        ["effective samples n_eff", _num(fit.n_eff, 4)],
        ["AIC / BIC", f"{_num(fit.aic, 6)} / {_num(fit.bic, 6)}"],
        ["parameters not identified",
         f"{int(np.sum(~fit.identified))} of {len(names)} ({int(np.sum(fit.held))} held at "
         "the prior)"],
        *[["identified combination", html.escape(str(c))] for c in fit.combinations],
        ["energy consistency νᵀD(ν)ν ≥ 0",
         f"{neg_share:.2%} of samples negative, minimum {_num(min_power, 3)} W"],
    ])
    generated = datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    heading = html.escape(title or f"Damping identification: {source or 'data'}")
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{heading}</title><style>{CSS}</style></head><body>",
        f"<h1>{heading}</h1>",
        f'<p class="meta">input <code>{html.escape(source or "—")}</code> · generated '
        f"{generated} · dampest_ros</p>",
        "<h2>Summary</h2>", summary,
        "<h2>Coefficients</h2>",
        '<p class="note">Fossen model M ν̇ + C(ν)ν + D(ν)ν + g(η) = τ, FRD body frame; '
        "damping coefficients in SI units, positive when dissipative. Intervals are 95 % "
        "(Student-t on the block-robust covariance, including the sensor-bias budget). "
        "Parameters the data cannot determine are reported as not identified, with the "
        "reason.</p>",
        _table(header, coef_rows, coef_cls),
        f'<img src="{figs["coef"]}" alt="coefficients with 95 % intervals">',
        "<h2>Force prediction</h2>",
        '<p class="note">Measured y = τ − M ν̇ − C(ν)ν − g(η) vs predicted Φ(ν)θ, both '
        "low-passed as in the fit. NRMSE = RMSE / std(y); NSE = 1 − Σr²/Σ(y − ȳ)²; peak "
        "= max |r|; steady bias = mean residual over stretches of ≥ 1 s where |ν̇ᵢ| ≤ 10 % of "
        "its RMS (— where there are none); CV RMSE from blocked cross-validation; FRF "
        "error = median over the excited band (τ coherence ≥ 0.5) of the gain (dB) and "
        "phase (deg) of S<sub>τŷ</sub>/S<sub>τy</sub>; whiteness = share of autocorrelation "
        f"lags outside ±1.96/√N on the residual decimated by {dec}.</p>",
        _table(["DOF", "RMSE", "NRMSE", "NSE", "peak error", "steady bias", "steady share",
                "CV RMSE", "FRF gain err (dB)", "FRF phase err (°)", "ACF outside"],
               force_rows),
        f'<p class="note">First {min(force_seconds, duration):.0f} s of the longest '
        "segment:</p>",
        f'<img src="{figs["force"]}" alt="measured vs predicted force">',
        *_heldout_section(heldout, heldout_note),
        "<h2>Residuals</h2>",
        f'<img src="{figs["spectrum"]}" alt="residual spectrum">',
        f'<img src="{figs["acf"]}" alt="residual autocorrelation">',
        "<h2>Free run</h2>",
        f'<p class="note">The model integrated (RK4 at the sample rate) from the measured ν '
        f"at the start of the longest segment for {fr_len:.0f} s, driven by the measured τ "
        "and attitude, with no feedback from the measured velocity.</p>",
        _table(["DOF", "RMSE", "NRMSE", "NSE", "peak error"], vel_rows),
        f'<img src="{figs["free_run"]}" alt="free-run velocity overlay">',
        "<h2>Excitation coverage</h2>",
        '<p class="note">Quadratic terms are only determined over the speeds the data cover; '
        "dotted lines: 1st and 99th percentiles.</p>",
        f'<img src="{figs["coverage"]}" alt="velocity histograms">',
        f'<p class="meta">Written in {time.perf_counter() - t_start:.1f} s.</p>',
        "</body></html>",
    ]
    index = out / "index.html"
    index.write_text("\n".join(parts), encoding="utf-8")
    return index


def _heldout_section(scores: Mapping[str, FloatArray] | None, note: str) -> list[str]:
    """The held-out table (R² and RMSE of the damping force per DOF), or nothing."""
    if scores is None:
        return []
    rows = [[f"{FORCE_NAMES[i]} ({FORCE_UNITS[i]})", _num(scores["nse"][i], 5),
             _num(scores["rmse"][i])] for i in range(6)]
    return ["<h2>Held-out data</h2>",
            f'<p class="note">Scored on {html.escape(note or "data the fit did not use")}: '
            "y = τ − M ν̇ − C(ν)ν − g(η) against the model's D(ν)ν, low-passed as in the fit; "
            "R² = 1 − Σr²/Σ(y − ȳ)².</p>",
            _table(["DOF", "held-out R²", "held-out RMSE"], rows)]


# --- online identification ------------------------------------------------------------------


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
    nrows, ncols = _grid(len(names), 3)
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
    return _save(fig, path, bottom=0.55 / fig.get_figheight() + 0.06, wspace=0.3, hspace=0.4)


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
    return _save(fig, path, bottom=0.45 / fig.get_figheight() + 0.05, hspace=0.35,
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
    truth_v, batch_v = _aligned(truth, names), _aligned(batch, names)
    header = ",".join(["t"] + names + [f"{n}_std" for n in names])
    np.savetxt(out / "convergence.csv", np.column_stack([t, theta, std]), delimiter=",",
               header=header, comments="", fmt="%.9g")
    figs = []
    for kind, members in groups.items():
        idx = [names.index(n) for n in members]
        png = _convergence_figure(kind, members, t, theta[:, idx], std[:, idx],
                                  truth_v[idx] if truth_v is not None else None,
                                  units or {}, out / f"convergence_{kind}.png")
        figs.append(f'<img src="{png}" alt="{html.escape(kind)} coefficients over time">')
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
        row = [html.escape(name), _num(theta[-1, j]), _num(std[-1, j], 3), _num(tr),
               _num(err, 3), "—" if inside is None else ("yes" if inside else "<b>no</b>"),
               "—" if np.isnan(coverage[j]) else f"{100 * coverage[j]:.0f} %"]
        if batch_v is not None:
            b_err = (batch_v[j] - tr) / tr * 100 if tr and np.isfinite(tr) else np.nan
            row += [_num(batch_v[j]), _num(b_err, 3)]
        rows.append(row)
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{html.escape(title or 'Online identification')}</title>"
        f"<style>{CSS}</style></head><body>",
        f"<h1>{html.escape(title or 'Online identification')}</h1>",
        f'<p class="meta">generated {datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")} · '
        "dampest_ros</p>",
        "<h2>Summary</h2>",
        _table(["", ""], [[html.escape(k), html.escape(v)] for k, v in summary]),
        f"<h2>Final estimate (t = {t[-1]:.1f} s)</h2>",
        '<p class="note">Recursive least squares on the live samples; damping coefficients '
        "in SI units, positive when dissipative. The batch column is the least-squares fit "
        "on the same samples, all weighted equally. The coverage is the share of the "
        "recorded instants of the second half of the run at which the truth lay within "
        "±2σ of the estimate (about 95 % when σ is right). The estimate over time, from the "
        "prior at t = 0, is in <code>convergence.csv</code>.</p>",
        _table(head, rows),
        "<h2>Convergence</h2>", *figs,
    ]
    if tracking is not None:
        dofs = ", ".join(DOF_NAMES[i] for i in tracking.dofs)
        by_unit = list(dict.fromkeys(u for r in tracking.rms.values() for u in r))
        parts += [
            "<h2>Velocity tracking with the identified model</h2>",
            '<p class="note">The per-DOF velocity PI of <code>controller_node</code> flies sine '
            f"references in {html.escape(dofs)} on the simulator (the true vehicle), alone "
            "and with the feed-forward D(ν<sub>ref</sub>)ν<sub>ref</sub> + "
            "C(ν<sub>ref</sub>)ν<sub>ref</sub> of the final model. RMS over the DOFs of "
            "each unit apart (m/s and rad/s are not added) after the first "
            f"{tracking.t[tracking.skip] - tracking.t[0]:.0f} s.</p>",
            _table(["controller", *(f"RMS error ({u}; " + ", ".join(
                DOF_NAMES[i] for i in tracking.dofs if VEL_UNITS[i] == u) + ")"
                for u in by_unit)],
                   [[html.escape(k), *(_num(v.get(u, np.nan), 4) for u in by_unit)]
                    for k, v in tracking.rms.items()]),
            f'<img src="{_tracking_figure(tracking, out / "tracking.png")}" '
            'alt="velocity tracking">',
        ]
    parts.append("</body></html>")
    index = out / "index.html"
    index.write_text("\n".join(parts), encoding="utf-8")
    return index
