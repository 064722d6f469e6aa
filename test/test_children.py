"""The children fixture (test/conftest.py): a child's whole process group is killed when the
test ends, and on a timeout of run()."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

#: A child that starts a grandchild in its process group, writes its pid, and waits.
PARENT = ("import subprocess, sys, time\n"
          "g = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(600)'])\n"
          "open(sys.argv[1], 'w').write(str(g.pid))\n"
          "time.sleep(600)\n")


def alive(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state != "Z"


def grandchild(path: Path, timeout: float = 30.0) -> int:
    end = time.monotonic() + timeout
    while not path.exists() or not path.read_text():
        assert time.monotonic() < end, "the child did not start its own"
        time.sleep(0.05)
    return int(path.read_text())


def test_close_kills_the_child_and_its_grandchild(children: Any, tmp_path: Path) -> None:
    proc = children.start([sys.executable, "-c", PARENT, str(tmp_path / "pid")])
    pid = grandchild(tmp_path / "pid")
    assert os.getpgid(proc.pid) == proc.pid == os.getpgid(pid)  # a session of its own
    children.close()
    assert proc.returncode is not None and not alive(proc.pid)
    end = time.monotonic() + 10.0
    while alive(pid) and time.monotonic() < end:  # reaped by init once orphaned
        time.sleep(0.05)
    assert not alive(pid)


def test_run_kills_the_group_on_timeout(children: Any, tmp_path: Path) -> None:
    t0 = time.monotonic()
    with pytest.raises(subprocess.TimeoutExpired):
        children.run([sys.executable, "-c", PARENT, str(tmp_path / "pid")], timeout=5.0,
                     capture_output=True)
    pid = grandchild(tmp_path / "pid", timeout=1.0)
    end = time.monotonic() + 10.0
    while alive(pid) and time.monotonic() < end:
        time.sleep(0.05)
    assert not alive(pid) and time.monotonic() - t0 < 20.0
