"""dampest inspect: what a log holds and whether it can feed identification.

A bag (rosbag2 or ROS 1), or a folder of per-topic CSV files: every topic with its message
type, count, mean rate, jitter (standard deviation of the steps over their mean), gaps and
longest step, then whether the topics identification needs (IMU, DVL and thruster state or a
body wrench) are there with the right types; for a folder also each file's topic, time
column, detected time unit and the columns read. A single CSV log: its rows, time unit, rate,
jitter, gaps and the columns identification reads. Exit status 1 when something
identification needs is missing.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path
from typing import TYPE_CHECKING

from dampest_ros.cli.common import (
    BAG_HELP,
    add_topic_options,
    describe,
    table,
    tau_topic,
    topic_roles,
)

if TYPE_CHECKING:
    import numpy as np

EXAMPLE = ("examples:\n  dampest inspect bags/sample\n"
           "  dampest inspect survey.bag --imu-topic /imu/data --wrench-topic /wrench\n"
           "  dampest inspect logs/csv_export/")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of dampest inspect."""
    describe(p, __doc__, EXAMPLE, BAG_HELP)
    p.add_argument("bag", metavar="LOG", help="rosbag2 directory (MCAP or SQLite3), ROS 1 .bag "
                                              "file, folder of per-topic CSV files, or a .csv "
                                              "/ .csv.gz log")
    p.add_argument("--gap", type=float, default=0.5, metavar="S",
                   help="report gaps longer than this many seconds (default: 0.5)")
    add_topic_options(p)


def stamp_stats(t: np.ndarray, gap: float) -> tuple[float, float, int, float]:
    """Mean rate (Hz, over the steps that are not gaps), jitter (%, std/mean of those
    steps), gaps (steps over ``gap`` s) and the longest step (s) of stamps ``t`` (s)."""
    import numpy as np

    if len(t) < 2:
        return float("nan"), float("nan"), 0, 0.0
    dt = np.diff(t)
    even = dt[dt <= gap] if np.any(dt <= gap) else dt
    return (1.0 / float(even.mean()), 100.0 * float(even.std() / even.mean()),
            int(np.sum(dt > gap)), float(dt.max()))


def run(args: argparse.Namespace) -> int:
    """Print the summary; exit 1 when the log lacks what identification needs."""
    from dampest_ros.io.csv import is_csv

    if is_csv(args.bag):
        return _run_csv(args)
    return _run_log(args)


def _run_log(args: argparse.Namespace) -> int:
    from dampest_ros.io.bag import bag_summary, read_bag, role_type_errors
    from dampest_ros.io.csv_folder import is_csv_folder, load_folder, resolve_topic

    summary = bag_summary(args.bag)
    data = read_bag(args.bag)
    rows = []
    for name, topic in sorted(summary.topics.items()):
        series = data.get(name.lstrip("/"))
        stats = stamp_stats(series.stamp, args.gap) if series is not None else (
            float("nan"), float("nan"), 0, 0.0)
        rows.append((name, topic.msgtype, topic.count, *stats))
    print(f"{summary.path} ({summary.storage}): {summary.message_count} messages, "
          f"{summary.end - summary.start:.1f} s from t={summary.start:.3f}")
    print(table(("topic", "type", "messages", "rate Hz", "jitter %", f"gaps>{args.gap}s",
                 "longest s"), rows))
    topics = topic_roles(args)
    if is_csv_folder(args.bag):
        log = load_folder(args.bag)
        print(table(("file", "topic", "time column", "unit", "columns read"),
                    [(f.file, t, f.clock, f.unit, _groups(f.columns))
                     for t, f in sorted(log.files.items())]))
        for why in log.skipped:
            print(f"skipped {why}")
        topics = {role: resolve_topic(args.bag, t) for role, t in topics.items()}
    have = {n.lstrip("/") for n in summary.topics}
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


def _groups(columns: tuple[str, ...]) -> str:
    """Column names shortened to their fields: ``field.angular_velocity.x`` … →
    ``angular_velocity.xyz``, ``field.effort0`` … → ``effort0-7``."""
    from dampest_ros.io.csv_folder import normalise

    groups: dict[str, list[str]] = {}
    for c in columns:
        m = re.fullmatch(r"(.*?)(?:\.([xyzw])|(\d+))?", normalise(c))
        assert m is not None
        groups.setdefault(m.group(1), []).append(m.group(2) or m.group(3) or "")
    parts = []
    for field, tails in groups.items():
        if tails[0].isdigit():
            parts.append(f"{field}{tails[0]}-{tails[-1]}" if len(tails) > 1 else field + tails[0])
        else:
            parts.append(f"{field}.{''.join(tails)}" if tails[0] else field)
    return " ".join(parts)


def _run_csv(args: argparse.Namespace) -> int:
    """A single CSV log: rows, time unit, rate, jitter, gaps, columns read."""
    from dampest_ros.io.csv import BASE_COLUMNS, read_csv, used_column
    from dampest_ros.io.csv_table import read_head, seconds

    header, _ = read_head(Path(args.bag))
    columns = read_csv(args.bag, required=(), keep=used_column)
    missing = [c for c in BASE_COLUMNS if c not in columns]
    if "time" not in columns:
        print(f"not ready for identification: missing {missing}")
        return 1
    t, unit = seconds(columns["time"], str(args.bag), "time")
    rate, jitter, gaps, longest = stamp_stats(t, args.gap)
    print(f"{args.bag} (csv): {len(t)} rows, {t[-1] - t[0]:.1f} s, time in {unit}")
    print(table(("rate Hz", "jitter %", f"gaps>{args.gap}s", "longest s"),
                [(rate, jitter, gaps, longest)]))
    print(f"columns read: {' '.join(columns)}; not read: "
          f"{' '.join(h for h in header if h not in columns) or 'none'}")
    if missing:
        print(f"not ready for identification: missing {missing} (a column map renames "
              "other names, --columns)")
        return 1
    print("ready for identification: time, velocity and depth columns present (the "
          "acceleration and force columns are checked against the vehicle by identify)")
    return 0
