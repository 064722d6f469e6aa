"""The report of a batch identification: ``write_report`` writes ``index.html`` and PNG
figures (relative links, so the directory can be copied or zipped as is): measured vs predicted
damping force, residual spectrum and autocorrelation with whiteness bounds, coefficients with
95 % intervals vs a prior (and a truth when known), a free-run velocity overlay, excitation
coverage, and the tables of coefficients and metrics
(:mod:`dampest_ros.core.identification.validate`).
"""

from __future__ import annotations

import html
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.identification import validate
from dampest_ros.core.identification.batch import Fit
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, RigidBody
from dampest_ros.core.signals.samples import Samples
from dampest_ros.report.figures import (
    FORCE_UNITS,
    VEL_UNITS,
    Values,
    acf_figure,
    aligned,
    coef_figure,
    coverage_figure,
    force_figure,
    free_run_figure,
    generated_utc,
    html_head,
    html_table,
    num,
    parameter_units,
    spectrum_figure,
    write_index,
)

FloatArray = NDArray[np.float64]


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
        Result of :func:`dampest_ros.core.identification.batch.fit`; ``fit.flags`` marks
        unidentified parameters, which are shown as such, not as numbers.
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
        τ between samples in the free run (see
        :func:`dampest_ros.core.identification.validate.free_run`).
    force_seconds, free_run_seconds : float
        Length of the force plot and of the free run (s), from the start of the longest
        segment.
    heldout : mapping of str to ndarray, each shape (6,), optional
        :func:`dampest_ros.core.identification.validate.metrics` of the damping force on data the
        fit did not use (``nse`` is shown as R², ``rmse`` in N and N·m).
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
    theta = np.asarray(fit.theta, dtype=float)
    prior_v, truth_v = aligned(prior, list(fit.names)), aligned(truth, list(fit.names))
    v = _validate(samples, model, body, theta, cutoff, tau_hold, free_run_seconds)
    figs = _figures(out, samples, model, fit, v, prior_v, truth_v, cutoff, force_seconds)
    heading = html.escape(title or f"Damping identification: {source or 'data'}")
    parts = [
        *html_head(heading),
        f'<p class="meta">input <code>{html.escape(source or "—")}</code> · generated '
        f"{generated_utc()} · dampest_ros</p>",
        "<h2>Summary</h2>", _summary_table(samples, fit, v, source, cutoff),
        *_coefficients_section(fit, prior_v, truth_v, figs["coef"]),
        *_force_section(fit, v, figs["force"], min(force_seconds, _duration(samples))),
        *_heldout_section(heldout, heldout_note),
        "<h2>Residuals</h2>",
        f'<img src="{figs["spectrum"]}" alt="residual spectrum">',
        f'<img src="{figs["acf"]}" alt="residual autocorrelation">',
        *_free_run_section(v, samples.rate, figs["free_run"]),
        "<h2>Excitation coverage</h2>",
        '<p class="note">Quadratic terms are only determined over the speeds the data cover; '
        "dotted lines: 1st and 99th percentiles.</p>",
        f'<img src="{figs["coverage"]}" alt="velocity histograms">',
        f'<p class="meta">Written in {time.perf_counter() - t_start:.1f} s.</p>',
        "</body></html>",
    ]
    return write_index(out, parts)


