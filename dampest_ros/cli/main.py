"""The ``dampest`` command: simulate, identify, validate, inspect, export/import, record,
replay, reindex, demo, live, gap.

Each sub-command lives in its own module with ``add_parser(subparsers)`` and ``run(args)``.
A failure ends in one line on stderr and exit status 2; ``--debug`` (or ``DAMPEST_DEBUG=1``)
lets the exception through with its traceback.
"""

from __future__ import annotations

import argparse
import os
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
from dampest_ros.io.recorder import RecorderError

#: Failures whose message says what is wrong and how to fix it; any other exception is
#: reported with its type as an unexpected failure.
EXPECTED = (ConfigError, DataError, BagError, MissingTopicError, RecorderError, OSError,
            ValueError)

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
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of a failure (also DAMPEST_DEBUG=1)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module in COMMANDS:
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``dampest`` console script; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.run(args))
    except KeyboardInterrupt:
        print(f"dampest {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:
        if args.debug or os.environ.get("DAMPEST_DEBUG", "0") not in ("", "0"):
            raise
        what = (str(exc) if isinstance(exc, EXPECTED) else
                f"unexpected {type(exc).__name__}: {exc} (dampest --debug "
                f"{args.command} ... shows where)")
        print(f"dampest {args.command}: error: {what}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
