"""dampest inspect: what a bag (rosbag2 or ROS 1) holds and whether it can feed identification.

Prints every topic with its message type, count, rate, gaps and longest gap, then whether
the topics identification needs (IMU, DVL and thruster state or a body wrench) are there
with the right types; exit status 1 when they are not.
"""

from __future__ import annotations

import argparse

from dampest_ros.cli.common import (
    BAG_HELP,
    add_topic_options,
    describe,
    table,
    tau_topic,
    topic_roles,
)

EXAMPLE = ("examples:\n  dampest inspect bags/sample\n"
           "  dampest inspect survey.bag --imu-topic /imu/data --wrench-topic /wrench")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of dampest inspect."""
    describe(p, __doc__, EXAMPLE, BAG_HELP)
    p.add_argument("bag", metavar="BAG",
                   help="rosbag2 directory (MCAP or SQLite3) or ROS 1 .bag file")
    p.add_argument("--gap", type=float, default=0.5, metavar="S",
                   help="report gaps longer than this many seconds (default: 0.5)")
    add_topic_options(p)


def run(args: argparse.Namespace) -> int:
    """Print the summary; exit 1 when the bag lacks a topic identification needs or one of
    them carries another message type."""
    import numpy as np

    from dampest_ros.io.bag import bag_summary, read_bag, role_type_errors

    summary = bag_summary(args.bag)
    data = read_bag(args.bag)
    rows = []
    for name, topic in sorted(summary.topics.items()):
        series = data.get(name.lstrip("/"))
        rate, gaps, longest = float("nan"), 0, 0.0
        if series is not None and len(series) > 1:
            dt = np.diff(series.stamp)
            rate = 1.0 / float(np.median(dt))
            gaps = int(np.sum(dt > args.gap))
            longest = float(dt.max())
        rows.append((name, topic.msgtype, topic.count, rate, gaps, longest))
    print(f"{summary.path} ({summary.storage}): {summary.message_count} messages, "
          f"{summary.end - summary.start:.1f} s from t={summary.start:.3f}")
    print(table(("topic", "type", "messages", "rate Hz", f"gaps>{args.gap}s", "longest s"),
                rows))
    have = {n.lstrip("/") for n in summary.topics}
    topics = topic_roles(args)
    tau = "body wrench" if "wrench" in topics else "thruster"
    needed = [topics["imu"], topics["dvl"], tau_topic(topics)]
    missing = [t for t in needed if t not in have]
    problems = role_type_errors(summary, topics)
    if missing:
        problems.insert(0, f"missing {missing} (use --imu-topic etc. with dampest identify "
                           "if they have other names, --wrench-topic if τ is logged as a "
                           "body wrench)")
    if problems:
        print(f"not ready for identification: {'; '.join(problems)}")
        return 1
    print(f"ready for identification: IMU, DVL and {tau} topics present")
    return 0