@dataclass(frozen=True)
class _Validation:
    """The validation numbers of a fit on its samples (N samples at ``rate``).

    Attributes
    ----------
    y, y_hat : ndarray, shape (N, 6)
        Measured and predicted damping force, low-passed as in the fit (N, N·m).
    metrics : mapping of str to ndarray, each shape (6,)
        :func:`~dampest_ros.core.identification.validate.metrics` of ``y_hat`` against ``y``.
    dec : int
        Decimation of the residual for the whiteness test.
    white : Whiteness
        Autocorrelation of the decimated residual.
    f : ndarray, shape (F,)
        Frequencies of the spectra (Hz).
    p_y, p_r : ndarray, shape (F, 6)
        Power spectral densities of ``y`` and of the residual.
    frf : FrfError or None
        Gain and phase error over the excited band; None where it cannot be computed.
    rows : slice
        The free run's samples.
    sim : ndarray, shape (len(rows), 6)
        Free-run velocity (m/s, rad/s); NaN after a divergence.
    free_run : mapping of str to ndarray, each shape (6,)
        :func:`~dampest_ros.core.identification.validate.metrics` of ``sim`` against ν.
    neg_share : float
        Share of samples where νᵀD(ν)ν < 0.
    min_power : float
        Least νᵀD(ν)ν over the samples (W).
    """

    y: FloatArray
    y_hat: FloatArray
    metrics: Mapping[str, FloatArray]
    dec: int
    white: validate.Whiteness
    f: FloatArray
    p_y: FloatArray
    p_r: FloatArray
    frf: validate.FrfError | None
    rows: slice
    sim: FloatArray
    free_run: Mapping[str, FloatArray]
    neg_share: float
    min_power: float


