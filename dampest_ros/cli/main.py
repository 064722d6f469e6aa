"""The dampest command: one table of sub-commands, each imported only when it is chosen.

A sub-command is a row of :data:`COMMANDS`: its line in ``dampest --help``, the function that
adds its options to its parser (a light module: no numpy, core or ROS at import time, so that
``dampest CMD --help`` is quick) and the function that does the work (imported only when the
command runs). A failure ends in one line on stderr and exit status 2; ``--debug`` (or
``DAMPEST_DEBUG=1``) lets the exception through with its traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Command:
    """One sub-command."""

    help: str  #: its line in ``dampest --help``
    parser: str  #: ``module:function`` adding its options to an ArgumentParser
    run: str  #: ``module:function`` taking the parsed arguments, returning the exit status


COMMANDS: dict[str, Command] = {
    "simulate": Command("simulate a vehicle and write a rosbag2 bag",
                        "dampest_ros.cli.simulate:add_arguments", "dampest_ros.cli.simulate:run"),
    "identify": Command("identify damping from a bag or CSV",
                        "dampest_ros.cli.identify_options:add_arguments",
                        "dampest_ros.cli.identify:run"),
    "validate": Command("score a model YAML on another log (bag or CSV)",
                        "dampest_ros.cli.validate:add_arguments", "dampest_ros.cli.validate:run"),
    "gap": Command("find where a model and measured data disagree and name the missing effect",
                   "dampest_ros.cli.gap_options:add_arguments", "dampest_ros.cli.gap:run"),
    "inspect": Command("topics, rates, gaps and readiness of a bag, CSV folder or CSV",
                       "dampest_ros.cli.inspect:add_arguments", "dampest_ros.cli.inspect:run"),
    "export": Command("write a model as gz-sim, URDF or UUV Simulator hydrodynamics",
                      "dampest_ros.cli.export:add_arguments", "dampest_ros.cli.export:run"),
    "import": Command("read gz-sim, URDF or UUV Simulator hydrodynamics into a model file",
                      "dampest_ros.cli.export:add_import_arguments",
                      "dampest_ros.cli.export:run_import"),
    "record": Command("record topics to an MCAP bag (recorder_node)",
                      "dampest_ros.cli.record:add_arguments", "dampest_ros.cli.record:run"),
    "replay": Command("play a bag with its timing (replay_node)",
                      "dampest_ros.cli.replay:add_arguments", "dampest_ros.cli.replay:run"),
    "reindex": Command("rebuild metadata.yaml, recover a killed recording",
                       "dampest_ros.cli.reindex:add_arguments", "dampest_ros.cli.reindex:run"),
    "demo": Command("online identification of a simulated BlueROV2 Heavy against the truth, "
                    "with a report", "dampest_ros.cli.demo:add_arguments",
                    "dampest_ros.cli.live:run"),
    "live": Command("online pipeline (sim, preprocess, RLS, controller) in one process",
                    "dampest_ros.cli.live_options:add_arguments", "dampest_ros.cli.live:run"),
    "arm": Command("an arm: design excitation, simulate in MuJoCo, identify dynamic "
                   "parameters and joint friction", "dampest_ros.cli.arm:add_arguments",
                   "dampest_ros.cli.arm:run"),
}

#: Failures whose message says what is wrong and how to fix it (besides OSError and
#: ValueError, which the dampest errors of the core derive from): ``module: class`` names,
#: checked only when their module is loaded, so that nothing is imported to report an error.
EXPECTED = {"dampest_ros.io.bag": ("BagError", "MissingTopicError"),
            "dampest_ros.io.recorder": ("RecorderError",)}


def resolve(target: str) -> Callable[..., Any]:
    """The function of a ``module:function`` target (the module imported now)."""
    module, _, name = target.partition(":")
    function: Callable[..., Any] = getattr(importlib.import_module(module), name)
    return function


def build_parser(configure: Collection[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser of ``dampest``.

    Parameters
    ----------
    configure : collection of str, optional
        Sub-commands whose options are added (their parser modules imported); the others
        are listed by name and help line only. Default: all.
    """
    parser = argparse.ArgumentParser(
        prog="dampest",
        description="Identify the hydrodynamic damping D(ν) of underwater vehicles from\n"
                    "recorded ROS 2 bags, CSV or live topics, find where a simulator and\n"
                    "measurements disagree, record and replay logs, and simulate vehicles\n"
                    "to test it all.",
        epilog="Run 'dampest COMMAND --help' for the options and an example of a command.\n"
               "example:\n  dampest simulate --protocol B --duration 120 --out bags/b120\n"
               "  dampest identify bags/b120 --vehicle bluerov2_heavy --out model.yaml",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of a failure (also DAMPEST_DEBUG=1)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, command in COMMANDS.items():
        p = sub.add_parser(name, help=command.help, description=command.help,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        if configure is None or name in configure:
            resolve(command.parser)(p)
    return parser


def command_parser(name: str) -> argparse.ArgumentParser:
    """The parser of one sub-command, configured (for tests and documentation)."""
    parser = build_parser((name,))
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            sub: argparse.ArgumentParser = action.choices[name]
            return sub
    raise KeyError(name)


def expected(exc: BaseException) -> bool:
    """Whether ``exc`` is a failure whose message explains itself (:data:`EXPECTED`)."""
    if isinstance(exc, OSError | ValueError):
        return True
    for module, names in EXPECTED.items():
        loaded = sys.modules.get(module)
        if loaded is not None and isinstance(exc, tuple(getattr(loaded, n) for n in names)):
            return True
    return False


def _interrupt(signum: int, frame: object) -> None:
    """A signal handler that raises KeyboardInterrupt, as SIGINT's default one does."""
    raise KeyboardInterrupt


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``dampest`` console script; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    # the first word that is not an option is the command (dampest's own options take no
    # value); only its parser is built
    chosen = next((a for a in argv if not a.startswith("-")), "")
    args = build_parser((chosen,)).parse_args(argv)
    # SIGTERM (systemd, docker, launch) ends a command as Ctrl-C does: what a command keeps on
    # an interrupt (live and demo save the run so far) it keeps on SIGTERM too
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        return int(resolve(COMMANDS[args.command].run)(args))
    except KeyboardInterrupt:
        print(f"dampest {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (dampest … | head): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except Exception as exc:
        if args.debug or os.environ.get("DAMPEST_DEBUG", "0") not in ("", "0"):
            raise
        what = (str(exc) if expected(exc) and str(exc) else
                f"unexpected {type(exc).__name__}: {exc} (dampest --debug "
                f"{args.command} ... shows where)")
        print(f"dampest {args.command}: error: {what}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
