"""The work of dampest gap (its options and --help: cli/gap_options.py): the comparison,
the text tables and the HTML report."""

from __future__ import annotations

import argparse
import html
import re
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from dampest_ros.cli.common import Elapsed, check_outputs, table
from dampest_ros.cli.inputs import load_model_for, load_samples
from dampest_ros.cli.pool import expand_inputs, map_logs_on_dask
from dampest_ros.core.gap.data import FORCE_UNITS, Chunk, GapData
from dampest_ros.core.gap.effects import Current
from dampest_ros.core.gap.library import library
from dampest_ros.core.gap.localise import LocalRow, concentration, localise, residual_psd
from dampest_ros.core.gap.model_effects import Memory
from dampest_ros.core.gap.relative import RelativeRefit, refit_relative
from dampest_ros.core.gap.search import GapOptions, GapResult, correction, find_gap
from dampest_ros.core.gap.update import free_run_errors, updated_model
from dampest_ros.core.identification.misfit import element_drags
from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.identity import Identity
from dampest_ros.core.physics.point_drag import PointSpec
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, ConfigError
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.measurements import JointSeries
from dampest_ros.core.signals.plausibility import unusable_samples
from dampest_ros.core.signals.preprocess import DataError
from dampest_ros.core.signals.samples import Samples
from dampest_ros.io.bag import bag_summary, is_bag, read_bag
from dampest_ros.io.remote import is_url, local_log
from dampest_ros.io.yaml_io import load_vehicle, save_model
from dampest_ros.report.figures import psd_limits, psd_unit

DPI = 90


def _joints(path: str, args: argparse.Namespace, vehicle: Vehicle) -> JointSeries | None:
    """The logged thruster state of a bag on the samples' clock, or None for CSV input, for
    a vehicle without thrusters or a bag without the thruster topic (τ from --wrench-topic):
    the candidates that need rotor speeds then say so."""
    p = Path(path)
    if not is_bag(p) or vehicle.thrusters is None:
        return None
    topic = args.thrusters_topic
    if args.wrench_topic and topic not in {t.lstrip("/") for t in bag_summary(p).topics}:
        return None
    series = read_bag(p, [topic])[topic]
    if not isinstance(series, JointSeries):
        return None
    # the preprocessing shifts the thrust by --delay; so must the dead-zone table
    return replace(series, stamp=series.stamp + float(args.delay))


def _load_log(path: str, args: argparse.Namespace) -> tuple[Samples, JointSeries | None]:
    """One log's samples and logged thruster state (a path, or a URL copied here first;
    runs on a Dask worker)."""
    vehicle = load_vehicle(args.vehicle)
    with local_log(path) as local:
        return load_samples(local, vehicle, args), _joints(local, args, vehicle)


def pooled_logs(paths: list[str], args: argparse.Namespace
                ) -> tuple[Samples, JointSeries | None, dict[str, list[str]]]:
    """The samples (and logged thruster state) of one log, or of several one after the other:
    each log's clock is shifted to start 1 s after the previous one ends, its samples a
    segment of their own, so that the effects are screened on the pooled data and the held-out
    part is the last logs' end. The thruster state is kept only when every log has it.
    Several logs are read on Dask (--workers, --scheduler); one that fails is left out with
    its reason. The third value names the logs pooled and left out (for the model file)."""
    if len(paths) == 1 and not is_url(paths[0]):
        return (*_load_log(paths[0], args), {})
    with map_logs_on_dask(paths, partial(_load_log, args=args), args) as (_, done, failed, _):
        parts: list[tuple[Samples, JointSeries | None]] = list(done.values())
    logs = {"logs": list(done), "logs_left_out": list(failed) or ["none"]}
    shifted: list[Samples] = []
    joints: list[JointSeries | None] = []
    end = 0.0
    for s, j in parts:
        offset = end + 1.0 - float(s.t[0]) if shifted else 0.0
        shifted.append(replace(s, t=s.t + offset))
        joints.append(None if j is None else replace(j, stamp=j.stamp + offset))
        end = float(shifted[-1].t[-1])
    print(f"{len(parts)} logs pooled, one after the other in time", file=sys.stderr)
    pooled = Samples.concatenate(shifted)
    if any(j is None for j in joints):
        return pooled, None, logs
    js = [j for j in joints if j is not None]
    if any(j.names != js[0].names for j in js):
        return pooled, None, logs
    return pooled, replace(js[0], stamp=np.concatenate([j.stamp for j in js]),
                           velocity=np.concatenate([j.velocity for j in js]),
                           effort=np.concatenate([j.effort for j in js]),
                           position=np.concatenate([j.position for j in js])), logs


