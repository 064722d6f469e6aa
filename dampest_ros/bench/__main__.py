"""``python -m dampest_ros.bench`` (``make bench``): run the benchmark groups, print the table."""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from collections.abc import Callable

import dampest_ros.bench
from dampest_ros.bench import arm, offline, online, pool, recorder, startup
from dampest_ros.cli.common import table

Rows = Callable[[argparse.Namespace, str], list[tuple[str, ...]]]

#: The groups of rows, in the order they run (``--only`` picks some).
GROUPS: dict[str, Rows] = {
    "startup": startup.startup_rows, "limits": offline.limits_rows,
    "simulate": offline.simulate_rows,
    "identify": offline.identify_rows, "select": offline.select_rows, "pool": pool.pool_rows,
    "arm": arm.arm_rows, "live": online.live_rows, "estimator": online.estimator_rows,
    "recorder": recorder.recorder_rows, "arm_peers": arm.arm_peers_rows}
#: Groups that run only when named with ``--only`` (make bench-peers): they need the peers of
#: requirements/peers.txt and take minutes.
ON_REQUEST = ("arm_peers",)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmarks and print the table."""
    ap = argparse.ArgumentParser(prog="python -m dampest_ros.bench",
                                 description=dampest_ros.bench.__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, nargs="*", default=[1.0],
                    help="lengths of the identification bags in hours (default: 1)")
    ap.add_argument("--sim-seconds", type=float, default=600.0,
                    help="simulated seconds for the simulator benchmark (default: 600)")
    ap.add_argument("--live-seconds", type=float, default=120.0,
                    help="simulated seconds of the live pipeline (default: 120)")
    ap.add_argument("--estimator-seconds", type=float, default=60.0,
                    help="seconds of samples for the estimator CPU rows (default: 60)")
    ap.add_argument("--recorder-seconds", type=float, default=120.0,
                    help="simulated seconds recorded by the recorder rows (default: 120)")
    ap.add_argument("--kills", type=int, default=10,
                    help="recordings killed with SIGKILL in the recorder rows (default: 10)")
    ap.add_argument("--pool-seconds", type=float, default=600.0,
                    help="length of each of the 8 bags of the pooled rows (default: 600)")
    ap.add_argument("--only", nargs="+", choices=list(GROUPS),
                    default=[g for g in GROUPS if g not in ON_REQUEST],
                    help="groups of rows to run (default: all but "
                         f"{', '.join(ON_REQUEST)})")
    args = ap.parse_args(argv)
    rows: list[tuple[str, ...]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, group in GROUPS.items():
            if name in args.only:
                rows += group(args, tmp)
    print(table(("benchmark", "time", "figure", "goal", "peak MB"), rows))
    load = os.getloadavg()
    print(f"\nmachine: {os.cpu_count()} cores, load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} "
          f"(1, 5, 15 min), Python {sys.version.split()[0]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
