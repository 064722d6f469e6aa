"""``dampest identify``: identify the damping model from a bag or a CSV file."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from dampest_ros.cli.common import (
    add_preprocess_options,
    add_topic_options,
    load_samples,
    restrict_terms,
    table,
)
from dampest_ros.core.batch import METHODS, Fit, FitOptions, fit
from dampest_ros.core.damping import DampingModel
from dampest_ros.core.excitation import speed_limits
from dampest_ros.core.frequency import memory_impedance
from dampest_ros.core.rigid_body import DOF_NAMES, RigidBody
from dampest_ros.core.samples import Samples
from dampest_ros.core.selection import Selection, select_terms
from dampest_ros.io.yaml_io import load_model, load_vehicle, save_model
from dampest_ros.report import write_report

EXAMPLE = ("example: dampest identify bags/b600 --vehicle config/vehicles/bluerov2_heavy.yaml "
           "--out model.yaml")


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the sub-command."""
    p = sub.add_parser("identify", help="identify damping from a bag or CSV",
                       description=__doc__ + " INPUT is a rosbag2 directory (MCAP or SQLite3) "
                       "with IMU, DVL, pressure and thruster topics, or a CSV file in the seed "
                       "format (time,u,v,w,p,q,r,ax,ay,az,wx,wy,wz,depth,tau_X..tau_N).",
                       epilog=EXAMPLE)
    p.add_argument("input", help="rosbag2 directory or .csv file")
    p.add_argument("--vehicle", required=True,
                   help="vehicle preset (name or YAML): mass, added mass, thrusters, "
                        "nominal damping (the prior and the term structure)")
    p.add_argument("--terms", help="comma list of the preset's terms to identify, e.g. "
                                   "linear,quadratic (default: all terms of the preset)")
    p.add_argument("--method", choices=METHODS, default="wls",
                   help="ols, wls (per-DOF noise weights, default), ridge, bounded "
                        "(physical signs), map (Gaussian prior from --prior)")
    p.add_argument("--select", action="store_true",
                   help="choose extra terms by forward BIC selection: sway-yaw, heave-pitch "
                        "and lift cross-coupling, fluid memory per DOF (rate estimated)")
    p.add_argument("--prior", help="model YAML whose theta/theta_std are the MAP prior")
    p.add_argument("--cutoff", type=float, default=2.0,
                   help="low-pass (Hz) applied to the regression (default: 2)")
    p.add_argument("--columns", help="YAML column map for CSV input (their name: our name)")
    p.add_argument("--out", help="write the model YAML (a ROS 2 parameters file) here")
    p.add_argument("--report", metavar="DIR",
                   help="write an HTML report with plots (index.html + PNG) to DIR")
    p.add_argument("--truth", help="model YAML of the true coefficients (simulated data), "
                                   "shown in the report")
    add_topic_options(p)
    add_preprocess_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Read, preprocess, fit, print the table, write the model."""
    t0 = time.perf_counter()
    vehicle = load_vehicle(args.vehicle)
    model, nominal = restrict_terms(vehicle, args.terms)
    samples = load_samples(args.input, vehicle, args)
    if args.select:
        selection = select_terms(samples, model, vehicle.body, cutoff=args.cutoff)
        print(selection_table(selection))
        print(memory_check(samples, selection.model, vehicle.body))
        values = dict(zip(model.parameter_names, nominal, strict=True))
        model = selection.model
        nominal = np.array([values.get(n, 0.0) for n in model.parameter_names])
    prior, prior_std = nominal, None
    if args.prior:
        pm = load_model(args.prior)
        values = dict(zip(pm.parameter_names, pm.theta, strict=True))
        stds = dict(zip(pm.parameter_names, pm.theta_std, strict=True))
        prior = np.array([values.get(n, v) for n, v in zip(model.parameter_names, nominal,
                                                             strict=True)])
        prior_std = np.array([stds.get(n, np.inf) for n in model.parameter_names])
    options = FitOptions(method=args.method, cutoff=args.cutoff,
                         speed_range=tuple(speed_limits(vehicle)))
    result = fit(samples, model, vehicle.body, options, prior=prior, prior_std=prior_std)
    elapsed = time.perf_counter() - t0
    print(f"{args.input}: {len(samples)} samples ({len(samples) / samples.rate:.0f} s in "
          f"{int(samples.segment.max()) + 1} segment(s)), {result.method}, "
          f"condition number {result.cond:.3g}, {elapsed:.1f} s")
    print(report_table(result, prior))
    print()
    print(table(("dof", "RMSE", "NSE", "CV RMSE"),
                [(DOF_NAMES[i], float(result.rmse[i]), float(result.r2[i]),
                  float(result.cv_rmse[i])) for i in range(6)]))
    for name, why in result.flags.items():
        print(f"not identified: {name}: {why}")
    if args.out:
        write_model(Path(args.out), result, model, vehicle.body.M, source=str(args.input))
        print(f"wrote {args.out}")
    if args.report:
        truth = None
        if args.truth:
            tm = load_model(args.truth)
            truth = dict(zip(tm.parameter_names, tm.theta, strict=True))
        page = write_report(args.report, samples, model, vehicle.body, result, prior=prior,
                            truth=truth, title=f"Damping of {vehicle.name}",
                            source=str(args.input), cutoff=args.cutoff)
        print(f"wrote {page}")
    return 0


def selection_table(selection: Selection) -> str:
    """The forward-selection path: each added term with BIC, AIC and its error reduction."""
    rows = [(st.added, st.n_params, st.bic, st.aic,
             f"{st.err:.1%}" if st.err else "") for st in selection.steps]
    rates = "".join(f"\n{k} = {v:.4g} 1/s" for k, v in selection.rates.items())
    return ("term selection (forward, BIC; a term must remove ≥ 10 % of its DOF's residual):\n"
            + table(("model", "params", "BIC", "AIC", "error reduction"), rows) + rates + "\n")


def memory_check(samples: Samples, model: DampingModel, body: RigidBody) -> str:
    """Frequency-domain cross-check of each selected memory rate (Welch + rational fit)."""
    mem = model.term("freq")
    if mem is None:
        return ""
    static = DampingModel([t for t in model.terms if t.kind != "freq"])
    theta = fit(samples, static, body, FitOptions(gyro_bias=0.0, dvl_bias=0.0)).theta
    lines = []
    for d, lam in zip(mem.state_dofs, mem.rates, strict=True):
        imp = memory_impedance(samples, static, body, theta, int(d))
        lines.append(f"memory on {DOF_NAMES[int(d)]}: λ = {lam:.4g} 1/s (time domain), "
                     f"{imp.rate:.4g} 1/s (frequency domain, c = {imp.gain:.4g})")
    return "\n".join(lines) + "\n"


def report_table(result: Fit, prior: np.ndarray) -> str:
    """Parameter table: estimate, std, 95 % interval, prior; unidentified ones marked."""
    ci = result.interval()
    rows = []
    for j, name in enumerate(result.names):
        if name in result.flags:
            rows.append((name, "not identified", "", "", "", float(prior[j])))
        else:
            rows.append((name, float(result.theta[j]), float(result.std[j]), float(ci[j, 0]),
                         float(ci[j, 1]), float(prior[j])))
    return table(("parameter", "estimate", "std", "95% low", "95% high", "prior"), rows)


def write_model(path: Path, result: Fit, model: DampingModel, M: np.ndarray,
                source: str) -> None:
    """Save a fit as the model YAML with its metrics and the unidentified parameters."""
    unidentified = list(result.flags)
    ci = result.interval()
    save_model(path, result.names, result.theta, result.std, M, damping=model, extra={
        "source": source, "method": result.method, "samples": int(result.n),
        "ci95_low": [float(x) for x in ci[:, 0]], "ci95_high": [float(x) for x in ci[:, 1]],
        "nse": [float(x) for x in result.r2], "rmse": [float(x) for x in result.rmse],
        "condition_number": float(result.cond),
        "unidentified": unidentified or ["none"],
        "unidentified_reason": [result.flags[n] for n in unidentified] or ["none"]})
