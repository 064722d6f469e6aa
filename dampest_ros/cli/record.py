"""dampest record: record topics to a rosbag2 MCAP bag (runs the recorder node here).

Options as ros2 bag record's where they mean the same. Stops on Ctrl-C or SIGTERM, which
close the bag; a bag whose recording was killed is recovered with dampest reindex. A full
disk stops the recording with the bag closed and every message received kept (exit status
1). When no message has arrived after 5 s a warning says so: start the pipeline (or the
vehicle) first, on the same ROS_DOMAIN_ID.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from dampest_ros.cli.common import describe

EXAMPLE = ("examples:\n  dampest record -o trial1                # the dampest topics, Ctrl-C "
           "to stop\n"
           "  dampest record -o trial1 --all -x '^/truth/' --max-bag-duration 600\n"
           "  dampest record -o trial1 -e '^/(imu|dvl)/' pressure   # a regex and a topic\n"
           "  dampest record -o trial1 --compression zstd\n"
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
    p.add_argument("-e", "--regex", default="", metavar="REGEX",
                   help="also record the topics this regular expression matches (anywhere "
                        "in the resolved name, e.g. '^/vehicle/'), as they appear; alone: "
                        "only those")
    p.add_argument("-s", "--storage", default="mcap", metavar="ID",
                   help="storage identifier: only mcap is written (default: mcap)")
    p.add_argument("-x", "--exclude-regex", default="", metavar="REGEX",
                   help="never record the topics this regular expression matches (anywhere "
                        "in the resolved name, e.g. '^/truth/'); with topics or --all")
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
                   help="MCAP chunk compression, which every MCAP reader undoes (as ros2 bag "
                        "record's --storage-preset-profile zstd_fast) (default: none)")
    p.add_argument("--compression-mode", choices=("none", "file", "message"), default="none",
                   help="rosbag2's own compression of whole files or single messages: not "
                        "written (it would give up the journal that keeps a killed "
                        "recording); only 'none' is accepted, use --compression")
    p.add_argument("--compression-format", choices=("zstd",), default="",
                   help="format of --compression-mode (not written: use --compression zstd)")
    p.add_argument("--namespace", default="", metavar="NS",
                   help="namespace the relative topic names are resolved in")
    p.add_argument("--node-name", default="", metavar="NAME",
                   help="name of the recorder node (default: recorder_node)")
    p.add_argument("--use-sim-time", action="store_true",
                   help="log times from /clock instead of the system clock")


def node_parameters(args: argparse.Namespace) -> dict[str, object]:
    """The recorder node's parameters for the options."""
    params: dict[str, object] = {"max_bag_size": args.max_bag_size,
                                 "max_bag_duration": float(args.max_bag_duration),
                                 "compression": args.compression,
                                 "exclude_regex": args.exclude_regex, "regex": args.regex}
    if args.output:
        params["output"] = str(args.output)
    if args.all:
        params["topics"] = ["all"]
    elif args.topics or args.regex:
        params["topics"] = list(args.topics) or [""]
    if args.chunk_size is not None:
        params["chunk_size"] = args.chunk_size
    if args.flush_period is not None:
        params["flush_period"] = float(args.flush_period)
    if args.use_sim_time:
        params["use_sim_time"] = True
    return params


def ros_arguments(args: argparse.Namespace) -> list[str]:
    """The node's --ros-args for the options (string values JSON-quoted for YAML)."""
    out = ["--ros-args"]
    for name, value in node_parameters(args).items():
        out += ["-p", f"{name}:={json.dumps(value)}"]
    if args.namespace:
        out += ["-r", f"__ns:={args.namespace}"]
    if args.node_name:
        out += ["-r", f"__node:={args.node_name}"]
    return out


def run(args: argparse.Namespace) -> int:
    """Record until interrupted."""
    if args.all and (args.topics or args.regex):
        raise ValueError("give topics (or -e/--regex) or --all, not both")
    if args.storage != "mcap":
        raise ValueError(f"-s/--storage {args.storage}: dampest record writes MCAP only (a "
                         "killed recording is recovered from the MCAP chunk journal; dampest "
                         "replay and ros2 bag play read it); drop -s, or give -s mcap")
    if args.compression_mode != "none" or args.compression_format:
        raise ValueError("--compression-mode/--compression-format: rosbag2's file and message "
                         "compression is not written (it would give up the journal that keeps "
                         "a killed recording); --compression zstd compresses the MCAP chunks, "
                         "which every MCAP reader undoes")
    if args.output and Path(args.output).exists():
        raise FileExistsError(f"{args.output} exists; dampest record never overwrites a bag")
    from dampest_ros.ros import recorder_node  # rclpy only for this command
    from dampest_ros.ros.common import check_options

    check_options(recorder_node.RecorderNode.PARAMS, node_parameters(args),
                  {"regex": "-e/--regex", "exclude_regex": "-x/--exclude-regex",
                   "topics": "TOPIC", "output": "-o/--output"})
    recorder_node.main(["dampest record", *ros_arguments(args)])
    return 0