def run(args: argparse.Namespace) -> int:
    """Load, compare, localise, name the missing effects, print and write the report.

    The model file (``--out``) and the report (``--report``) are written whatever the free
    run does: a run that diverges or fails is explained in them and on the terminal."""
    t0 = time.perf_counter()
    check_outputs(args, {"out": "model.yaml"}, ("report",))
    if args.max_steps < 0:
        raise ConfigError("--max-steps", f"must be ≥ 0, got {args.max_steps}")
    if not 0.2 <= args.split <= 0.9:
        raise ConfigError("--split", f"must be in [0.2, 0.9] (the share of the time fitted), "
                                     f"got {args.split:g}")
    if not 0.0 <= args.min_heldout < 1.0:
        raise ConfigError("--min-heldout", f"must be in [0, 1) (a share of the residual "
                                           f"power), got {args.min_heldout:g}")
    vehicle = load_vehicle(args.vehicle)
    mf, model, body = load_model_for(args.model, vehicle)
    cands = library([c.strip() for c in str(args.candidates).split(",") if c.strip()])
    paths = expand_inputs(args.input)
    args.input = ", ".join(paths)
    samples, joints, logs = pooled_logs(paths, args)
    reason = unusable_samples(samples)
    if reason is not None:
        raise DataError(f"{args.input}: {reason}")
    data = GapData(samples, model, mf.theta, body, vehicle.thrusters, joints,
                   cutoff=args.cutoff, split=args.split, flown=mf.flown,
                   model_rmse=model_rmse(mf))
    seconds = len(samples) / samples.rate
    print(f"{args.input}: {len(samples)} samples ({seconds:.0f} s in "
          f"{int(samples.segment.max()) + 1} segment(s)); fit on the first "
          f"{100 * args.split:.0f} % of the time, scored on the last "
          f"{100 * (1 - args.split):.0f} %")
    y_rms = np.sqrt(np.mean((data.r0 + _model_force(data)) ** 2, axis=0))
    r_rms = np.sqrt(np.mean(data.r0**2, axis=0))
    print("\n1. one-step residual r = τ − (M ν̇ + C ν + D ν + g) of the model "
          f"(low-passed at {args.cutoff:g} Hz):")
    print(table(("dof", "damping force RMS", "residual RMS", "residual / force"),
                [(f"{FORCE_NAMES[i]} ({FORCE_UNITS[i]})", float(y_rms[i]), float(r_rms[i]),
                  f"{100 * r_rms[i] / max(y_rms[i], 1e-300):.1f} %") for i in range(6)]))
    rows = localise(samples, data.r0, passband=args.cutoff)
    print("\n2. where the residual is concentrated (RMS in the subset / overall RMS):")
    print(concentration_text(rows))
    print("\n3-4. candidate effects, ranked by held-out evidence:")
    opts = GapOptions(min_heldout=args.min_heldout, max_steps=args.max_steps)
    result = find_gap(data, cands, opts, progress=lambda s: print("  " + s))
    for key, why in result.skipped.items():
        print(f"  skipped {key}: {why}")
    print()
    print(steps_table(data, result) if result.steps else "no effect named.")
    print(f"\n{result.conclusion}.")
    relative = current_refit(data, result, element_drags(vehicle))
    if relative is not None:
        print("\n5. the model refitted at the relative velocity ν_r, jointly with the "
              "current:\n" + refit_text(relative))
    # the model file first: it does not depend on the free run
    final = final_model(data, result, mf, args, logs, vehicle.identity, relative)
    if args.out:
        save_model(Path(args.out), final)
    free = free_run_errors(data, result.effects)
    print()
    print(free_run_text(free))
    if args.out:
        print(f"wrote {args.out}")
    if args.report:
        out = Path(args.report)
        write_report(out, data, result, rows, free, final, args, relative)
        print(f"wrote {out / 'index.html'}")
    print(f"({time.perf_counter() - t0:.1f} s)")
    return 0


