"""dampest record: record topics to a rosbag2 MCAP bag (runs the recorder node here).

Stops on Ctrl-C or SIGTERM, which close the bag; a bag whose recording was killed is
recovered with dampest reindex. A full disk stops the recording with the bag closed and
every message received kept (exit status 1).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from dampest_ros.cli.common import describe

EXAMPLE = ("examples:\n  dampest record -o trial1\n"
           "  dampest record -o trial1 --all --max-bag-duration 600\n"
           "  dampest record -o t imu/data dvl/twist --namespace /vehicle")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of dampest record."""
    describe(p, __doc__, EXAMPLE)
    p.add_argument("topics", nargs="*", metavar="TOPIC",
                   help="topics to record (default: every topic of the dampest contract: "
                        "imu/data, dvl/twist, pressure, thrusters/state, truth/odom, "
                        "dampest/*, diagnostics)")
    p.add_argument("-o", "--output", default="",
                   help="bag directory to create; it must not exist "
                        "(default: rosbag2_YYYY_MM_DD-HH_MM_SS)")
    p.add_argument("-a", "--all", action="store_true",
                   help="record every topic found in the graph (not /rosout, "
                        "/parameter_events)")
    p.add_argument("--max-bag-size", type=int, default=0, metavar="BYTES",
                   help="split into a new file after this many bytes (default: 0, never)")
    p.add_argument("--max-bag-duration", type=float, default=0.0, metavar="S",
                   help="split into a new file after this many seconds (default: 0, never)")
    p.add_argument("--chunk-size", type=int, default=None, metavar="BYTES",
                   help="MCAP chunk size; each chunk is flushed to disk (default: 262144)")
    p.add_argument("--flush-period", type=float, default=None, metavar="S",
                   help="flush a chunk at least this often (until then its messages are in "
                        "the file's journal: a killed recording loses none) (default: 0.2)")
    p.add_argument("--compression", choices=("none", "zstd", "lz4"), default="none",
                   help="chunk compression (default: none)")
    p.add_argument("--namespace", default="", metavar="NS",
                   help="namespace the relative topic names are resolved in")
    p.add_argument("--node-name", default="", metavar="NAME",
                   help="name of the recorder node (default: recorder_node)")
    p.add_argument("--use-sim-time", action="store_true",
                   help="log times from /clock instead of the system clock")


def ros_arguments(args: argparse.Namespace) -> list[str]:
    """The node's --ros-args for the options (string values JSON-quoted for YAML)."""
    params: dict[str, object] = {"max_bag_size": args.max_bag_size,
                                 "max_bag_duration": float(args.max_bag_duration),
                                 "compression": args.compression}
    if args.output:
        params["output"] = str(args.output)
    if args.all:
        params["topics"] = ["all"]
    elif args.topics:
        params["topics"] = list(args.topics)
    if args.chunk_size is not None:
        params["chunk_size"] = args.chunk_size
    if args.flush_period is not None:
        params["flush_period"] = float(args.flush_period)
    if args.use_sim_time:
        params["use_sim_time"] = True
    out = ["--ros-args"]
    for name, value in params.items():
        out += ["-p", f"{name}:={json.dumps(value)}"]
    if args.namespace:
        out += ["-r", f"__ns:={args.namespace}"]
    if args.node_name:
        out += ["-r", f"__node:={args.node_name}"]
    return out


def run(args: argparse.Namespace) -> int:
    """Record until interrupted."""
    if args.all and args.topics:
        raise ValueError("give topics or --all, not both")
    if args.output and Path(args.output).exists():
        raise FileExistsError(f"{args.output} exists; dampest record never overwrites a bag")
    from dampest_ros.ros import recorder_node  # rclpy only for this command

    recorder_node.main(["dampest record", *ros_arguments(args)])
    return 0
