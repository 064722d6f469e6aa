"""The ``dampest`` command: simulate, identify, validate, inspect, export/import, record,
replay, reindex, demo, live, gap.

Each sub-command lives in its own module with ``add_parser(subparsers)`` and ``run(args)``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from dampest_ros.cli import (
    demo,
    export,
    gap,
    identify,
    inspect,
    live,
    record,
    reindex,
    replay,
    simulate,
    validate,
)
from dampest_ros.core.preprocess import DataError
from dampest_ros.core.rigid_body import ConfigError
from dampest_ros.io.bag import BagError, MissingTopicError

COMMANDS = (simulate, identify, validate, gap, inspect, export, record, replay, reindex, demo,
            live)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command."""
    parser = argparse.ArgumentParser(
        prog="dampest",
        description="Identify the hydrodynamic damping D(ν) of underwater vehicles from "
                    "recorded ROS 2 bags, CSV or live topics, find where a simulator and "
                    "measurements disagree, record and replay logs, and simulate vehicles "
                    "to test it all.",
        epilog="Run 'dampest COMMAND --help' for the options of a command.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module in COMMANDS:
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``dampest`` console script; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.run(args))
    except (ConfigError, DataError, BagError, MissingTopicError, FileNotFoundError,
            FileExistsError, ValueError) as exc:
        print(f"dampest {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"dampest {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
