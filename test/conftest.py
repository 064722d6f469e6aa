"""Fixtures shared by the tests: the figures a report saves, and the check that every axis
of them carries a unit."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from matplotlib.figure import Figure

REPO = Path(__file__).resolve().parents[1]
PACKAGE = "dampest_ros"
# What a user's workspace holds after cloning (pyproject.toml included: colcon must ignore it).
PACKAGE_FILES = ["package.xml", "setup.py", "setup.cfg", "pyproject.toml", "resource", PACKAGE,
                 "config", "launch"]

#: A unit in brackets or parentheses, e.g. (N), (N·s/m), [m/s], (N²/Hz), (unitless).
UNIT = re.compile(r"[(\[][^()\[\]]*[A-Za-z²][^()\[\]]*[)\]]")


@pytest.fixture
def saved_figures(monkeypatch: pytest.MonkeyPatch) -> list[Figure]:
    """Every Figure saved from now on (Figure.savefig wrapped)."""
    saved: list[Figure] = []
    original = Figure.savefig

    def savefig(self: Figure, *args: Any, **kwargs: Any) -> None:
        saved.append(self)
        original(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", savefig)
    return saved


def label_problems(figures: list[Figure]) -> list[str]:
    """Axes whose x or y axis lacks a label with a unit. An x axis shared with a labelled
    one (the bottom row of a column) counts as labelled; categorical x ticks (words, no
    scale) need no unit."""
    problems = []
    for fig in figures:
        for ax in fig.axes:
            if not ax.get_visible():
                continue
            where = f"{fig.texts[0].get_text() if fig.texts else ''}/{ax.get_title()}"
            if not UNIT.search(ax.get_ylabel()):
                problems.append(f"{where}: y label {ax.get_ylabel()!r}")
            siblings = ax.get_shared_x_axes().get_siblings(ax)
            ticks = [t.get_text() for t in ax.get_xticklabels()]
            categorical = bool(ticks) and all(re.fullmatch(r"[a-z .]+", t) for t in ticks)
            if not categorical and not any(UNIT.search(s.get_xlabel()) for s in siblings):
                problems.append(f"{where}: x label {ax.get_xlabel()!r}")
    return problems



@pytest.fixture
def axis_unit_problems() -> Callable[[list[Figure]], list[str]]:
    """:func:`label_problems`, for tests that check figures."""
    return label_problems


def find_colcon() -> Path:
    """The venv's colcon, else the one on PATH; the test is skipped without one."""
    colcon = Path(sys.executable).parent / "colcon"
    if colcon.exists():
        return colcon
    found = shutil.which("colcon")
    if found is None:
        pytest.skip("colcon not installed")
    return Path(found)


@pytest.fixture(scope="session")
def colcon_install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``colcon build`` of the package files of a clone in a temporary workspace, once per
    session (the packaging test and the multiprocess nodes only read it); returns
    install/dampest_ros."""
    ws = tmp_path_factory.mktemp("ws")
    src = ws / "src" / PACKAGE
    src.mkdir(parents=True)
    for name in PACKAGE_FILES:
        path = REPO / name
        if path.is_dir():
            shutil.copytree(path, src / name,
                            ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        else:
            shutil.copy2(path, src / name)
    env = dict(os.environ, COLCON_HOME=str(ws / "colcon_home"), COLCON_LOG_PATH=str(ws / "log"))
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    proc = subprocess.run([str(find_colcon()), "build", "--base-paths", "src", "--build-base",
                           "build", "--install-base", "install"], cwd=ws, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return ws / "install" / PACKAGE
