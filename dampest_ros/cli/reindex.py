"""dampest reindex: rebuild metadata.yaml of an MCAP bag from its storage files.

Every chunk is checked. A storage file without a summary (the recording was killed) or with
damaged chunks is read up to its last readable record, damaged chunks skipped and counted, and
rewritten; the damaged original is kept as <file>.damaged. Every file is then read back as
identify reads it (every chunk checked, every message deserialised). A bag still being
recorded is refused. Exit status 1 when bytes or messages could not be read or a file does not
read back whole (the counts are printed), 0 when everything was.
"""

from __future__ import annotations

import argparse

from dampest_ros.cli.common import describe, table

EXAMPLE = "example:\n  dampest reindex rosbag2_2024_05_01-10_00_00"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of dampest reindex."""
    describe(p, __doc__, EXAMPLE)
    p.add_argument("bag", metavar="BAG", help="rosbag2 directory with .mcap files")


def run(args: argparse.Namespace) -> int:
    """Reindex and print what each file held and what could not be read."""
    from dampest_ros.io.reindex import reindex

    report = reindex(args.bag)
    if report.removed:
        print(f"removed partial files left by a killed recorder or reindex: "
              f"{', '.join(report.removed)}")
    rows = [(f.name, f.messages, "complete" if f.complete else
             f"recovered ({f.journal} from the journal)" if f.journal else
             "recovered" if f.messages else "unreadable", f.lost_messages, f.lost_bytes,
             f.error or "") for f in report.files]
    print(table(("file", "messages", "state", "messages lost", "bytes lost", "stopped at"),
                rows))
    print(f"wrote {report.path / 'metadata.yaml'}: {report.messages} messages; unreadable: "
          f"{report.lost_messages} messages counted by the indexes, {report.lost_bytes} bytes")
    for f in report.files:
        if f.unverified:
            print(f"{f.name} does not read back whole after reindex: {f.unverified}")
    return 1 if report.lost_bytes or report.lost_messages or not report.verified else 0
