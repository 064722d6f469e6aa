"""dampest validate: score a model YAML on another log (rosbag2 or ROS 1 bag, or CSV).

The model (written by dampest identify --out, or any model file) is held fixed and
compared with a log it was not identified from, in two ways, per DOF:

  force:    the damping force the log demands, y = tau - M nu_dot - C(nu)nu - g(eta),
            against the model's D(nu)nu (plus fluid memory), both low-passed at --cutoff
            as identify does: R^2 = 1 - sum(r^2)/sum((y - mean y)^2) (the Nash-Sutcliffe
            efficiency of the force) and RMSE (N, N m);
  free run: the model integrated from the measured velocity at the start of the longest
            segment for --free-run seconds, driven by the measured tau and attitude, with
            no feedback from the measured velocity: NSE and RMSE of the velocity (m/s,
            rad/s).

M and C(nu)nu act as the vehicle's added_mass_terms say; u, v, w are taken as over ground
(DVL bottom lock) in still water, as identify and gap take them.

--out writes one row per sample (CSV, .csv.gz compressed), body FRD, N and N m, low-passed
at --cutoff (0: as logged):
  time
  damping_X .. damping_N   the model's D(nu)nu
  hydro_X .. hydro_N       everything the model attributes to the water: the acting
                           added-mass terms (M_A nu_dot, C_A(nu)nu, Munk moments) plus
                           D(nu)nu and fluid memory
  target_X .. target_N     tau - M nu_dot - C(nu)nu - g(eta)
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from dampest_ros.cli.common import (
    BAG_HELP,
    CSV_HELP,
    add_columns_option,
    add_cutoff_option,
    add_preprocess_options,
    add_topic_options,
    add_vehicle_option,
    add_window_options,
    describe,
)

if TYPE_CHECKING:
    import numpy as np

    from dampest_ros.core.physics.damping import DampingModel
    from dampest_ros.core.physics.rigid_body import RigidBody
    from dampest_ros.core.signals.samples import Samples

EXAMPLE = ("example:\n"
           "  dampest identify bags/run1 --vehicle bluerov2_heavy --out model.yaml\n"
           "  dampest validate model.yaml bags/run2 --vehicle bluerov2_heavy --out forces.csv\n"
           "  dampest validate model.yaml survey.bag --vehicle bluerov2_heavy")

FORCE_UNITS = ("N", "N", "N", "N·m", "N·m", "N·m")
VEL_UNITS = ("m/s", "m/s", "m/s", "rad/s", "rad/s", "rad/s")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of dampest validate."""
    describe(p, __doc__, EXAMPLE, BAG_HELP, CSV_HELP)
    p.add_argument("model", metavar="MODEL",
                   help="model YAML (ROS 2 parameters file), e.g. from dampest identify --out")
    p.add_argument("input", metavar="LOG",
                   help="rosbag2 directory (MCAP or SQLite3), ROS 1 .bag file, or .csv / "
                        ".csv.gz file in any flavour identify reads")
    add_vehicle_option(p)
    p.add_argument("--out", metavar="FORCES.csv",
                   help="write time, damping_X..N, hydro_X..N, target_X..N per sample here")
    add_cutoff_option(p, "none, the scores as logged")
    p.add_argument("--free-run", type=float, default=120.0, metavar="SECONDS",
                   help="length of the free run (s) from the start of the longest segment "
                        "(default: 120)")
    add_columns_option(p)
    add_window_options(p)
    add_topic_options(p)
    add_preprocess_options(p)


