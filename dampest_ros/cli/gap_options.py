"""dampest gap: where do a simulator model and measured data disagree, and what is missing?

Compares the model (--model, the damping model the user believes, with --vehicle for mass,
restoring data and thrusters) with a measured bag (rosbag2 or ROS 1) or CSV through the one-step
inverse-dynamics residual and a free run, localises the residual, then names the missing
physical effects one at a time by their held-out evidence (dampest_ros/core/gap/), until
no candidate is significant. Uses only what a real vehicle logs (IMU, DVL, pressure,
thruster state, or the CSV columns): never truth topics or simulator settings.
"""

from __future__ import annotations

import argparse

from dampest_ros.cli.common import (
    BAG_HELP,
    CSV_HELP,
    add_columns_option,
    add_cutoff_option,
    add_dask_options,
    add_preprocess_options,
    add_topic_options,
    add_vehicle_option,
    describe,
)

EXAMPLE = ("example (a simulated 'measurement' with a current the model does not know):\n"
           "  dampest simulate --duration 300 --effects 'current: [0.2, 0, 0]' --out "
           "bags/current\n"
           "  dampest gap bags/current --model bags/current/truth_model.yaml --vehicle "
           "bluerov2_heavy --report gap_report")

#: Default of --min-heldout (dampest_ros.core.gap.search.GapOptions.min_heldout; a test checks
#: the two agree).
MIN_HELDOUT = 0.03


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of dampest gap (its work: dampest_ros.cli.gap.run)."""
    describe(p, __doc__, EXAMPLE, BAG_HELP, CSV_HELP)
    p.add_argument("input", metavar="MEASURED", nargs="+",
                   help="rosbag2 directory (MCAP or SQLite3), ROS 1 .bag file, or .csv / "
                        ".csv.gz file from the vehicle; several (or a quoted glob, or a .txt "
                        "list) are pooled one after the other in time (read on Dask), the "
                        "last part held out")
    p.add_argument("--model", required=True, metavar="MODEL",
                   help="model YAML (ROS 2 parameters file) of the damping you believe, e.g. "
                        "the simulator's; its M is used as M_RB + M_A")
    add_vehicle_option(p)
    p.add_argument("--report", metavar="DIR",
                   help="write index.html, PNG figures and final_model.yaml here")
    p.add_argument("--out", metavar="MODEL",
                   help="write the model with the named effects (YAML) here")
    p.add_argument("--candidates", default="all",
                   help="comma list of candidate keys or families (current, buoyancy, "
                        "cg_offset, thrusters, added_mass, damping, memory, sensor_bias, "
                        "or keys such as thrust_gain, delay, linear.X_u, cross.Y_vr); "
                        "default: all")
    add_dask_options(p)
    p.add_argument("--max-steps", type=int, default=6, metavar="N",
                   help="name at most this many effects (default: 6)")
    add_cutoff_option(p)
    p.add_argument("--split", type=float, default=0.7,
                   help="share of the time used to fit; the rest is held out (default: 0.7)")
    p.add_argument("--min-heldout", type=float, default=MIN_HELDOUT,
                   help="smallest held-out reduction of the weighted residual power for an "
                        f"effect to count (default: {MIN_HELDOUT})")
    add_columns_option(p)
    add_topic_options(p)
    add_preprocess_options(p)
