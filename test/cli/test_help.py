"""dampest --help: plain text, an example per command, a help text per option, and quick
(only the chosen command's parser is imported; no numpy or scipy for --help)."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys

import pytest

from dampest_ros.cli import common, gap_options, identify_options, simulate
from dampest_ros.cli.main import COMMANDS, build_parser, command_parser

#: Sphinx / reStructuredText markup that must not reach a terminal.
MARKUP = re.compile(r"``|:(mod|class|func|meth|attr|data|ref|doc):`")


def test_main_help_lists_every_command_with_an_example() -> None:
    text = build_parser(()).format_help()
    assert not MARKUP.search(text)
    for name, command in COMMANDS.items():
        assert re.search(rf"^\s+{name}\s+\S", text, re.M), name
        assert command.help.split()[0] in text
    assert "example:" in text and "dampest identify " in text


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_command_help_is_plain_with_an_example_and_every_option_explained(name: str) -> None:
    parser = command_parser(name)
    text = parser.format_help()
    assert not MARKUP.search(text), MARKUP.search(text)
    epilog = parser.epilog or ""
    assert re.match(r"examples?\b[^\n]*:\n", epilog), epilog
    assert f"dampest {name} " in epilog
    assert (parser.description or "").startswith(f"dampest {name}") or name == "import"
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        what = action.option_strings or [action.dest]
        assert action.help and action.help != argparse.SUPPRESS, what
        assert not MARKUP.search(action.help), what
        assert len(action.help) >= 15, what  # a sentence, not a word


def test_shared_options_have_one_help_text() -> None:
    """An option defined in several commands (--vehicle, --cutoff, --columns, the topic and
    preprocessing options) reads the same everywhere, apart from its default."""
    helps: dict[str, set[str]] = {}
    for name in ("identify", "validate", "gap"):
        for action in command_parser(name)._actions:
            for option in action.option_strings:
                text = re.sub(r"\(default: [^)]*\)|; 0: [^)]*", "", action.help or "")
                helps.setdefault(option, set()).add(text)
    for option in ("--vehicle", "--cutoff", "--columns", "--imu-topic", "--wrench-topic",
                   "--rate", "--max-gap", "--delay"):
        assert len(helps[option]) == 1, (option, helps[option])


def test_choices_of_the_parsers_are_the_cores() -> None:
    """The parsers spell out choices the core defines (importing the core would load scipy
    for --help); they must agree."""
    from dampest_ros.core.gap.search import GapOptions
    from dampest_ros.core.identification.batch import METHODS
    from dampest_ros.core.simulation.excitation import PROTOCOLS
    from dampest_ros.core.simulation.simulate import BACKENDS

    assert identify_options.METHODS == METHODS
    assert common.PROTOCOLS == PROTOCOLS
    assert simulate.BACKENDS == BACKENDS
    assert gap_options.MIN_HELDOUT == GapOptions.min_heldout


def _modules_after(argv: list[str]) -> set[str]:
    """The modules loaded by ``dampest ARGV`` in a fresh interpreter (exit status 0)."""
    code = ("import sys\nfrom dampest_ros.cli.main import main\n"
            "try:\n    main(sys.argv[1:])\nexcept SystemExit as e:\n    assert e.code == 0\n"
            "print('\\n'.join(sys.modules))")
    out = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True,
                         check=True).stdout
    return set(out.split())


@pytest.mark.parametrize("argv", [["--help"], ["identify", "--help"], ["gap", "--help"],
                                  ["export", "--help"], ["record", "--help"]])
def test_help_imports_neither_numpy_nor_scipy_nor_rclpy(argv: list[str]) -> None:
    loaded = _modules_after(argv)
    assert {"numpy", "scipy", "matplotlib", "rclpy", "mujoco"}.isdisjoint(loaded), argv
    assert "dampest_ros.core" not in loaded
