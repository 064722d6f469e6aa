"""The README's shell commands run as written on a fresh clone (the pip-only path).

Every ``dampest`` command of the README's ``sh`` blocks must parse, and read only files that
are in the repository or that a command before it writes (no placeholders). The set-up
block's sample-bag commands run here; all practical ones (not those that run until stopped,
or the ROS 2 nodes of a full install) run in order in a slow test, and the record/replay
block, whose commands run until stopped, in another.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from dampest_ros.cli.main import COMMANDS, build_parser
from dampest_ros.io.bag import bag_summary

REPO = Path(__file__).resolve().parents[2]
#: First words of commands of a colcon workspace or a full ROS 2 install, not of the
#: pip-only path (the colcon build itself is tested in test/test_package.py).
WORKSPACE = ("ros2", "colcon", "rosdep", "source", ".", "mkdir", "git", "cd")
#: Commands that run until they are stopped (record, replay) or for minutes (live, demo):
#: parsed and checked, not run.
LONG = {"record", "replay", "live", "demo"}
#: What a command reads and what it writes, by option name.
READS = ("input", "bag", "model", "file", "prior", "truth", "columns")
WRITES = ("out", "output", "csv", "report")


def sh_blocks() -> list[list[list[str]]]:
    """The README's ``sh`` blocks in order, each as its commands' argv lists (continuation
    lines joined, comments dropped, ``a && b`` split; a command run in the background keeps
    its trailing ``&``)."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    blocks: list[list[list[str]]] = []
    for block in re.findall(r"^```sh\n(.*?)^```", text, re.S | re.M):
        commands: list[list[str]] = []
        for line in block.replace("\\\n", " ").splitlines():
            words = shlex.split(line, comments=True)
            while words:
                cut = words.index("&&") if "&&" in words else len(words)
                commands.append(words[:cut])
                words = words[cut + 1:]
        blocks.append(commands)
    return blocks


def readme_commands() -> list[list[str]]:
    """The commands of the README's ``sh`` blocks in order, as argv lists without a trailing
    ``&``."""
    return [c[:-1] if c[-1] == "&" else c for block in sh_blocks() for c in block]


def pip_commands() -> list[list[str]]:
    """The README's commands of the pip-only path: dampest and make."""
    return [c for c in readme_commands() if c[0] in ("dampest", "make")]


def _paths(args: object, names: tuple[str, ...]) -> list[Path]:
    """The paths given to the named options (a list option gives each of its values)."""
    out = []
    for name in names:
        value = getattr(args, name, None)
        for v in value if isinstance(value, list) else [value]:
            if v not in (None, ""):
                out.append(Path(str(v)))
    return out


def _made_by(path: Path, made: list[Path]) -> bool:
    return any(path == m or m in path.parents for m in made)


def test_readme_has_the_pip_path_and_no_placeholders() -> None:
    commands = pip_commands()
    assert ["make"] in commands
    assert any(c[:2] == ["dampest", "gap"] for c in commands)
    parser = build_parser()
    made: list[Path] = []
    makefile = (REPO / "Makefile").read_text()
    for argv in commands:
        if argv[0] == "make":
            for target in argv[1:]:
                assert re.search(rf"^{target}:", makefile, re.M), argv
            continue
        if "--help" in argv:
            assert argv[1] == "--help" or argv[1] in COMMANDS, argv
            continue
        try:
            args = parser.parse_args(argv[1:])
        except SystemExit:
            pytest.fail(f"README command does not parse: {shlex.join(argv)}")
        for path in _paths(args, READS):
            assert (REPO / path).exists() or _made_by(path, made), \
                f"{shlex.join(argv)} reads {path}, which neither the repository nor an " \
                "earlier README command provides"
        vehicle = getattr(args, "vehicle", None)
        if vehicle:
            assert (REPO / vehicle).is_file() or \
                (REPO / "config" / "vehicles" / f"{vehicle}.yaml").is_file(), argv
        made += _paths(args, WRITES)