def _validate(samples: Samples, model: DampingModel, body: RigidBody, theta: FloatArray,
              cutoff: float, tau_hold: str, free_run_seconds: float) -> _Validation:
    """Score ``theta``, shape (p,), on ``samples``: force prediction, residual whiteness and
    spectrum, FRF error, free run over ``free_run_seconds`` (s) of the longest segment, and
    energy consistency (:mod:`dampest_ros.core.identification.validate`); ``cutoff`` (Hz) is
    the fit's low-pass (0: none)."""
    rate = samples.rate
    y, y_hat = validate.predicted_force(samples, model, body, theta, cutoff)
    r = y - y_hat
    # the fit low-passed y and Φ at `cutoff`: decimate the residual to ≈ 2·cutoff so that
    # the whiteness test asks whether what is left in the fitted band is white
    dec = max(1, int(rate // (2 * cutoff))) if cutoff > 0 else 1
    white = validate.residual_whiteness(r[::dec], rate / dec,
                                        max_lag=min(5.0, len(samples) / rate / 4))
    f, p_r = validate.residual_spectrum(r, rate)
    _, p_y = validate.residual_spectrum(y, rate)
    try:
        frf: validate.FrfError | None = validate.frf_error(
            samples, y, y_hat, rate, f_max=cutoff if cutoff > 0 else None)
    except ValueError:
        frf = None
    rows = validate.longest_segment(samples, free_run_seconds)
    sim = validate.free_run(samples, model, body, theta, rows, tau_hold)
    neg_share, min_power = validate.energy_consistency(samples, model, theta)
    return _Validation(
        y, y_hat, validate.metrics(y, y_hat, samples.nu_dot, rate), dec, white, f, p_y, p_r,
        frf, rows, sim, validate.metrics(samples.nu[rows], np.where(np.isfinite(sim), sim,
                                                                    np.inf)),
        neg_share, min_power)


def _figures(out: Path, samples: Samples, model: DampingModel, fit: Fit, v: _Validation,
             prior_v: FloatArray | None, truth_v: FloatArray | None, cutoff: float,
             force_seconds: float) -> dict[str, str]:
    """Draw the report's PNG figures into ``out``; their file names by key (``force``,
    ``spectrum``, ``acf``, ``coef``, ``free_run``, ``coverage``).

    ``prior_v`` and ``truth_v``, shape (p,), are drawn with the coefficients; the force plot
    covers ``force_seconds`` (s) of the longest segment; ``cutoff`` (Hz) is marked on the
    spectrum.
    """
    seg = validate.longest_segment(samples, force_seconds)
    t0 = float(samples.t[seg.start])
    rows = v.rows
    return {
        "force": force_figure(samples.t[seg] - t0, v.y[seg], v.y_hat[seg], out / "force.png"),
        "spectrum": spectrum_figure(v.f, v.p_y, v.p_r, cutoff, out / "residual_spectrum.png"),
        "acf": acf_figure(v.white, out / "residual_acf.png"),
        "coef": coef_figure(list(fit.names), np.asarray(fit.theta, dtype=float),
                            fit.interval(), fit.held, fit.identified, prior_v, truth_v,
                            parameter_units(model), out / "coefficients.png"),
        "free_run": free_run_figure(samples.t[rows] - float(samples.t[rows.start]),
                                    samples.nu[rows], v.sim, out / "free_run.png"),
        "coverage": coverage_figure(samples.nu, out / "coverage.png"),
    }


def _duration(samples: Samples) -> float:
    """Length of the data (s): sample count over rate (0 without a rate)."""
    return len(samples) / samples.rate if samples.rate else 0.0


def _summary_table(samples: Samples, fit: Fit, v: _Validation, source: str,
                   cutoff: float) -> str:
    """The summary table: input, samples, method, low-pass ``cutoff`` (Hz), conditioning,
    n_eff, AIC/BIC, what is not identified and the energy consistency."""
    N, rate = len(samples), samples.rate
    n_seg = int(np.unique(samples.segment).size)
    return html_table(["", ""], [
        ["input", html.escape(source or "—")],
        ["samples", f"{N} at {rate:.4g} Hz ({_duration(samples):.1f} s in {n_seg} segment(s))"],
        ["method", html.escape(fit.method)],
        ["regression low-pass", f"{cutoff:g} Hz" if cutoff > 0 else "none"],
        ["condition number (scaled)", num(fit.cond, 3)],
        ["effective samples n_eff", num(fit.n_eff, 4)],
        ["AIC / BIC", f"{num(fit.aic, 6)} / {num(fit.bic, 6)}"],
        ["parameters not identified",
         f"{int(np.sum(~fit.identified))} of {len(fit.names)} ({int(np.sum(fit.held))} held at "
         "the prior)"],
        *[["identified combination", html.escape(str(c))] for c in fit.combinations],
        ["energy consistency νᵀD(ν)ν ≥ 0",
         f"{v.neg_share:.2%} of samples negative, minimum {num(v.min_power, 3)} W"],
    ])


def _coefficients_section(fit: Fit, prior_v: FloatArray | None, truth_v: FloatArray | None,
                          figure: str) -> list[str]:
    """The coefficients' heading, note, table (estimate, std, 95 % interval, prior, truth,
    why not identified; unidentified rows flagged) and ``figure``; ``prior_v`` and ``truth_v``
    have shape (p,)."""
    theta = np.asarray(fit.theta, dtype=float)
    ci = fit.interval()
    std = fit.std
    header = ["parameter", "estimate", "std", "95 % low", "95 % high", "prior"]
    if truth_v is not None:
        header += ["truth", "truth in 95 %"]
    header.append("note")
    rows, cls = [], []
    for j, name in enumerate(fit.names):
        flagged = not fit.identified[j]
        row = [html.escape(name)]
        if fit.held[j]:
            row += ["held at prior", "", "", ""]
        else:
            row += [num(theta[j]), num(std[j], 3), num(ci[j, 0]), num(ci[j, 1])]
        row.append(num(prior_v[j]) if prior_v is not None else "—")
        if truth_v is not None:
            row.append(num(truth_v[j]))
            inside = (not flagged and np.isfinite(truth_v[j])
                      and ci[j, 0] <= truth_v[j] <= ci[j, 1])
            row.append("" if flagged else ("yes" if inside else "<b>no</b>"))
        why = fit.flags.get(name) or fit.constrained.get(name, "")
        row.append(f'<span class="reason">{html.escape(why)}</span>')
        rows.append(row)
        cls.append("flag" if flagged else "")
    return [
        "<h2>Coefficients</h2>",
        '<p class="note">Fossen model M ν̇ + C(ν)ν + D(ν)ν + g(η) = τ, FRD body frame; '
        "damping coefficients in SI units, positive when dissipative. Intervals are 95 % "
        "(Student-t on the block-robust covariance, including the sensor-bias budget). "
        "Parameters the data cannot determine are reported as not identified, with the "
        "reason.</p>",
        html_table(header, rows, cls),
        f'<img src="{figure}" alt="coefficients with 95 % intervals">',
    ]


def _force_section(fit: Fit, v: _Validation, figure: str, shown_seconds: float
                   ) -> list[str]:
    """The force prediction's heading, note, per-DOF table (fit metrics, CV RMSE, FRF error,
    whiteness) and ``figure``, whose first ``shown_seconds`` (s) the note names."""
    met, frf = v.metrics, v.frf
    rows = []
    for i in range(6):
        g = frf.median_gain_db[i] if frf is not None else np.nan
        ph = frf.median_phase_deg[i] if frf is not None else np.nan
        rows.append([
            f"{FORCE_NAMES[i]} ({FORCE_UNITS[i]})", num(met["rmse"][i]),
            num(met["nrmse"][i], 3), num(met["nse"][i], 5), num(met["peak_error"][i]),
            num(met["steady_bias"][i], 3), f"{met['steady_fraction'][i]:.0%}",
            num(fit.cv_rmse[i]), num(g, 3), num(ph, 3),
            f"{v.white.fraction_outside[i]:.0%}"])
    return [
        "<h2>Force prediction</h2>",
        '<p class="note">Measured y = τ − M ν̇ − C(ν)ν − g(η) vs predicted Φ(ν)θ, both '
        "low-passed as in the fit. NRMSE = RMSE / std(y); NSE = 1 − Σr²/Σ(y − ȳ)²; peak "
        "= max |r|; steady bias = mean residual over stretches of ≥ 1 s where |ν̇ᵢ| ≤ 10 % of "
        "its RMS (— where there are none); CV RMSE from blocked cross-validation; FRF "
        "error = median over the excited band (τ coherence ≥ 0.5) of the gain (dB) and "
        "phase (deg) of S<sub>τŷ</sub>/S<sub>τy</sub>; whiteness = share of autocorrelation "
        f"lags outside ±1.96/√N on the residual decimated by {v.dec}.</p>",
        html_table(["DOF", "RMSE", "NRMSE", "NSE", "peak error", "steady bias", "steady share",
                    "CV RMSE", "FRF gain err (dB)", "FRF phase err (°)", "ACF outside"], rows),
        f'<p class="note">First {shown_seconds:.0f} s of the longest segment:</p>',
        f'<img src="{figure}" alt="measured vs predicted force">',
    ]


def _free_run_section(v: _Validation, rate: float, figure: str) -> list[str]:
    """The free run's heading, note, per-DOF velocity table and ``figure``; ``rate`` (Hz) gives
    the run's length."""
    rows = [[f"{DOF_NAMES[i]} ({VEL_UNITS[i]})", num(v.free_run["rmse"][i], 3),
             num(v.free_run["nrmse"][i], 3), num(v.free_run["nse"][i], 4),
             num(v.free_run["peak_error"][i], 3)] for i in range(6)]
    length = (v.rows.stop - v.rows.start - 1) / rate if rate else 0.0
    return [
        "<h2>Free run</h2>",
        f'<p class="note">The model integrated (RK4 at the sample rate) from the measured ν '
        f"at the start of the longest segment for {length:.0f} s, driven by the measured τ "
        "and attitude, with no feedback from the measured velocity.</p>",
        html_table(["DOF", "RMSE", "NRMSE", "NSE", "peak error"], rows),
        f'<img src="{figure}" alt="free-run velocity overlay">',
    ]


def _heldout_section(scores: Mapping[str, FloatArray] | None, note: str) -> list[str]:
    """The held-out table (R² and RMSE of the damping force per DOF), or nothing."""
    if scores is None:
        return []
    rows = [[f"{FORCE_NAMES[i]} ({FORCE_UNITS[i]})", num(scores["nse"][i], 5),
             num(scores["rmse"][i])] for i in range(6)]
    return ["<h2>Held-out data</h2>",
            f'<p class="note">Scored on {html.escape(note or "data the fit did not use")}: '
            "y = τ − M ν̇ − C(ν)ν − g(η) against the model's D(ν)ν, low-passed as in the fit; "
            "R² = 1 − Σr²/Σ(y − ȳ)².</p>",
            html_table(["DOF", "held-out R²", "held-out RMSE"], rows)]