def model_forces(samples: Samples, model: DampingModel, body: RigidBody, theta: np.ndarray,
                 cutoff: float) -> dict[str, np.ndarray]:
    """Target, damping, memory and hydrodynamic force per sample, each shape (N, 6).

    ``target`` y = τ − M ν̇ − C(ν)ν − g(η); ``damping`` the static D(ν)ν; ``memory`` the
    fluid-memory force Σ c_m z_m; ``hydro`` = added-mass force as it acts
    (:meth:`RigidBody.added_mass_force`) + damping + memory. Body FRD, N and N·m, all
    low-passed at ``cutoff`` (Hz, 0: none) within each segment, as the fit sees them.
    """
    import numpy as np

    from dampest_ros.core.identification.validate import predicted_force
    from dampest_ros.core.signals.preprocess import zero_phase

    theta = np.asarray(theta, dtype=float)
    static = theta.copy()
    if model.term("freq") is not None:
        static[model.slice("freq")] = 0.0
    y, damping = predicted_force(samples, model, body, static, cutoff)
    memory = np.zeros_like(damping)
    if model.term("freq") is not None:
        memory = predicted_force(samples, model, body, theta - static, cutoff)[1]
    added = body.added_mass_force(samples.nu, samples.nu_dot)
    if cutoff > 0:
        for sl in samples.segments():  # segments, not samples
            added[sl] = zero_phase(added[sl], samples.rate, cutoff)
    return {"target": y, "damping": damping, "memory": memory,
            "hydro": added + damping + memory}


def run(args: argparse.Namespace) -> int:
    """Load model and log, print the per-DOF scores, write the forces."""
    import sys
    import time
    from pathlib import Path

    import numpy as np

    from dampest_ros.cli.common import check_outputs, table
    from dampest_ros.cli.inputs import cut, load_model_for, load_samples
    from dampest_ros.core.identification.validate import free_run_error, longest_segment, metrics
    from dampest_ros.core.physics.rigid_body import DOF_NAMES, FORCE_NAMES, ConfigError
    from dampest_ros.io.csv import write_table
    from dampest_ros.io.yaml_io import load_vehicle

    t0 = time.perf_counter()
    check_outputs(args, {"out": "forces.csv"})
    vehicle = load_vehicle(args.vehicle)
    mf, model, body = load_model_for(args.model, vehicle)
    if not args.cutoff >= 0:
        raise ConfigError("--cutoff", f"must be ≥ 0 Hz, got {args.cutoff}")
    if not 0 < args.free_run < np.inf:
        raise ConfigError("--free-run", f"must be a finite number of seconds > 0, got "
                                        f"{args.free_run}")
    samples = cut(load_samples(args.input, vehicle, args), args)
    forces = model_forces(samples, model, body, mf.theta, args.cutoff)
    force = metrics(forces["target"], forces["damping"] + forces["memory"])
    rows = longest_segment(samples, args.free_run)
    free = free_run_error(samples, model, body, mf.theta, rows)
    seconds = (rows.stop - rows.start - 1) / samples.rate
    print(f"{args.input}: {len(samples)} samples ({len(samples) / samples.rate:.0f} s in "
          f"{int(np.unique(samples.segment).size)} segment(s)); model {args.model} "
          f"({len(mf.theta)} parameters); {time.perf_counter() - t0:.1f} s")
    print(f"force: y = τ − M ν̇ − C(ν)ν − g(η) vs the model's D(ν)ν, low-passed at "
          f"{args.cutoff:g} Hz; free run: {seconds:.0f} s from the measured ν, driven by the "
          "measured τ")
    print(table(("dof", "force R²", "force RMSE", "unit", "free-run NSE", "free-run RMSE",
                 "unit"),
                [(f"{DOF_NAMES[i]}/{FORCE_NAMES[i]}", float(force["nse"][i]),
                  float(force["rmse"][i]), FORCE_UNITS[i], float(free["nse"][i]),
                  float(free["rmse"][i]), VEL_UNITS[i]) for i in range(6)]))
    if np.isfinite(free["diverged_after"][0]):
        print(f"free run: no score (—): the model's velocity diverged "
              f"{free['diverged_after'][0]:.1f} s after the start, although the integration is "
              "sub-stepped for its stiffness: "
              "the identified model is unstable on this log's τ (the force scores above "
              "still hold; check the fit's held-out R² and dissipativity)", file=sys.stderr)
    if args.out:
        columns = {"time": samples.t}
        for kind in ("damping", "hydro", "target"):
            columns.update({f"{kind}_{n}": forces[kind][:, i]
                            for i, n in enumerate(FORCE_NAMES)})
        write_table(Path(args.out), columns)
        print(f"wrote {args.out}")
    return 0