def model_rmse(mf: Model) -> np.ndarray | None:
    """The believed model's residual RMS per DOF on its own fit data (``extra['rmse']``,
    written by ``dampest identify``), or None when the file does not say."""
    given = mf.extra.get("rmse")
    try:
        out = np.asarray(given, dtype=float)
    except (TypeError, ValueError):
        return None
    return out if out.shape == (6,) and np.all(np.isfinite(out)) else None


def _model_force(data: GapData) -> np.ndarray:
    """Φθ of the model, low-passed like the residual (for the force scale)."""
    def force(ch: Chunk) -> np.ndarray:
        z = np.zeros((len(ch), data.n_states))
        return data.model.force(ch.nu, data.theta, z)
    return data.filtered(force)


def concentration_text(rows: list[LocalRow], top: int = 3) -> str:
    """Per DOF, the subsets where the residual RMS is most above its overall RMS."""
    conc = concentration(rows, top)
    lines = []
    for i in range(6):
        items = [f"{label} {ratio:.2f}×" for d, label, ratio in conc if d == i]
        lines.append(f"  {FORCE_NAMES[i]} (RMS {rows[0].rms[i]:.3g} {FORCE_UNITS[i]}): "
                     + ", ".join(items))
    return "\n".join(lines)


def final_magnitudes(data: GapData, result: GapResult) -> list[str]:
    """Per named effect, its magnitude ± σ after the final joint refit (what the model file
    holds) and, for a damping coefficient, the model's value before → after."""
    values = dict(zip(data.model.parameter_names, data.theta.tolist(), strict=True))
    upd = updated_model(data, result.effects)
    after = dict(zip(upd.model.parameter_names, upd.theta.tolist(), strict=True))
    lines = []
    for (e, p), cov in zip(result.effects, result.covs, strict=True):
        u = e.model_update(data, p)
        names = [*u.get("theta", {}), *(c["name"] for c in u.get("cross", []))]
        text = e.describe(p, cov)
        if names:
            text += "; in the model: " + ", ".join(
                f"{n} {values[n]:.4g} → {after[n]:.4g}" if n in values else
                f"{n} {after[n]:.4g} (added)" for n in names)
        if "terms" in u:
            text += "; written as added_mass_terms " + ", ".join(
                f"{k}: {str(v).lower()}" for k, v in u["terms"].items()
                if k != "coriolis_zero")
        lines.append(text)
    return lines


def steps_table(data: GapData, result: GapResult) -> str:
    """The steps: effect, held-out reduction, ΔBIC; the final magnitudes ± σ; held-out RMS
    per DOF before → after each step."""
    rows = []
    for k, st in enumerate(result.steps, 1):
        rows.append((k, st.effect.title, f"{100 * st.screen.heldout:.1f} %",
                     f"{st.bic_after - st.bic_before:.0f}"))
    head = table(("step", "effect named", "held-out reduction", "ΔBIC"), rows)
    mags = "\n".join(f"  step {k}: {text}"
                     for k, text in enumerate(final_magnitudes(data, result), 1))
    rms = table(("step", *(f"{f} before→after" for f in FORCE_NAMES)),
                [(k, *(f"{st.rms_before[i]:.3g}→{st.rms_after[i]:.3g}" for i in range(6)))
                 for k, st in enumerate(result.steps, 1)])
    worse = "".join(f"\n  step {k}: {d.text}" for k, st in enumerate(result.steps, 1)
                    for d in st.worse)
    return (head + "\n\nmagnitudes after the final joint refit (± 1σ, block-robust; "
            "as written to the model):\n" + mags
            + "\n\nheld-out residual RMS per DOF (N, N·m):\n" + rms
            + ("\n\nDOFs whose held-out residual grew, and why:" + worse if worse else ""))