def _sandbox(tmp_path: Path) -> Path:
    """A fresh clone's top folder as the commands see it: config/ and a copy of bags/."""
    (tmp_path / "config").symlink_to(REPO / "config")
    shutil.copytree(REPO / "bags", tmp_path / "bags")
    return tmp_path


def _command(argv: list[str]) -> list[str]:
    """``argv`` of a README ``dampest`` command as this interpreter's dampest."""
    exe = Path(sys.executable).parent / "dampest"
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "dampest_ros.cli.main"]
    return [*cmd, *argv[1:]]


#: The environment the README's commands run in (the ROS ones on the test's own domain).
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg", "ROS_DOMAIN_ID": "87",
       "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}


def _run(children: Any, argv: list[str], cwd: Path) -> str:
    """Run a README command to its end (exit status 0) as one of ``children``; its stderr."""
    proc = children.run(_command(argv), cwd=cwd, env=ENV, capture_output=True, text=True,
                        timeout=900)
    assert proc.returncode == 0, f"{shlex.join(argv)}:\n{proc.stdout[-2000:]}" \
                                 f"\n{proc.stderr[-2000:]}"
    return proc.stderr


def test_the_sample_bag_commands_of_the_set_up_run(tmp_path: Path, children: Any) -> None:
    cwd = _sandbox(tmp_path)
    sample = [c for c in pip_commands() if (c[0] == "dampest" and "bags/sample" in c)
              or c[:3] == ["dampest", "export", "model.yaml"]][:3]
    assert [c[1] for c in sample] == ["inspect", "identify", "export"]
    for argv in sample:
        _run(children, argv, cwd)
    assert (cwd / "model.yaml").is_file() and (cwd / "hydrodynamics.sdf").is_file()


@pytest.mark.slow
def test_every_practical_readme_command_runs_in_order(tmp_path: Path, children: Any) -> None:
    """All of them, minutes: the simulations, identify with its report, validate, export and
    import, gap on a hidden current and buoyancy offset."""
    cwd = _sandbox(tmp_path)
    skipped: list[Path] = []
    ran = 0
    parser = build_parser()
    for argv in pip_commands():
        if argv[0] != "dampest" or "--help" in argv:
            continue
        args = parser.parse_args(argv[1:])
        if argv[1] in LONG or any(_made_by(p, skipped) for p in _paths(args, READS)):
            skipped += _paths(args, WRITES)
            continue
        if (cwd / str(getattr(args, "out", "") or "-")).exists() and argv[1] == "simulate":
            continue  # the same bag twice in the README (set-up and section)
        _run(children, argv, cwd)
        ran += 1
    assert ran >= 10
    assert (cwd / "gap_report" / "index.html").is_file()


@pytest.mark.slow
def test_the_record_replay_block_runs_in_order(tmp_path: Path, children: Any) -> None:
    """The record/replay block as a user runs it (about a minute): the commands with ``&``
    in the background, ``record`` until they have ended (then Ctrl-C), the others in
    order; the bag holds the pipeline's messages, without the no-message warning, and the
    offline RLS on it writes a model."""
    block = next(b for b in sh_blocks() if any(c[:2] == ["dampest", "record"] for c in b))
    cwd = _sandbox(tmp_path)
    background: list[subprocess.Popen[str]] = []
    for argv in block:
        if argv[-1] == "&":
            background.append(children.start(_command(argv[:-1]), cwd=cwd, env=ENV,
                                             stdout=subprocess.DEVNULL, text=True))
        elif argv[1] == "record":
            log = tmp_path / "record.log"
            recorder = children.start(_command(argv), log=log, cwd=cwd, env=ENV)
            assert all(p.wait(timeout=300) == 0 for p in background)
            assert children.stop(recorder, signal.SIGINT, 60) == 0, log.read_text()
            assert "no message" not in log.read_text(), log.read_text()
        else:
            _run(children, argv, cwd)
    counts = bag_summary(cwd / "bags" / "trial1").topics
    assert all(counts[t].count > 100 for t in ("/imu/data", "/dvl/twist", "/thrusters/state"))
    assert (cwd / "rls_model.yaml").is_file()
