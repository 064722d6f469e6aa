"""dampest identify: identify the damping model from a bag or a CSV file.

Batch methods (--method ols, wls, ridge, bounded, map) preprocess the whole log at once
(dampest_ros/core/signals/preprocess.py, dampest_ros/core/identification/batch.py). --method rls
instead replays the bag's sensor messages through the online path of the nodes: the causal
preprocessor (messages in stamp order), the samples as the dampest/* topics carry them, and the
estimator node's recursive least squares with its default prior and settings, so that its
result is the estimator node's on the same data.

Terms: the preset's (the vehicle file's damping section) and, in each DOF where they misfit
the data, the element drags and library terms the data select (element drags first: the drag
of an appendage at a point r of the body on its own velocity v + ω × r, one coefficient in a
force and its moments, at the vehicle file's geoms off the origin, else at ± L/2 along x and
± L/4 along y and z): a DOF misfits when its held-out R² with the
preset's terms is below 0.999 and its residual more than 3 times what a library search on the
same data leaves. The number of terms added is the data's (blocked cross-validation over 5
contiguous time folds with a guard of two filter periods at each boundary, BIC, and the
one-standard-error rule, simplest and physically named terms first); the misfit lines, the
added terms per DOF and, in the model file, which terms are the preset's (preset_terms) and
which selection added (selected_terms) are printed and written. Why by default: on physics the
preset does not describe (MuJoCo's fluid model) its terms alone leave held-out force R² of
0.54-0.97 where the added terms reach 0.99-1.00, and on data it describes nothing is added.
--no-select keeps the preset's terms alone; --select searches every DOF, memory included, and
may drop preset terms. Pooled logs and --method rls fit the preset's terms (or --structure).

INPUT is a bag (a rosbag2 directory, MCAP or SQLite3, or a ROS 1 .bag file) with IMU, DVL,
pressure and thruster (or body wrench) topics, or a CSV log.
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
    add_window_options,
    describe,
)

EXAMPLE = ("examples:\n"
           "  dampest identify bags/b600 --vehicle bluerov2_heavy --out model.yaml\n"
           "  dampest identify bags/b600 --vehicle bluerov2_heavy --select --holdout 0.3 "
           "--report report\n"
           "  dampest identify 'bags/dive_*' --vehicle bluerov2_heavy --workers 2 "
           "--drift-plot drift.png --out pooled.yaml\n"
           "  dampest identify survey.bag --vehicle bluerov2_heavy --wrench-topic /wrench "
           "--out model.yaml")

#: Batch methods (dampest_ros.core.identification.batch.METHODS; a test checks the two agree).
METHODS = ("ols", "wls", "ridge", "bounded", "map")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of dampest identify (its work: dampest_ros.cli.identify.run)."""
    describe(p, __doc__, EXAMPLE, BAG_HELP, CSV_HELP)
    p.add_argument("input", metavar="INPUT", nargs="+",
                   help="rosbag2 directory, ROS 1 .bag file, .csv or .csv.gz file, or an "
                        "fsspec URL of one (e.g. s3://…, copied where it is read); several "
                        "(or a quoted glob pattern such as 'bags/dive_*', or a .txt file "
                        "listing logs one per line) are pooled into one model, each log "
                        "preprocessed on its own Dask worker, and the drift of every "
                        "coefficient between the logs is tested")
    add_vehicle_option(p)
    p.add_argument("--terms", help="comma list of the preset's terms to identify, e.g. "
                                   "linear,quadratic (default: all terms of the preset)")
    p.add_argument("--method", choices=(*METHODS, "rls"), default="wls",
                   help="ols, wls (per-DOF noise weights, default), ridge, bounded "
                        "(physical signs), map (Gaussian prior from --prior); rls: the "
                        "estimator node's recursive least squares on the bag's messages "
                        "replayed through the online preprocessing (bags only)")
    p.add_argument("--forgetting-factor", type=float, default=1.0, metavar="LAMBDA",
                   help="rls: forgetting factor λ in [0.9, 1] (default: 1, every sample "
                        "weighs the same)")
    chosen = p.add_mutually_exclusive_group()
    chosen.add_argument("--select", action="store_true",
                        help="search the whole damping library (linear, cross-flow v|r|, "
                             "bilinear u·w lift, speed-magnitude u‖v‖ and p‖ω‖ terms in every "
                             "force row, fluid memory per DOF with its rate) by blocked "
                             "cross-validation and BIC on top of the preset's terms, in every "
                             "DOF, and fit the sparse model found (the preset's terms the data "
                             "do not support go). Without it, identify already adds library "
                             "terms (no memory) in the DOFs where the preset's terms misfit the "
                             "data (a 'misfit' line each), and only there")
    chosen.add_argument("--no-select", action="store_true",
                        help="the preset's terms alone, even where they misfit the data (the "
                             "misfit lines still say where)")
    p.add_argument("--structure", metavar="MODEL",
                   help="identify the term structure of this model file instead of the "
                        "preset's (e.g. one written by identify --select), with any method, "
                        "rls included: the structure found offline, then tracked online")
    p.add_argument("--prior", metavar="MODEL",
                   help="model YAML whose theta/theta_std are the MAP prior (rls: the RLS "
                        "prior)")
    add_cutoff_option(p)
    add_columns_option(p)
    add_window_options(p)
    p.add_argument("--holdout", metavar="FRACTION|TIME",
                   help="fit on the rest and score on the last part of the log: a fraction "
                        "of the time (0.3 = the last 30 %%) or seconds (120s, or a number > 1); "
                        "prints and reports the held-out R² and RMSE of the damping force "
                        "per DOF")
    p.add_argument("--out", metavar="MODEL",
                   help="write the model YAML (a ROS 2 parameters file) here")
    p.add_argument("--report", metavar="DIR",
                   help="write an HTML report with plots (index.html + PNG) to DIR")
    p.add_argument("--truth", metavar="MODEL",
                   help="model YAML of the true coefficients (simulated data), shown in the "
                        "report")
    add_dask_options(p)
    p.add_argument("--drift-plot", metavar="PNG",
                   help="several logs: plot each coefficient's per-log estimate ± 2σ "
                        "against the log's start time to this PNG")
    p.add_argument("--keep-all", action="store_true",
                   help="several logs: pool every log, also those whose own estimate the "
                        "others do not explain within their sigma (by default such a log, "
                        "e.g. of another vehicle, is named and left out; keep them to see a "
                        "drift of the damping between the logs)")
    add_topic_options(p)
    add_preprocess_options(p)
