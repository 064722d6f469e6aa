"""Running one benchmark task in a fresh subprocess (so that its peak resident memory is its
own), and what the tasks share: the vehicles, the ROS environment, the console script."""

from __future__ import annotations

import importlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

VEHICLE = "bluerov2_heavy"
MUJOCO_VEHICLE = "torpedo_auv"  # the stiffer of the two MuJoCo presets (slender, finned)


def ros_env() -> None:
    """Keep the benchmark's ROS traffic on this host (domain: the environment's, else 77)."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", "77")


def dampest_script() -> str:
    """The dampest console script of this interpreter's environment (else the one on PATH)."""
    here = Path(sys.executable).parent / "dampest"
    return str(here) if here.exists() else (shutil.which("dampest") or "dampest")


def run_task(task: str, *args: str) -> dict[str, float]:
    """Call ``task`` (``MODULE.FUNCTION`` of this package) with ``args``."""
    module, function = task.rsplit(".", 1)
    result: dict[str, float] = getattr(
        importlib.import_module(f"dampest_ros.bench.{module}"), function)(*args)
    return result


def spawn(task: str, *args: str) -> subprocess.Popen[str]:
    """Start a task in a subprocess (it prints its result plus the peak RSS as JSON)."""
    code = ("import json, resource; from dampest_ros.bench.runner import run_task; "
            f"r = run_task({task!r}, *{list(args)!r}); "
            "r['peak_mb'] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024; "
            "print(json.dumps(r))")
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)


def result(proc: subprocess.Popen[str], task: str) -> dict[str, float]:
    out, err = proc.communicate()
    if proc.returncode:
        raise RuntimeError(f"benchmark {task} failed:\n{err}")
    result: dict[str, float] = json.loads(out.strip().splitlines()[-1])
    return result


def child(task: str, *args: str) -> dict[str, float]:
    """Run a task in a subprocess; its result plus the peak RSS (MB)."""
    return result(spawn(task, *args), task)
