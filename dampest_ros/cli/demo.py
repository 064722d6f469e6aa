"""``dampest demo``: the online pipeline on a simulated BlueROV2 Heavy, with its report.

sim → preprocess → RLS estimator → controller in one process (``dampest live`` with its
defaults: protocol B for 300 s of simulation time, faster than real time). A table of the
estimate against the simulator's truth (coefficient, estimate, std, truth, error) is printed
as it converges; at the end OUT (default runs/demo) holds the model (model.yaml) and
report/index.html with the convergence of every coefficient (±2σ band, truth) and the
controller's tracking without and with the model's feed-forward. Every option of
``dampest live`` applies (see ``dampest live --help``).
"""

from __future__ import annotations

import argparse

from dampest_ros.cli import live


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the sub-command."""
    p = sub.add_parser("demo", help="online identification of a simulated BlueROV2 Heavy "
                                    "against the truth, with a report", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog="example: dampest demo --duration 120 --out runs/short")
    live.add_options(p, "runs/demo")
    p.set_defaults(run=live.run)