def current_refit(data: GapData, result: GapResult, points: Sequence[PointSpec]
                  ) -> RelativeRefit | None:
    """When a current is named, the believed model (with any terms the gap added) refitted at
    ν_r jointly with it, its terms chosen again there as identify chooses them, ``points``'
    element drags included (:func:`refit_relative`); else None."""
    found = [(e, p) for e, p in result.effects if isinstance(e, Current)]
    if not found:
        return None
    e, p = found[0]
    upd = updated_model(data, result.effects)
    with Elapsed("refitting the model at the relative velocity"):
        return refit_relative(data, upd.model, upd.theta, e.ned(p), result.r, points=points)


def refit_text(rel: RelativeRefit) -> str:
    """The jointly estimated current, the terms added at ν_r per DOF, and the held-out R² and
    RMS per DOF before (believed model at ν) and after (refit at ν_r)."""
    v = rel.current
    head = (f"  current {float(np.hypot(v[0], v[1])):.3f} m/s towards "
            f"{float(np.degrees(np.arctan2(v[1], v[0])) % 360.0):.1f}° (north {v[0]:+.3f}, "
            f"east {v[1]:+.3f} m/s)\n")
    if rel.added:
        head += (f"  terms added where the model's terms misfit ν_r (default selection, "
                 f"{rel.rounds} current–terms round(s)):\n" + "".join(
                     f"    {FORCE_NAMES[i]}: {', '.join(names)}\n"
                     for i, names in rel.added.items()))
    else:
        head += "  no terms added: the model's terms fit ν_r as well as the library's\n"
    return head + table(
        ("held-out", *(f"{f} ({u})" for f, u in zip(FORCE_NAMES, FORCE_UNITS, strict=True))),
        [("R² believed", *(f"{x:.4f}" for x in rel.r2_before)),
         ("R² refit at ν_r", *(f"{x:.4f}" for x in rel.r2_after)),
         ("RMS believed", *(f"{x:.3g}" for x in rel.rms_before)),
         ("RMS refit at ν_r", *(f"{x:.3g}" for x in rel.rms_after))])


def free_run_text(free: dict[str, Any] | str) -> str:
    """The free-run comparison (with why a run diverged), or why it was skipped."""
    if isinstance(free, str):
        return free
    text = (f"free run over {free['seconds']:.0f} s (velocity RMSE, m/s and rad/s):\n"
            + table(("model", *DOF_NAMES),
                    [("believed", *map(float, free["nominal"])),
                     ("with the named effects", *map(float, free["final"]))]))
    for name, why in free["notes"].items():
        text += f"\n{_model_label(name)} {why}"
    if free["omitted"]:
        text += "\n(not representable in the free run: " + "; ".join(free["omitted"]) + ")"
    return text


def _model_label(name: str) -> str:
    """'the believed model', 'the model with the named effects' (free-run row names)."""
    return f"the {name} model" if name == "believed" else f"the model {name}"


def _param_key(key: str) -> str:
    return re.sub(r"[^A-Za-z0-9_]", "_", key)


