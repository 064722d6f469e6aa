"""dampest replay: play a rosbag2 bag (MCAP or SQLite3) with its timing (runs the replay
node here). Messages are published as recorded, byte for byte; stops at the end of the bag
(unless --loop) or on Ctrl-C. Options as ros2 bag play's where they mean the same; unlike
it, playback waits (up to 10 s) for a subscriber on every played topic, and at the end waits
up to 5 s until reliable subscribers have every message.
"""

from __future__ import annotations

import argparse
import json

from dampest_ros.cli.common import describe

EXAMPLE = ("examples:\n  dampest replay trial1 --rate 10\n"
           "  dampest replay trial1 --clock --topics imu/data dvl/twist   # /clock at 40 Hz\n"
           "  dampest replay trial1 --exclude-topics dampest/model diagnostics\n"
           "  dampest replay trial1.db3 -s sqlite3              # the storage is detected "
           "without -s\n"
           "  dampest replay trial1 --remap /imu/data:=/vehicle/imu/data "
           "--wait-for-all-acked 20000")
#: The storages replay reads (rosbags' rosbag2 reader).
STORAGES = ("mcap", "sqlite3")
#: ``--wait-for-all-acked`` 0 (wait until every message is acknowledged) as the node's
#: ``wait_for_acked``: its upper limit, seconds.
ACKED_UNLIMITED = 3600.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of dampest replay."""
    describe(p, __doc__, EXAMPLE)
    p.add_argument("bag", help="rosbag2 directory (MCAP or SQLite3) or .mcap/.db3 file")
    p.add_argument("-s", "--storage", choices=STORAGES, default=None,
                   help="storage of the bag (default: detected); the bag is checked against "
                        "it")
    p.add_argument("-r", "--rate", type=float, default=1.0,
                   help="playback speed factor (default: 1, real time)")
    p.add_argument("--topics", nargs="+", default=[], metavar="TOPIC",
                   help="play only these topics (default: all)")
    p.add_argument("--exclude-topics", nargs="+", default=[], metavar="TOPIC",
                   help="do not play these topics (default: none)")
    p.add_argument("--remap", nargs="+", default=[], metavar="FROM:=TO",
                   help="publish bag topic FROM as TO")
    p.add_argument("--start-offset", type=float, default=0.0, metavar="S",
                   help="start this many seconds into the bag")
    p.add_argument("-l", "--loop", action="store_true", help="play again and again")
    p.add_argument("--clock", nargs="?", type=float, const=40.0, default=None,
                   metavar="HZ", help="publish /clock from the bag time, HZ times per second "
                                      "(40 when given without a value)")
    p.add_argument("--reliability", choices=("bag", "reliable", "best_effort"),
                   default="bag", help="publisher reliability (default: as recorded)")
    p.add_argument("--queue-depth", type=int, default=1000,
                   help="publisher queue in messages (default: 1000)")
    p.add_argument("--wait-for-subscribers", type=int, default=1, metavar="N",
                   help="start once every played topic has N matched subscribers (default: "
                        "1; 0: play at once, what is published before a subscriber matches "
                        "reaches no one)")
    p.add_argument("--wait-for-subscribers-timeout", type=float, default=10.0, metavar="S",
                   help="wait at most S seconds for them, then warn and play (default: 10)")
    p.add_argument("--delay", type=float, default=0.0, metavar="S",
                   help="wait this long before playing (default: 0)")
    p.add_argument("--wait-for-all-acked", type=int, default=5000, metavar="MS",
                   help="at the end, wait up to MS milliseconds until reliable subscribers "
                        "have every message (default: 5000; 0: until they have, at most an "
                        "hour; -1: exit at once)")


def node_parameters(args: argparse.Namespace) -> dict[str, object]:
    """The replay node's parameters for the options."""
    params: dict[str, object] = {
        "bag": str(args.bag), "rate": float(args.rate),
        "topics": list(args.topics) or [""],
        "exclude_topics": list(args.exclude_topics) or [""], "remap": list(args.remap) or [""],
        "start_offset": float(args.start_offset), "loop": bool(args.loop),
        "clock": args.clock is not None, "reliability": args.reliability,
        "queue_depth": int(args.queue_depth),
        "wait_for_subscribers": int(args.wait_for_subscribers),
        "wait_for_subscribers_timeout": float(args.wait_for_subscribers_timeout),
        "delay": float(args.delay),
        "wait_for_acked": acked_seconds(args.wait_for_all_acked)}
    if args.clock is not None:
        params["clock_rate"] = float(args.clock)
    return params


def acked_seconds(ms: int) -> float:
    """The node's ``wait_for_acked`` (s) for ``--wait-for-all-acked MS`` (ros2 bag play's
    milliseconds: 0 waits without limit, here :data:`ACKED_UNLIMITED`; -1 does not wait).

    Raises
    ------
    ValueError
        Below -1, or beyond :data:`ACKED_UNLIMITED`.
    """
    if not -1 <= ms <= ACKED_UNLIMITED * 1000:
        raise ValueError(f"--wait-for-all-acked: {ms} ms: must be -1 (do not wait), 0 (until "
                         f"acknowledged) or up to {ACKED_UNLIMITED * 1000:.0f}")
    return 0.0 if ms < 0 else ACKED_UNLIMITED if ms == 0 else ms / 1000


def check_storage(args: argparse.Namespace) -> None:
    """With ``-s/--storage``: the bag must be of that storage.

    Raises
    ------
    ValueError
        The bag's storage is another (both named, and that -s can be dropped).
    """
    if args.storage is None:
        return
    from dampest_ros.io.bag import bag_summary

    found = bag_summary(str(args.bag)).storage
    if found != args.storage:
        raise ValueError(f"-s/--storage {args.storage}: {args.bag} is stored as {found}; give -s "
                         f"{found}, or drop -s (the storage is detected)")


def ros_arguments(args: argparse.Namespace) -> list[str]:
    """The node's --ros-args for the options."""
    out = ["--ros-args"]
    for name, value in node_parameters(args).items():
        out += ["-p", f"{name}:={json.dumps(value)}"]
    return out


def run(args: argparse.Namespace) -> int:
    """Check the options against the node's parameter specs (a bag that cannot be read, a
    rate out of range: ValueError naming the option), then play the bag."""
    from dampest_ros.ros import replay_node  # rclpy only for this command
    from dampest_ros.ros.common import check_options

    check_options(replay_node.ReplayNode.PARAMS, node_parameters(args),
                  {"bag": "BAG", "clock_rate": "--clock",
                   "wait_for_acked": "--wait-for-all-acked"})
    check_storage(args)
    replay_node.main(["dampest replay", *ros_arguments(args)])
    return 0
