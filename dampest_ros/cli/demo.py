"""``dampest demo``: simulate a BlueROV2 Heavy, identify its damping, compare with the truth.

The embedded default scenario: protocol B (ramped surge + PRBS on every DOF) for 300 s with
realistic sensor noise, written to an MCAP bag and identified offline from the bag alone.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np

from dampest_ros.cli import identify, simulate
from dampest_ros.cli.common import table
from dampest_ros.io.yaml_io import load_model


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the sub-command."""
    p = sub.add_parser("demo", help="simulate, identify and compare with the truth",
                       description=__doc__)
    p.add_argument("--out", default="runs/demo", help="output folder, replaced if it exists "
                                                      "(default: runs/demo)")
    p.add_argument("--duration", type=float, default=300.0, help="seconds (default: 300)")
    p.add_argument("--vehicle", default="bluerov2_heavy", help="preset (default: bluerov2_heavy)")
    p.add_argument("--seed", type=int, default=1)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Simulate → bag → identify → table against the truth."""
    out = Path(args.out)
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    bag = out / "bag"
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    simulate.add_parser(sub)
    identify.add_parser(sub)
    print(f"== simulate {args.vehicle}, protocol B, {args.duration:.0f} s → {bag}")
    sim_args = parser.parse_args(["simulate", "--vehicle", args.vehicle, "--protocol", "B",
                                  "--duration", str(args.duration), "--seed", str(args.seed),
                                  "--out", str(bag)])
    simulate.run(sim_args)
    print(f"\n== identify from the bag alone → {out / 'model.yaml'}")
    id_args = parser.parse_args(["identify", str(bag), "--vehicle", args.vehicle,
                                 "--out", str(out / "model.yaml"), "--report",
                                 str(out / "report"), "--truth",
                                 str(bag / "truth_model.yaml")])
    identify.run(id_args)
    truth = load_model(bag / "truth_model.yaml")
    est = load_model(out / "model.yaml")
    t = dict(zip(truth.parameter_names, truth.theta, strict=True))
    rows = []
    for name, value, std in zip(est.parameter_names, est.theta, est.theta_std, strict=True):
        err = (value - t[name]) / t[name] * 100 if t[name] else float("nan")
        rows.append((name, float(t[name]), float(value), float(std), err,
                     "yes" if abs(value - t[name]) <= 1.96 * std else "NO"))
    print("\n== estimate against the simulator's truth")
    print(table(("parameter", "truth", "estimate", "std", "error %", "truth in 95%"), rows))
    worst = np.nanmax(np.abs([r[4] for r in rows]))
    print(f"\nlargest relative error of a nonzero coefficient: {worst:.2f} %")
    return 0