def final_model(data: GapData, result: GapResult, mf: Model, args: argparse.Namespace,
                logs: dict[str, list[str]] | None = None,
                identity: Identity | None = None,
                relative: RelativeRefit | None = None) -> Model:
    """The believed model with the named effects applied, its σ and what they updated;
    ``logs``: the logs pooled and left out (:func:`pooled_logs`), recorded in ``extra``;
    ``identity``: the vehicle's (else the believed model's). With a current named, the
    ``relative`` refit's terms, θ, σ and held coefficients replace them (the model fitted at
    ν_r), its current, the terms it added and its held-out scores under
    ``extra['gap']['refit']``."""
    upd = updated_model(data, result.effects)
    std = dict(zip(mf.parameter_names, mf.theta_std.tolist(), strict=True))
    effects: dict[str, Any] = {}
    updated: set[str] = set()
    mem = upd.model.term("freq")
    for (e, p), cov in zip(result.effects, result.covs, strict=True):
        s = np.sqrt(np.abs(np.diag(cov)))
        u = e.model_update(data, p)
        for name in [*u.get("theta", {}), *(c["name"] for c in u.get("cross", []))]:
            std[name] = float(s[0])
            updated.add(name)
        if isinstance(e, Memory) and mem is not None:
            for name, d in zip(mem.parameter_names, mem.state_dofs, strict=True):
                if int(d) == e.dof:
                    std[name] = float(s[0])
                    updated.add(name)
        entry: dict[str, Any] = {}
        for name, v, sd in zip(e.params, p, s, strict=True):
            entry[_param_key(name)] = float(v)
            entry[_param_key(name) + "_std"] = float(sd)
        entry["title"] = e.title
        effects[_param_key(e.key)] = entry
    damping = upd.model if relative is None else relative.model
    names = damping.parameter_names
    extra: dict[str, Any] = {
        "source": f"dampest gap {args.input} --model {args.model}", **(logs or {}),
        "gap": {"named": [e.key for e, _ in result.effects] or ["none"],
                "conclusion": result.conclusion, **effects, **upd.extra}}
    # a coefficient the believed model held at its prior stays held unless an effect set it
    held = {n: why for n, why in mf.held.items() if n in names and n not in updated}
    theta, theta_std = upd.theta, np.array([std.get(n, 0.0) for n in names])
    if relative is not None:
        f = relative.fit
        theta, theta_std = f.theta, f.std
        held = f.held_reasons
        extra["gap"]["refit"] = {
            "what": "the model refitted at the relative velocity, jointly with the current, "
                    "with library terms added where its terms misfit; theta is this refit",
            "current_ned": [float(x) for x in relative.current],
            "added_terms": [n for i in sorted(relative.added) for n in relative.added[i]]
            or ["none"],
            "r2_heldout_before": [float(x) for x in relative.r2_before],
            "r2_heldout_after": [float(x) for x in relative.r2_after],
            "rmse_heldout_before": [float(x) for x in relative.rms_before],
            "rmse_heldout_after": [float(x) for x in relative.rms_after]}
    return Model(names, theta, theta_std, upd.M,
                 damping=damping, extra=extra, M_A=upd.M_A,
                 added_mass_terms=upd.added_mass_terms, held=held,
                 identity=identity or mf.identity)


# --- report ------------------------------------------------------------------------------


CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1200px;
margin:2em auto;padding:0 1em;color:#222;line-height:1.45}
table{border-collapse:collapse;margin:.6em 0 1.2em;font-size:.9em}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right}
th{background:#f2f2f2}td:first-child,th:first-child{text-align:left}
td.hot{background:#ffe0d6}td.warm{background:#fff4e0}
img{max-width:100%;border:1px solid #ddd;margin:.3em 0 1em}.note{color:#555;font-size:.92em}
"""


def _html_table(header: list[str], rows: list[list[str]], classes: list[list[str]] | None = None
                ) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = []
    for k, row in enumerate(rows):
        cells = []
        for j, c in enumerate(row):
            cls = classes[k][j] if classes else ""
            cells.append(f'<td class="{cls}">{c}</td>' if cls else f"<td>{c}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _residual_figure(data: GapData, before: np.ndarray, after: np.ndarray, title: str,
                     path: Path, seconds: float = 60.0) -> str:
    """Held-out residual before/after over ``seconds`` and its spectrum, per DOF."""
    before_all = before
    test = np.flatnonzero(data.test)
    n = min(len(test), round(seconds * data.rate))
    idx = test[:n]
    t = data.samples.t[idx] - data.samples.t[0]
    # break the lines at segment boundaries
    cut = np.flatnonzero(np.diff(data.samples.segment[idx])) + 1
    t = np.insert(t, cut, np.nan)
    before = np.insert(before[idx], cut, np.nan, axis=0)
    after_s = np.insert(after[idx], cut, np.nan, axis=0)
    fig = Figure(figsize=(12, 9))
    axes = fig.subplots(6, 2, sharex="col", gridspec_kw={"width_ratios": [2.2, 1]})
    f_b, P_b = residual_psd(data.samples, before_all, data.test)
    f_a, P_a = residual_psd(data.samples, after, data.test)
    f_hi = max(2 * data.cutoff, 1.0)
    shown = (f_b > 0) & (f_b <= f_hi)
    for i in range(6):
        ax = axes[i, 0]
        ax.plot(t, before[:, i], lw=0.9, color="0.55", label="before")
        ax.plot(t, after_s[:, i], lw=0.9, color="tab:red", label="after")
        ax.set_ylabel(f"{FORCE_NAMES[i]} ({FORCE_UNITS[i]})")
        ax.grid(alpha=0.3)
        ax = axes[i, 1]
        low, high = psd_limits([P_b[shown, i], P_a[shown, i]])
        ax.loglog(f_b[1:], np.maximum(P_b[1:, i], low), lw=0.9, color="0.55")
        ax.loglog(f_a[1:], np.maximum(P_a[1:, i], low), lw=0.9, color="tab:red")
        ax.set_xlim(f_b[1], f_hi)
        ax.set_ylim(low, high)
        ax.set_ylabel(f"PSD ({psd_unit(i)})", fontsize=8)
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[5, 0].set_xlabel("time (s), held-out part")
    axes[5, 1].set_xlabel("frequency (Hz)")
    axes[0, 1].set_title("residual PSD", fontsize=9)
    fig.suptitle(title, fontsize=11)
    fig.subplots_adjust(left=0.07, right=0.985, bottom=0.06, top=0.94, hspace=0.35, wspace=0.3)
    fig.savefig(path, dpi=DPI, format="png")
    return path.name


def write_report(out: Path, data: GapData, result: GapResult,
                 rows: list[LocalRow], free: dict[str, Any] | str,
                 final: Model, args: argparse.Namespace,
                 relative: RelativeRefit | None = None) -> Path:
    """index.html, residual figures per step and final_model.yaml in ``out``; with a
    current named, the ``relative`` refit as the last row of the per-DOF residuals."""
    out.mkdir(parents=True, exist_ok=True)
    save_model(out / "final_model.yaml", final)
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>dampest gap</title>"
             f"<style>{CSS}</style></head><body><h1>Sim-to-real gap</h1>"
             f"<p class='note'>measured: {html.escape(str(args.input))} · model: "
             f"{html.escape(str(args.model))} · vehicle: {html.escape(str(args.vehicle))} · "
             f"{len(data.samples)} samples, {len(data.samples) / data.rate:.0f} s · fit on the "
             f"first {100 * data.split:.0f} % of the time, held-out scores on the rest · "
             f"regression low-passed at {data.cutoff:g} Hz</p>"]
    # 1. compare
    r_rms = np.sqrt(np.mean(data.r0**2, axis=0))
    parts.append("<h2>1. Comparison</h2><p>One-step inverse-dynamics residual "
                 "r = τ − (M ν̇ + C ν + D ν + g) of the model (RMS over all data):</p>")
    parts.append(_html_table(["", *FORCE_NAMES], [["residual RMS",
                                                   *(f"{x:.4g}" for x in r_rms)]]))
    if isinstance(free, str):
        parts.append(f"<p class='note'>{html.escape(free)}</p>")
    else:
        parts.append(f"<p>Free run of the measured τ over {free['seconds']:.0f} s (velocity "
                     "RMSE, m/s and rad/s):</p>")
        parts.append(_html_table(["model", *DOF_NAMES], [
            ["believed", *(f"{x:.4g}" for x in free["nominal"])],
            ["with the named effects", *(f"{x:.4g}" for x in free["final"])]]))
        for name, why in free["notes"].items():
            parts.append(f"<p><b>{html.escape(_model_label(name).capitalize())} "
                         f"{html.escape(why)}.</b></p>")
        if free["omitted"]:
            parts.append("<p class='note'>Not representable in the free run: "
                         + html.escape("; ".join(free["omitted"])) + "</p>")
    # 2. localise
    parts.append("<h2>2. Where the residual is</h2><p class='note'>RMS of the residual in "
                 "each subset divided by its overall RMS (bands: RMS per unit bandwidth "
                 "relative to the whole spectrum). Shaded: ≥ 1.5× and ≥ 1.25×.</p>")
    total = rows[0].rms
    trows, tcls = [], []
    for row in rows:
        if row.group == "band":
            ratio = row.rms / np.maximum(total, 1e-300) / np.sqrt(max(row.share, 1e-12))
        else:
            ratio = row.rms / np.maximum(total, 1e-300)
        trows.append([html.escape(f"{row.group}: {row.label}"), f"{100 * row.share:.0f} %",
                      *(f"{x:.2f}" for x in ratio)])
        tcls.append(["", "", *("hot" if x >= 1.5 else "warm" if x >= 1.25 else ""
                               for x in ratio)])
    parts.append(_html_table(["subset", "share", *FORCE_NAMES], trows, tcls))
    # 3-4. steps
    parts.append("<h2>3–4. Effects named</h2>")
    if result.steps:
        srows = []
        mags = final_magnitudes(data, result)
        for k, (st, mag) in enumerate(zip(result.steps, mags, strict=True), 1):
            srows.append([str(k), html.escape(st.effect.title), html.escape(mag),
                          *(f"{st.rms_before[i]:.3g} → {st.rms_after[i]:.3g}" for i in range(6)),
                          f"{st.bic_before:.0f} → {st.bic_after:.0f}",
                          f"{100 * st.screen.heldout:.1f} %"])
        if relative is not None:
            added = ", ".join(n for names in relative.added.values() for n in names)
            srows.append(["refit", html.escape("the model refitted at ν_r with the current; "
                                               f"terms added: {added or 'none'}"),
                          html.escape(refit_text(relative).splitlines()[0].strip()),
                          *(f"{relative.rms_before[i]:.3g} → {relative.rms_after[i]:.3g} "
                            f"(R² {relative.r2_after[i]:.4f})" for i in range(6)), "", ""])
        parts.append(_html_table(["step", "effect", "magnitude ± σ (final joint refit)",
                                  *(f"{f} held-out RMS ({u})"
                                    for f, u in zip(FORCE_NAMES, FORCE_UNITS, strict=True)),
                                  "BIC", "held-out reduction"], srows))
        worse = [f"step {k}: {d.text}" for k, st in enumerate(result.steps, 1)
                 for d in st.worse]
        if worse:
            parts.append("<p>DOFs whose held-out residual grew in a step, and why:</p><ul>"
                         + "".join(f"<li>{html.escape(w)}</li>" for w in worse) + "</ul>")
        r_prev = result.r0
        for k, (st, mag) in enumerate(zip(result.steps, mags, strict=True), 1):
            r_after = data.r0 - correction(data, result.effects[:k]) \
                if k < len(result.steps) else result.r
            name = _residual_figure(data, r_prev, r_after,
                                    f"step {k}: {st.effect.title}", out / f"step{k}.png")
            parts.append(f"<h3>Step {k}: {html.escape(st.effect.title)}</h3>"
                         f"<p>{html.escape(mag)}; runner-up: "
                         f"{html.escape(st.runner_up)}</p><img src='{name}'>")
            r_prev = r_after
    parts.append(f"<p><b>{html.escape(result.conclusion)}.</b></p>")
    if result.rejected:
        parts.append("<p>Significant but rejected: " + html.escape("; ".join(
            f"{k} ({v})" for k, v in result.rejected.items())) + "</p>")
    if result.skipped:
        parts.append("<p class='note'>Not tested: " + html.escape("; ".join(
            f"{k} ({v})" for k, v in result.skipped.items())) + "</p>")
    last = result.screens[-1] if result.screens else []
    parts.append("<h3>Last round: the best remaining candidates</h3>")
    parts.append(_html_table(
        ["candidate", "held-out reduction", "best DOF", "ΔBIC (train)", "ERR", "significant"],
        [[html.escape(s.effect.title), f"{100 * s.heldout:.2f} %",
          f"{100 * float(s.heldout_dof.max()):.1f} %", f"{s.dbic:.0f}", f"{100 * s.err:.2f} %",
          "yes" if s.significant else "no"] for s in last[:10]]))
    if not result.steps:
        name = _residual_figure(data, result.r0, result.r0, "residual of the model",
                                out / "residual.png")
        parts.append(f"<img src='{name}'>")
    parts.append("<h2>5. Final model</h2><p><a href='final_model.yaml'>final_model.yaml</a> "
                 "(ROS 2 parameters file; effects that are not damping terms are listed under "
                 "<code>model.gap</code>).</p></body></html>")
    path = out / "index.html"
    path.write_text("\n".join(parts))
    return path

