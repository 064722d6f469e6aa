"""dampest demo: the online pipeline on a simulated BlueROV2 Heavy, with its report.

sim → preprocess → RLS estimator → controller in one process (dampest live with its
defaults: protocol B for 300 s of simulation time, faster than real time, λ = 0.999). The
estimator starts from a wrong prior, every coefficient at half its true value
(--prior-factor, or --prior FILE). A table of the estimate against the simulator's truth
(coefficient, estimate, std, truth, error) is printed at t = 0 and as it converges; the final
one adds the batch estimate on the same samples and how often the ±2σ band held the truth
over the second half of the run. OUT (default runs/demo) then holds the prior (prior.yaml),
the model (model.yaml) and report/index.html with the convergence of every coefficient from
the prior (±2σ band, truth) and the controller's tracking without and with the model's
feed-forward. Every option of dampest live applies (see dampest live --help).
"""

from __future__ import annotations

import argparse

from dampest_ros.cli.common import describe
from dampest_ros.cli.live_options import add_options

EXAMPLE = "example:\n  dampest demo --duration 120 --out runs/short"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of dampest demo: those of dampest live, results in runs/demo."""
    describe(p, __doc__, EXAMPLE)
    add_options(p, "runs/demo")
