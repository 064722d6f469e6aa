"""dampest simulate: fly a protocol in the simulator and write a rosbag2 (MCAP) bag.

The bag holds what a vehicle's sensors would log (IMU, DVL, pressure, thruster state) and the
truth (truth/odom); with the native backend the true coefficients are written next to it as
truth_model.yaml, for comparing an identification with.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from dampest_ros.cli.common import add_protocol_option, add_vehicle_option, describe

if TYPE_CHECKING:
    from dampest_ros.core.physics.vehicle import Vehicle

EXAMPLE = ("example:\n  dampest simulate --vehicle bluerov2_heavy --protocol B --duration 600 "
           "--seed 1 --out bags/b600")

#: The plants (dampest_ros.core.simulation.simulate.BACKENDS; a test checks the two agree).
BACKENDS = ("native", "mujoco")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of dampest simulate."""
    describe(p, __doc__, EXAMPLE)
    add_vehicle_option(p, "bluerov2_heavy")
    add_protocol_option(p)
    p.add_argument("--duration", type=float, default=600.0, metavar="S",
                   help="simulated seconds (default: 600)")
    p.add_argument("--seed", type=int, default=1,
                   help="seed of the excitation and the sensor noise (default: 1)")
    p.add_argument("--out", required=True, metavar="BAG",
                   help="bag directory to create (must not exist)")
    p.add_argument("--csv", metavar="FILE",
                   help="also write the synchronised samples as CSV (seed format)")
    p.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap",
                   help="rosbag2 storage format (default: mcap)")
    p.add_argument("--backend", choices=BACKENDS, default="native",
                   help="the plant: native (our own equations, default; writes the true "
                        "coefficients as truth_model.yaml) or mujoco (MuJoCo's ellipsoid "
                        "fluid model, physics we did not write: the vehicle needs a geometry: "
                        "block, e.g. --vehicle torpedo_auv; MuJoCo's own fluid wrench is "
                        "recorded on truth/hydro_wrench)")
    p.add_argument("--dt", type=float, default=0.02, metavar="S",
                   help="integration step in s (default: 0.02)")
    p.add_argument("--amplitude", type=float, default=1.0,
                   help="scale of the protocol's amplitudes (default: 1)")
    p.add_argument("--effects", metavar="YAML",
                   help="hidden effects to switch on, a YAML mapping (file or inline), e.g. "
                        "'current: [0.2, 0, 0]' (the fields of Effects in "
                        "dampest_ros/core/simulation/effects.py)")
    p.add_argument("--sensors", metavar="YAML",
                   help="sensor settings (rates, noise), a YAML mapping (file or inline)")


