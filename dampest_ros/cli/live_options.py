"""dampest live: the online pipeline in one process, faster than real time.

sim_node → preprocess_node → estimator_node → controller_node on one rclpy executor: the
BlueROV2 Heavy flies protocol B (300 s of simulation time by default) while the estimator
identifies its damping with recursive least squares. The estimator starts from a wrong
prior, as it would on a real vehicle: --prior-factor times the preset's nominal coefficients
(default 0.5: every coefficient at half the value the simulator flies as the truth; written
to OUT/prior.yaml and given to estimator_node as its prior parameter) with a standard
deviation ten times that, so that the data decide; or --prior FILE, a model YAML. A table
shows the estimate against the simulator's truth at t = 0 and every few simulated seconds as
it converges; at the end the model is saved (an atomic write, as the estimator's ~/save does)
to OUT/model.yaml, and the final table gives the coverage of the ±2σ band: the share of the
recorded instants of the second half of the run at which the truth lay within ±2σ of the
estimate (about 95 % when σ is right).

Then, unless switched off: the batch least-squares estimate on the very samples the RLS used
(--batch, an extra column of the final table), and a convergence report in OUT/report/
(--report): each coefficient's estimate over time with its ±2σ band and the truth, and the
velocity PI flying sine references on the simulator without and with the identified model's
feed-forward D(ν)ν + C(ν)ν, with the RMS tracking errors.

The controller runs in shadow mode by default: it reads the model through
dampest_ros.client and computes its commands (controller/cmd_wrench) while the protocol flies
the vehicle; with --controller fly it flies the vehicle itself (cmd_wrench) at the reference
--reference, using the model identified so far as feed-forward.

Executors: rclpy's SingleThreadedExecutor by default. With the GIL the MultiThreadedExecutor
runs the same callbacks with no parallelism and about twice the dispatch cost
(--executor multi to compare).
"""

from __future__ import annotations

import argparse

from dampest_ros.cli.common import add_protocol_option, add_vehicle_option, describe

EXAMPLE = "example:\n  dampest live --duration 300 --rate-factor 5"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of dampest live (its work: dampest_ros.cli.live.run)."""
    describe(p, __doc__, EXAMPLE)
    add_options(p, "runs/live")


def add_options(p: argparse.ArgumentParser, out: str) -> None:
    """The options of the online run (dampest live and dampest demo); ``out``: the default
    of --out."""
    p.add_argument("--out", default=out, help=f"output folder (default: {out})")
    p.add_argument("--duration", type=float, default=300.0,
                   help="simulated seconds (default: 300)")
    p.add_argument("--rate-factor", type=float, default=5.0,
                   help="simulated seconds per wall-clock second (default: 5; flat out the "
                        "pipeline reaches about 13 on an idle 2-core machine, make bench)")
    add_vehicle_option(p, "bluerov2_heavy")
    add_protocol_option(p)
    p.add_argument("--seed", type=int, default=1,
                   help="seed of the excitation and the sensor noise (default: 1)")
    p.add_argument("--prior", default="", metavar="FILE",
                   help="model YAML whose theta/theta_std are the estimator's prior (default: "
                        "OUT/prior.yaml written from --prior-factor)")
    p.add_argument("--prior-factor", type=float, default=0.5,
                   help="without --prior: prior mean = this × the preset's nominal "
                        "coefficients, standard deviation 10 × that (default: 0.5)")
    p.add_argument("--forgetting-factor", type=float, default=0.999,
                   help="RLS forgetting factor λ (default: 0.999; at λ = 1 the RLS σ shrinks "
                        "towards the estimate's systematic error and the ±2σ band covers the "
                        "truth ~80 %% of the time instead of ~97 %%)")
    p.add_argument("--effects", default="", metavar="YAML",
                   help="hidden effects to switch on, a YAML mapping (file or inline), e.g. "
                   "'{damping_change_time: 200, damping_change_factor: 1.3}'")
    p.add_argument("--every", type=float, default=20.0,
                   help="print the table every this many simulated seconds (default: 20)")
    p.add_argument("--record-every", type=float, default=0.5,
                   help="record the estimate and its σ for the report every this many "
                        "simulated seconds (default: 0.5)")
    p.add_argument("--executor", choices=("single", "multi"), default="single",
                   help="rclpy executor (default: single; see above)")
    p.add_argument("--controller", choices=("shadow", "fly", "off"), default="shadow",
                   help="controller mode (default: shadow)")
    p.add_argument("--reference", type=float, nargs=6, default=[0.3, 0.0, 0.0, 0.0, 0.0, 0.2],
                   metavar="V", help="velocity reference of the controller, FLU "
                   "(default: 0.3 0 0 0 0 0.2)")
    p.add_argument("--batch", action=argparse.BooleanOptionalAction, default=True,
                   help="also fit the batch least squares on the samples the RLS used (kept "
                        "in memory, ~1 kB per sample) (default: on)")
    p.add_argument("--report", action=argparse.BooleanOptionalAction, default=True,
                   help="write OUT/report/ (convergence and tracking plots) (default: on)")
    p.add_argument("--tracking-seconds", type=float, default=60.0,
                   help="length of each tracking run of the report (default: 60)")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS_DOMAIN_ID (default: the environment's, else 77)")
