"""The work of dampest identify (its options and --help: cli/identify_options.py)."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from dampest_ros.cli.common import DEFAULT_TOPICS, Elapsed, check_outputs, table, term_list
from dampest_ros.cli.inputs import (
    bag_topics,
    check_options,
    cut,
    load_samples,
    split_holdout,
    structure_of,
    warn_unchecked,
)
from dampest_ros.cli.pool import (
    check_pooled_options,
    drift_table,
    expand_inputs,
    log_table,
    plot_drift,
    reduce_all,
    samples_of,
)
from dampest_ros.core.identification.axis_check import CONE
from dampest_ros.core.identification.batch import Fit, FitOptions
from dampest_ros.core.identification.misfit import (
    element_drags,
    misfit_terms,
    with_element_drags,
)
from dampest_ros.core.identification.pool import (
    LogStatistics,
    consistency,
    drift,
    pooled_extent,
    pooled_fit,
)
from dampest_ros.core.identification.selection import (
    MIN_ERR,
    MIN_ERR_BESIDE_ELEMENTS,
    Selection,
    select_terms,
)
from dampest_ros.core.identification.validate import force_scores
from dampest_ros.core.identifier import DampingIdentifier, Prior, prior_arrays
from dampest_ros.core.online.estimator import EstimatorConfig, nominal_of
from dampest_ros.core.online.sample import OnlineConfig
from dampest_ros.core.physics.damping import DampingModel
from dampest_ros.core.physics.mounting import frame_id_note
from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, ConfigError
from dampest_ros.core.physics.vehicle import Vehicle
from dampest_ros.core.signals.preprocess import DataError
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.simulation.excitation import speed_limits
from dampest_ros.io.bag import bag_summary, is_bag, read_bag
from dampest_ros.io.remote import is_url
from dampest_ros.io.yaml_io import load_model, load_vehicle, save_model


def run(args: argparse.Namespace) -> int:
    """Read, preprocess, fit, print the table, write the model."""
    t0 = time.perf_counter()
    check_outputs(args, {"out": "model.yaml", "drift_plot": "drift.png"}, ("report",))
    vehicle = load_vehicle(args.vehicle)
    paths = expand_inputs(args.input)
    if len(paths) > 1 or is_url(paths[0]):  # a URL is fetched where a Dask worker reads it
        return run_pooled(args, vehicle, paths)
    args.input = paths[0]
    if args.method == "rls":
        return run_rls(args, vehicle)
    substitutions: list[str] = []
    preset, model, prior, result, samples, held = fit_log(args, vehicle, substitutions)
    elapsed = time.perf_counter() - t0
    print(f"{args.input}: {len(samples)} samples ({len(samples) / samples.rate:.0f} s in "
          f"{int(samples.segment.max()) + 1} segment(s)), {result.method}, "
          f"condition number {result.cond:.3g}, {elapsed:.1f} s")
    scores = None
    if held is not None:
        scores = force_scores(held, model, vehicle.body, result.theta, args.cutoff)
    print(report_table(result, prior, scores))
    print()
    print(table(("dof", "RMSE", "NSE", "CV RMSE"),
                [(DOF_NAMES[i], float(result.rmse[i]), float(result.r2[i]),
                  float(result.cv_rmse[i])) for i in range(6)]))
    for name, why in result.flags.items():
        print(f"not identified: {name}: {why}")
    for combination in result.combinations:
        print(f"identified combination: {combination}")
    for name, why in result.constrained.items():
        print(f"constrained: {name}: {why}")
    print()
    print(axis_text(result))
    if held is not None and scores is not None:
        print()
        print(heldout_text(held, scores))
        for line in unpredictive(result.names, scores):
            print(line)
    if args.out:
        write_model(Path(args.out), result, model, vehicle, source=str(args.input),
                    heldout=scores, flown=samples.nu,
                    more={**term_origin(preset, model),
                          **({"substitutions": substitutions} if substitutions else {})})
        print(f"wrote {args.out}")
    if args.report:
        truth = None
        if args.truth:
            tm = load_model(args.truth)
            truth = dict(zip(tm.parameter_names, tm.theta, strict=True))
        from dampest_ros.report.identify import write_report  # matplotlib: only for a report
        page = write_report(args.report, samples, model, vehicle.body, result, prior=prior,
                            truth=truth, title=f"Damping of {vehicle.name}",
                            source=str(args.input), cutoff=args.cutoff, heldout=scores,
                            heldout_note=heldout_note(held) if held is not None else "")
        print(f"wrote {page}")
    return 0


class LogFit(NamedTuple):
    """What :func:`fit_log` fitted: the preset's structure and the fitted one, the prior θ,
    the fit, the samples fitted and the held-out part (None without ``--holdout``)."""

    preset: DampingModel
    model: DampingModel
    prior: np.ndarray
    result: Fit
    samples: Samples
    held: Samples | None


def fit_log(args: argparse.Namespace, vehicle: Vehicle, substitutions: list[str]) -> LogFit:
    """Read and preprocess one log, choose the structure (the preset's, ``--select``'s or
    the default's) and fit it: the batch part of ``dampest identify`` (``substitutions``
    collects the sources that stood in for missing topics)."""
    model, nominal = structure_of(args, vehicle)
    samples = cut(load_samples(args.input, vehicle, args, substitutions), args)
    held = None
    if args.holdout is not None:
        samples, held = split_holdout(samples, args.holdout)
    preset = model
    if args.select:
        with Elapsed("selecting the damping terms"):
            selection = select_terms(samples, model, vehicle.body, cutoff=args.cutoff,
                                     points=element_drags(vehicle))
        print(selection_table(selection))
        print("terms per DOF: the preset's that stay, and those selection added:")
        print(added_table([n for n in selection.model.parameter_names
                           if n in model.parameter_names], selection.added(model),
                          *selection.cv_r2))
        print(element_drag_table(selection))
        model = selection.model
    else:
        model = default_selection(samples, model, vehicle, args)
    nominal = nominal_of(model, preset, nominal)
    spec = prior_spec(args, vehicle)
    prior = prior_of(model, nominal, spec)[0]
    identifier = DampingIdentifier(vehicle, method=args.method, cutoff=args.cutoff,
                                   prior=spec, structure=model).fit(samples)
    result = identifier.fit_
    assert result is not None  # fit() sets it
    return LogFit(preset, model, prior, result, samples, held)


def prior_spec(args: argparse.Namespace, vehicle: Vehicle) -> Prior | None:
    """--prior's model as a prior by name (names, θ, σ), or None without the option; a model
    of another vehicle than ``vehicle`` is refused (ConfigError naming both)."""
    if not args.prior:
        return None
    pm = load_model(args.prior)
    warn_unchecked(pm.belongs_to(vehicle.identity, str(args.prior)))
    return pm.parameter_names, pm.theta, pm.theta_std


def prior_of(model: DampingModel, nominal: np.ndarray, spec: Prior | None
             ) -> tuple[np.ndarray, np.ndarray | None]:
    """The prior mean and standard deviation: the nominal damping, or ``spec``'s values where
    it names a parameter (the nominal elsewhere)."""
    return (nominal, None) if spec is None else prior_arrays(model, nominal, spec)


def inconsistent_logs(logs: list[LogStatistics], keep_all: bool) -> dict[str, str]:
    """Test that the logs belong together (:func:`consistency`); print each that does not,
    and unless ``keep_all`` take it out of ``logs`` (in place: the list
    :func:`reduce_all`'s map runs over). Returns log → why it was left out."""
    if len(logs) < 2:
        return {}
    c = consistency(logs)
    out: dict[str, str] = {}
    for b in c.left_out:
        why = (f"its estimate is inconsistent with the other logs' (χ² {c.chi2[b]:.4g} on "
               f"{c.dof[b]} coefficients, p = {c.p_value[b]:.2g} < {c.alpha:g}/{len(logs)}): "
               "another vehicle, or its damping changed")
        print(f"{'kept (--keep-all)' if keep_all else 'left out'}: {logs[b].name}: {why}"
              + ("" if keep_all else "; --keep-all pools it anyway"), file=sys.stderr)
        out[logs[b].name] = why
    if keep_all:
        return {}
    logs[:] = [g for k, g in enumerate(logs) if k not in c.left_out]
    return out


def run_pooled(args: argparse.Namespace, vehicle: Vehicle, paths: list[str]) -> int:
    """Several logs: reduce each on Dask, fit them pooled, test the drift between them."""
    check_pooled_options(args)
    t0 = time.perf_counter()
    model, nominal = structure_of(args, vehicle)
    prior, prior_std = prior_of(model, nominal, prior_spec(args, vehicle))
    with reduce_all(paths, args, prior, prior_std) as (logs, failed, map_logs):
        failed.update(inconsistent_logs(logs, args.keep_all))
        extent = pooled_extent(logs, map_logs)
        options = FitOptions(method=args.method, cutoff=args.cutoff,
                             speed_range=tuple(speed_limits(vehicle, force=extent.force)))
        result = pooled_fit(logs, model, vehicle.body, options, map_logs, prior, prior_std,
                            extent)
        # the samples come here for the report only
        samples = Samples.concatenate(map_logs(samples_of)) if args.report else None
    if not (args.structure or args.terms or args.no_select):
        print(f"note: the logs are pooled on {vehicle.name}'s preset terms: the default's "
              "search for terms the preset misses runs on one log (dampest identify LOG "
              "--out one.yaml), then pool with --structure one.yaml; --no-select says the "
              "preset is meant", file=sys.stderr)
    print(f"{len(logs)} logs pooled ({len(failed)} left out): {extent.n} samples "
          f"({extent.duration:.0f} s), {result.method}, condition number "
          f"{result.cond:.3g}, {time.perf_counter() - t0:.1f} s")
    print(report_table(result, prior))
    print()
    print(table(("dof", "RMSE", "NSE", "CV RMSE (log fifths)"),
                [(DOF_NAMES[i], float(result.rmse[i]), float(result.r2[i]),
                  float(result.cv_rmse[i])) for i in range(6)]))
    for name, why in result.flags.items():
        print(f"not identified: {name}: {why}")
    for name, why in result.constrained.items():
        print(f"constrained: {name}: {why}")
    print()
    print(axis_text(result))
    more: dict[str, Any] = {"logs": [g.name for g in logs],
                            "logs_left_out": list(failed) or ["none"]}
    if len(logs) > 1:
        d = drift(logs)
        print(f"\ndrift between the {len(logs)} logs (χ² test per coefficient, "
              f"family-wise α = {d.alpha:g}):")
        print(drift_table(d, result))
        if d.moved.any():
            print(log_table(d))
        more["drift_changed"] = [n for n, m in zip(d.names, d.moved, strict=True) if m] \
            or ["none"]
        if args.drift_plot:
            from dampest_ros.report.figures import parameter_units
            plot_drift(Path(args.drift_plot), d, result, parameter_units(model))
            print(f"wrote {args.drift_plot}")
    if args.out:
        write_model(Path(args.out), result, model, vehicle, source=", ".join(paths),
                    flown=extent.flown, more=more)
        print(f"wrote {args.out}")
    if samples is not None:
        from dampest_ros.report.identify import write_report  # matplotlib: only for a report
        page = write_report(args.report, samples, model, vehicle.body, result, prior=prior,
                            title=f"Damping of {vehicle.name}, {len(logs)} logs pooled",
                            source=", ".join(g.name for g in logs), cutoff=args.cutoff)
        print(f"wrote {page}")
    return 0


def run_rls(args: argparse.Namespace, vehicle: Vehicle) -> int:
    """``--method rls``: the bag's sensor messages in stamp order through the online
    preprocessor and the estimator node's RLS; print the table, write the model."""
    t0 = time.perf_counter()
    delay = str(args.delay).strip().lower()
    unsupported = [opt for opt, used in (("--select", args.select), ("--report", args.report),
                                         ("--delay", delay == "auto" or float(delay) != 0.0),
                                         ("--columns", args.columns),
                                         ("--start", args.start is not None),
                                         ("--end", args.end is not None),
                                         ("--holdout", args.holdout is not None)) if used]
    if unsupported:
        raise DataError(f"--method rls does not take {', '.join(unsupported)} (batch methods "
                        "only)")
    if not 0.9 <= args.forgetting_factor <= 1.0:
        raise ConfigError("--forgetting-factor", f"must be in [0.9, 1], got "
                                                 f"{args.forgetting_factor:g} (1: every sample "
                                                 "weighs the same; 0.999: a memory of about "
                                                 "1000 samples)")
    path = Path(args.input)
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist")
    if not is_bag(path):
        raise DataError(f"--method rls replays the sensor messages of a bag (rosbag2 "
                        f"directory or ROS 1 .bag file); {path} is not one (a CSV holds "
                        "samples, not messages)")
    summary = bag_summary(path)
    topics = bag_topics(path, vehicle, args)
    check_options(args, args.rate, summary.duration, resample=True)
    types = {t.lstrip("/"): i.msgtype for t, i in summary.topics.items()}
    for role in ("imu", "dvl"):
        found = types.get(topics[role], "")
        if found in ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped"):
            raise DataError(f"--method rls reads an IMU and a DVL; {topics[role]} ({role}) "
                            f"carries {found}: identify it with a batch method (the default)")
    if topics["pressure"] not in types:
        del topics["pressure"]  # optional, as in the batch path
    if "wrench" in topics:
        del topics["thrusters"]  # τ from the body wrench: the thruster topic is not read
    rec = read_bag(path, list(topics.values()))
    # filterpy's Kalman filters import scipy.stats (~1 s): only for --method rls
    from dampest_ros.core.online.preprocessor import OnlinePreprocessor
    pre = OnlinePreprocessor(vehicle.thrusters, vehicle.body.gravity, vehicle.body.rho,
                             OnlineConfig(rate=args.rate, max_dvl_gap=args.max_gap),
                             mounting=vehicle.mounting)
    structure = structure_of(args, vehicle)[0] if args.structure else None
    est = DampingIdentifier(vehicle, None if structure else term_list(args.terms) or None,
                            prior=prior_spec(args, vehicle), structure=structure).online(
        EstimatorConfig(forgetting_factor=args.forgetting_factor, rate=args.rate,
                        cutoff=args.cutoff))
    stamps: list[float] = []
    for sample in pre.run(rec, topics):
        stamps.append(sample.t)
        est.add_sample(sample)
    est.process(force=True)
    if est.counts["used"] == 0:
        raise DataError(no_rls_sample(rec[topics["imu"].lstrip("/")].stamp,
                                      np.asarray(stamps), pre.cfg, est.regression.settle))
    d = est.rls.diagnostics(condition=True)
    c = pre.counts
    roles = [r for r in (*DEFAULT_TOPICS, "wrench") if r in topics or r == "pressure"]
    print(f"{args.input}: {sum(c[r] for r in roles)} messages (" +
          ", ".join(f"{c[r]} {r}" for r in roles) + f"), {c['samples']} samples, "
          f"{est.counts['used']} used by the RLS, λ = {args.forgetting_factor:g}, "
          f"condition number {d.condition_number:.3g}, {time.perf_counter() - t0:.1f} s")
    rejected = {k: c[k] for k in ("rejected_nonfinite", "rejected_out_of_order",
                                  "rejected_stale", "dvl_outliers", "clock_resets") if c[k]}
    if d.outliers:
        rejected["samples beyond the innovation gate (outliers)"] = d.outliers
    if rejected:
        print("rejected: " + ", ".join(f"{n} {k}" for k, n in rejected.items()))
    for role, (found, n) in pre.foreign_frames.items():  # not the sensors: section's frame_id
        print(f"{path.name}: warning: " + frame_id_note(
            topics[role], n, found, getattr(vehicle.mounting, role).frame_id), file=sys.stderr)
    ci = 1.959964 * est.theta_std
    print(table(("parameter", "estimate", "std", "95% low", "95% high", "prior"),
                [(n, float(th), float(sd), float(th - w), float(th + w), float(p0))
                 for n, th, sd, w, p0 in zip(est.names, est.theta, est.theta_std, ci,
                                             est.prior_theta, strict=True)]))
    for dof in d.unexcited:
        print(f"not excited: {dof} (no term's force reaches {est.rls.config.min_excitation:g} "
              "residual standard deviations; a large residual is a model misfit: try dampest "
              "identify --select)")
    if args.out:
        save_model(Path(args.out), est.to_model(1, source=str(args.input), method="rls"))
        print(f"wrote {args.out}")
    return 0


def no_rls_sample(imu: np.ndarray, stamps: np.ndarray, cfg: OnlineConfig,
                  settle: float) -> str:
    """Why the RLS used no sample of a log, and what it needs.

    Parameters
    ----------
    imu : ndarray, shape (m,)
        Stamps of the IMU messages (s).
    stamps : ndarray, shape (n,)
        Stamps of the online preprocessor's samples (s).
    cfg : OnlineConfig
        The preprocessor's settings: ``rate`` (``--rate``, Hz) and ``max_imu_gap`` (s).
    settle : float
        Seconds after each restart of the RLS's filter whose samples only settle it.
    """
    head = f"--method rls used 0 of {len(stamps)} samples"
    step = float(np.median(np.diff(imu))) if len(imu) > 1 else math.inf
    if step > cfg.max_imu_gap:
        return (f"{head}: the IMU comes at {1.0 / step:.3g} Hz, and the online path restarts "
                f"its inertial filters at every IMU step over {cfg.max_imu_gap:g} s; it "
                "needs an IMU well above --rate: use a batch method (the default)")
    seen = 1.0 / float(np.median(np.diff(stamps))) if len(stamps) > 1 else 0.0
    if seen < cfg.rate / 1.5:
        return (f"{head}: they come at {seen:.3g} Hz but the RLS runs at --rate "
                f"{cfg.rate:g} Hz, so every step restarts its filter before it settles; "
                f"give --rate {math.floor(seen):d} (with --cutoff below {seen / 2:.3g} Hz) "
                "or use a batch method")
    return (f"{head}: no gap-free stretch of the log is longer than the {settle:g} s the "
            "filter needs to settle; use a batch method")


def selection_table(selection: Selection) -> str:
    """The forward-selection path (each added term with BIC, AIC, its error reduction), the
    held-out R² per DOF before and after, the candidates left out with the reason, and both
    estimates of each chosen memory state."""
    rows = [(st.added, st.n_params, st.bic, st.aic,
             f"{st.err:.1%}" if st.err else "") for st in selection.steps]
    rates = "".join(f"\n{k} = {v:.4g} 1/s" for k, v in selection.rates.items())
    before, after = selection.cv_r2
    r2 = ("held-out R² per DOF (5 contiguous time folds, each predicted from the others):\n"
          + table(("dof", "base", "selected"), [(FORCE_NAMES[i], f"{before[i]:.4f}",
                                                  f"{after[i]:.4f}") for i in range(6)]))
    dropped = ""
    if selection.dropped:
        groups: dict[str, list[str]] = {}
        for name, why in selection.dropped.items():
            # one line per reason and column (the rows differ only in the force letter)
            groups.setdefault(why.split(" (|corr|")[0].replace(name[0] + "_", "F_"),
                              []).append(name)
        dropped = "\nleft out of the search:\n" + \
            "\n".join(f"  {', '.join(names)}: {why}" for why, names in groups.items())
    return ("term selection (stepwise over the damping library; a term must raise the "
            f"held-out R² of 5 contiguous time folds, lower BIC by 10 and remove ≥ {MIN_ERR:.0%} "
            f"of its DOF's residual ({MIN_ERR_BESIDE_ELEMENTS:.0%} beside element forces); − marks "
            "a removal):\n"
            + table(("model", "params", "BIC", "AIC", "error reduction"), rows) + rates
            + "\n" + r2 + dropped + "".join("\n" + ev.describe() for ev in selection.memory)
            + "\n")


def element_drag_table(selection: Selection | None) -> str:
    """The element drag search of a selection: its path (the one-standard-error cut) and
    the held-out R² per DOF of the base without and with the kept drags."""
    found = None if selection is None else selection.points
    if found is None:
        return ""
    before, after = found.r2
    path = table(("term", "held-out Σ(1 − R²)", "± standard error", "kept"),
                 [(n, f"{e:.5f}", f"{se:.5f}", "yes" if k <= found.steps else "no")
                  for k, (n, e, se) in enumerate(found.path)])
    r2 = table(("dof", "held-out R² base", "with element drags"),
               [(FORCE_NAMES[i], f"{before[i]:.4f}", f"{after[i]:.4f}") for i in range(6)])
    return (f"element drags (the drag of an element, or its lift, on its own "
            f"velocity v + ω × r at a point of the body; {len(found.chosen)} kept, "
            f"{found.steps} of the path's {len(found.path) - 1} steps (a mirror pair, ± y, "
            "may enter as one), "
            "blocked cross-validation and the one-standard-error rule, the six DOFs fitted "
            f"together), searched before the library terms:\n{path}\n{r2}"
            + (f"\ntaken out once the library terms joined (no longer lowering BIC by 10 in "
               f"any DOF), and the library searched again without them: "
               f"{', '.join(found.pruned)}" if found.pruned else ""))


def default_selection(samples: Samples, model: DampingModel, vehicle: Vehicle,
                      args: argparse.Namespace) -> DampingModel:
    """The preset's terms, and where they misfit the data, the terms the data select there
    (:func:`misfit_terms`): one line per misfit DOF and, unless ``--no-select`` (or
    ``--structure``), per misfit DOF the terms of the search, with or without the element
    drags first, that predicts it better (printed per DOF). Without a misfit the model is the
    preset's."""
    with Elapsed("checking the preset's terms against the term library"):
        found = misfit_terms(samples, model, vehicle.body, args.cutoff)
    if found is None or not found.rows:
        return model
    for i in found.rows:
        print(f"misfit: {FORCE_NAMES[i]}: held-out R² {found.before[i]:.3f} with the preset's "
              f"terms, {found.after[i]:.3f} with {len(found.added[i])} library terms added: "
              f"the residual is {found.ratio(i):.0f}× what the data allow")
    if args.no_select or args.structure:
        print("the damping structure misses physics in these data; without --no-select (or "
              f"--structure) identify adds the library terms: dampest identify {args.input} "
              f"--vehicle {args.vehicle}")
        return model
    with Elapsed("searching element drags, then the library again"):
        found = with_element_drags(found, samples, model, vehicle.body, args.cutoff,
                                   element_drags(vehicle))
    print(element_drag_table(found.drags))
    print("terms added by selection in the DOFs that misfit (blocked cross-validation, BIC "
          "and the one-standard-error rule; each DOF's from the search, with or without the "
          "element drags first, that predicts it better: "
          f"{', '.join(FORCE_NAMES[i] for i in found.taken) or 'none'} with them; --no-select: "
          "the preset's terms alone):")
    print(added_table(model.parameter_names, found.added, found.before, found.after))
    return found.model


def added_table(kept: list[str], added: dict[int, list[str]], before: np.ndarray,
                after: np.ndarray) -> str:
    """Per DOF: the number of the preset's terms in the model (``kept``, names), the terms
    selection added in the DOFs of ``added`` (row → names), and the held-out R² (5 contiguous
    time folds) with the preset's terms (``before``) and with the added ones (``after``), both
    shape (6,)."""
    rows = []
    for i in range(6):
        new = added.get(i, [])
        rows.append((FORCE_NAMES[i], sum(force_dof(n) == i for n in kept), len(new),
                     ", ".join(new) or "-", f"{before[i]:.4f}",
                     f"{after[i]:.4f}" if i in added else ""))
    return table(("dof", "preset", "added", "added terms", "held-out R² preset", "with added"),
                 rows)


def term_origin(preset: DampingModel, model: DampingModel) -> dict[str, list[str]]:
    """For the model file: the parameters of ``model`` from the preset (``preset_terms``) and
    those the term selection added (``selected_terms``), ``["none"]`` for an empty list."""
    names = model.parameter_names
    ours = [n for n in names if n in preset.parameter_names]
    return {"preset_terms": ours or ["none"],
            "selected_terms": [n for n in names if n not in ours] or ["none"]}


def force_dof(name: str) -> int:
    """The DOF whose force equation a coefficient sits in (``N_rv`` → 5), −1 if none."""
    head = name.split("_", 1)[0]
    return FORCE_NAMES.index(head) if head in FORCE_NAMES else -1


def unpredictive(names: list[str], scores: dict[str, np.ndarray]) -> list[str]:
    """One line per DOF whose held-out R² is below 0, naming its coefficients: they fit the
    training part but predict the held-out part worse than its mean does."""
    lines = []
    for i in np.flatnonzero(scores["nse"] < 0):
        mine = [n for n in names if force_dof(n) == i]
        lines.append(f"not predictive: {FORCE_NAMES[i]}: held-out R² {scores['nse'][i]:.3g} "
                     f"< 0, so {', '.join(mine) or 'its coefficients'} are not usable as "
                     "identified: the structure misses this DOF's physics or the held-out "
                     "part leaves the flown envelope (try --select, or more excitation)")
    return lines


def report_table(result: Fit, prior: np.ndarray,
                 heldout: dict[str, np.ndarray] | None = None) -> str:
    """Parameter table: estimate, std, 95 % interval, prior and what the data determine.

    A parameter held at its prior shows no estimate ("held at prior"); one that is only part
    of a combination, poorly determined or held by the dissipativity constraint shows its
    value with the status (not identified); one identified in a DOF whose held-out R²
    (``heldout["nse"]``, shape (6,)) is below 0 says so; the reasons follow the table."""
    ci = result.interval()
    members = {n for c in result.combinations for n in c.names}
    bad = set() if heldout is None else set(np.flatnonzero(heldout["nse"] < 0).tolist())
    rows: list[tuple[str | float, ...]] = []
    for j, name in enumerate(result.names):
        if result.held[j]:
            rows.append((name, "held at prior", "", "", "", float(prior[j]),
                         "not identified"))
            continue
        status = ("not predictive (held-out R² < 0)" if force_dof(name) in bad else
                  "identified" if result.identified[j] else
                  "constrained, not identified" if name in result.constrained else
                  "combination only, not identified" if name in members else
                  "poorly determined, not identified")
        rows.append((name, float(result.theta[j]), float(result.std[j]), float(ci[j, 0]),
                     float(ci[j, 1]), float(prior[j]), status))
    return table(("parameter", "estimate", "std", "95% low", "95% high", "prior", "status"),
                 rows)


def axis_text(result: Fit) -> str:
    """The pure-axis check (:mod:`~dampest_ros.core.identification.axis_check`) per DOF: the
    law a s + b s|s| of the samples along the axis against the model's, the Birge ratio and
    the σ scale it set, or that the DOF was not flown along its axis."""
    axes = result.axes
    if axes is None:
        return "pure-axis check: not run"
    if not axes.flown.any():
        return ("pure-axis check: no DOF was flown along its axis, so the pure-axis "
                "coefficients (X_u, X_u|u|, ...) are extrapolated from mixed motion and σ "
                "holds the noise only, not the model form's error there; fly pure-axis legs "
                "(dampest simulate --protocol axes shows them) to measure and check them")
    rows: list[tuple[str | float, ...]] = []
    for k in range(6):
        if not axes.flown[k]:
            rows.append((DOF_NAMES[k], int(axes.n[k]), "", "", "", "", "",
                         "not flown: extrapolated"))
            continue
        rows.append((DOF_NAMES[k], int(axes.n[k]), *(float(x) for x in axes.measured[k]),
                     *(float(x) for x in axes.modelled[k]), float(axes.ratio[k]),
                     f"σ × {axes.scale[k]:.2g}" if axes.scale[k] > 1 else "agrees"))
    head = (f"pure-axis check: the damping along each axis, a s + b s|s|, from the samples "
            f"flown along it (other DOFs within {CONE:.0%} of its speed share) against the "
            "model's on the axis itself at the same speeds; where they differ beyond σ "
            "(Birge ratio R > 1) the σ of that row's parameters is scaled by R")
    return "\n".join([head, table(("dof", "samples", "a data", "b data", "a model",
                                    "b model", "R", "σ"), rows)])


def axis_record(result: Fit) -> dict[str, Any]:
    """The pure-axis check for the model file: per DOF name, samples, the two laws and R
    (or ``not flown``)."""
    axes = result.axes
    if axes is None:
        return {}
    return {"axis_check": {
        DOF_NAMES[k]: ({"samples": int(axes.n[k]),
                        "data_ab": [float(x) for x in axes.measured[k]],
                        "model_ab": [float(x) for x in axes.modelled[k]],
                        "birge_ratio": float(axes.ratio[k]),
                        "sigma_scale": float(axes.scale[k])}
                       if axes.flown[k] else f"not flown ({int(axes.n[k])} samples)")
        for k in range(6)}}


def heldout_note(held: Samples) -> str:
    """What was held out, in words."""
    return (f"the last {held.t[-1] - held.t[0]:.1f} s of the log ({len(held)} samples), not "
            "used by the fit")


def heldout_text(held: Samples, scores: dict[str, np.ndarray]) -> str:
    """The held-out table: R² (NSE) and RMSE of the damping force per DOF."""
    units = ("N", "N", "N", "N·m", "N·m", "N·m")
    return (f"held out: {heldout_note(held)}; damping force y = τ − M ν̇ − C(ν)ν − g(η) vs "
            "the model's D(ν)ν:\n"
            + table(("dof", "held-out R²", "held-out RMSE", "unit"),
                    [(FORCE_NAMES[i], float(scores["nse"][i]), float(scores["rmse"][i]),
                      units[i]) for i in range(6)]))


def write_model(path: Path, result: Fit, model: DampingModel, vehicle: Vehicle,
                source: str, heldout: dict[str, np.ndarray] | None = None,
                flown: np.ndarray | None = None, more: dict[str, Any] | None = None
                ) -> None:
    """Save a fit as the model YAML of ``vehicle`` (its identity) with the body's mass matrix,
    added mass and added-mass switches, its metrics, the coefficients the data did not
    determine (``model.identified`` false, ``model.held`` with the reason), the flown speeds
    (``flown_speeds``: per-DOF smallest and largest of ``flown``, ν of the fitted samples,
    the envelope exports check dissipativity on), with a held-out part, its per-DOF R² and
    RMSE (``heldout_r2``, ``heldout_rmse``) and the coefficients of the DOFs whose held-out
    R² is below 0 (``not_predictive``), and ``more`` entries (e.g. the logs pooled)."""
    more = {**(more or {}), **axis_record(result), "source": source}
    if heldout is not None:
        more["heldout_r2"] = [float(x) for x in heldout["nse"]]
        more["heldout_rmse"] = [float(x) for x in heldout["rmse"]]
        bad = set(np.flatnonzero(heldout["nse"] < 0).tolist())
        more["not_predictive"] = [n for n in result.names if force_dof(n) in bad] or ["none"]
    if flown is not None:
        more["flown_speeds"] = {"min": [float(x) for x in flown.min(axis=0)],
                                "max": [float(x) for x in flown.max(axis=0)]}
    save_model(path, result.to_model(model, vehicle.body, more, vehicle.identity))