def run(args: argparse.Namespace) -> int:
    """Simulate, measure, write the bag, the truth model and optionally the CSV."""
    import time
    from pathlib import Path

    import numpy as np

    from dampest_ros.cli.common import Elapsed, check_outputs, speed_table, table
    from dampest_ros.core.identification.model import Model
    from dampest_ros.core.signals.preprocess import PreprocessConfig, preprocess
    from dampest_ros.core.simulation.effects import Effects, true_vehicle
    from dampest_ros.core.simulation.excitation import protocol
    from dampest_ros.core.simulation.sensors import SensorBias, SensorConfig, measure
    from dampest_ros.core.simulation.simulate import run as run_sim
    from dampest_ros.io.bag import write_bag
    from dampest_ros.io.csv import samples_to_columns, write_csv
    from dampest_ros.io.yaml_io import load_vehicle, read_mapping, save_model

    out = Path(args.out)
    if out.exists():
        raise FileExistsError(f"{out} exists; choose a new --out")
    check_outputs(args, {"csv": "samples.csv"}, ("out",))
    if not 0 < args.amplitude < np.inf:
        raise ValueError(f"--amplitude: must be a finite scale > 0 of the protocol's "
                         f"amplitudes, got {args.amplitude:g} (default 1)")
    vehicle = load_vehicle(args.vehicle)
    effects = Effects.from_dict(read_mapping(args.effects)) if args.effects else Effects()
    sensors = SensorConfig.from_dict(read_mapping(args.sensors)) if args.sensors \
        else SensorConfig()
    t0 = time.perf_counter()
    with Elapsed(f"simulating {args.duration:g} s of {vehicle.name}, protocol {args.protocol}"):
        excitation = protocol(args.protocol, vehicle, args.duration, seed=args.seed,
                              amplitude=args.amplitude)
        traj = run_sim(vehicle, excitation, effects, dt=args.dt, backend=args.backend)
        bias = SensorBias(effects.gyro_bias, effects.accel_bias, effects.dvl_bias)
        rec = measure(traj, vehicle.body.rho, vehicle.body.gravity, sensors, bias,
                      seed=args.seed, mounting=vehicle.mounting)
        write_bag(out, rec, storage=args.storage)
    if args.backend == "native":
        truth = true_vehicle(vehicle, effects)
        save_model(out / "truth_model.yaml", Model(
            truth.damping.parameter_names, truth.theta, np.zeros(truth.damping.n_params),
            truth.body.M, damping=truth.damping,
            extra={"source": "dampest simulate", "vehicle": vehicle.name,
                   "protocol": args.protocol, "duration": float(args.duration),
                   "seed": int(args.seed), "effects": str(effects.as_dict() or "none")},
            M_A=truth.body.added_mass, added_mass_terms=truth.body.added_mass_terms,
            identity=vehicle.identity))
    if args.csv:
        samples = preprocess(rec, vehicle, PreprocessConfig())
        write_csv(args.csv, samples_to_columns(samples))
    elapsed = time.perf_counter() - t0
    print(f"wrote {out} ({args.storage}) in {elapsed:.1f} s: {args.duration:.0f} s of "
          f"{vehicle.name}, protocol {args.protocol}, seed {args.seed} "
          f"({args.duration / elapsed:.0f}x real time)")
    print(table(("topic", "messages", "rate Hz"),
                [(k, len(s), (len(s) - 1) / max(float(s.stamp[-1] - s.stamp[0]), 1e-9))
                 for k, s in rec.items()]))
    print("\nbody velocity (FRD, m/s and rad/s):")
    print(speed_table(traj.nu))
    if excitation.design is not None:
        d = excitation.design
        print("\n" + table(("damping regressor condition number (scaled)", "value"),
                           [("random FFS within the limits (median)", d.cond_random),
                            ("start (random)", d.cond_start), ("designed", d.cond),
                            ("improvement over random", d.cond_random / d.cond)]))
    if effects.as_dict():
        print(f"\nhidden effects: {effects.as_dict()}")
    if args.backend == "mujoco":
        print("\ntruth: MuJoCo's fluid wrench on truth/hydro_wrench (FLU); no truth_model.yaml "
              "(MuJoCo's drag is not of our term form)")
        _added_mass_note(vehicle)
    return 0


def _added_mass_note(vehicle: Vehicle) -> None:
    """Say so when the vehicle does not describe the MuJoCo plant's added mass faithfully."""
    import numpy as np

    from dampest_ros.core.simulation.mujoco_backend import plant_vehicle

    plant = plant_vehicle(vehicle).body
    body = vehicle.body
    if (body.added_mass_terms != plant.added_mass_terms
            or not np.allclose(body.added_mass, plant.added_mass, rtol=1e-4,
                               atol=1e-4 * np.abs(plant.added_mass).max())):
        rows = ", ".join("[" + ", ".join(f"{x:.6g}" for x in r) + "]"
                         for r in plant.added_mass)
        print(f"note: {vehicle.name}'s added mass is not the plant's. To identify this bag "
              "with a faithful description, give the vehicle\n"
              f"  added_mass: [{rows}]\n"
              "  added_mass_terms: {inertial: false, coriolis: true, munk: true}\n"
              "(MuJoCo applies only the velocity terms of its geometry's added mass)")
