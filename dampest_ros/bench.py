"""Benchmarks (``make bench``): speed and memory of the simulator and the identification.

Each measurement runs in a fresh subprocess so that its peak resident memory is its own.
Prints a table; ``--hours`` sets the length of the long identification bags.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from dampest_ros.cli.common import table

VEHICLE = "bluerov2_heavy"


def _simulate(out: str, duration: str) -> dict[str, float]:
    from dampest_ros.core.excitation import make_excitation
    from dampest_ros.core.sensors import measure
    from dampest_ros.core.simulate import run
    from dampest_ros.io.bag import write_bag
    from dampest_ros.io.yaml_io import load_vehicle

    vehicle = load_vehicle(VEHICLE)
    t0 = time.perf_counter()
    traj = run(vehicle, make_excitation("B", vehicle, float(duration), seed=1))
    t1 = time.perf_counter()
    rec = measure(traj, vehicle.body.rho, vehicle.body.gravity, seed=1)
    t2 = time.perf_counter()
    write_bag(out, rec)
    t3 = time.perf_counter()
    return {"seconds": t3 - t0, "integrate": t1 - t0, "sensors": t2 - t1, "write": t3 - t2,
            "messages": float(sum(len(s) for s in rec.values()))}


def _deserialise(bag: str) -> dict[str, float]:
    from rosbags.highlevel import AnyReader

    t0 = time.perf_counter()
    n = 0
    with AnyReader([Path(bag)]) as reader:
        for conn, _, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)
            n += 1
    return {"seconds": time.perf_counter() - t0, "messages": float(n)}


def _identify(bag: str) -> dict[str, float]:
    from dampest_ros.cli.main import main

    t0 = time.perf_counter()
    with open(os.devnull, "w") as null:
        stdout, sys.stdout = sys.stdout, null
        try:
            status = main(["identify", bag, "--vehicle", VEHICLE])
        finally:
            sys.stdout = stdout
    return {"seconds": time.perf_counter() - t0, "status": float(status)}


TASKS = {"simulate": _simulate, "deserialise": _deserialise, "identify": _identify}


def _child(task: str, *args: str) -> dict[str, float]:
    """Run a task in a subprocess; its result plus the peak RSS (MB)."""
    code = ("import json, resource, sys; from dampest_ros import bench; "
            f"r = bench.TASKS[{task!r}](*{list(args)!r}); "
            "r['peak_mb'] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024; "
            "print(json.dumps(r))")
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    if out.returncode:
        raise RuntimeError(f"benchmark {task} failed:\n{out.stderr}")
    result: dict[str, float] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def main(argv: list[str] | None = None) -> int:
    """Run the benchmarks and print the table."""
    ap = argparse.ArgumentParser(prog="python -m dampest_ros.bench", description=__doc__)
    ap.add_argument("--hours", type=float, nargs="*", default=[1.0],
                    help="lengths of the identification bags in hours (default: 1)")
    ap.add_argument("--sim-seconds", type=float, default=600.0,
                    help="simulated seconds for the simulator benchmark (default: 600)")
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        sim = _child("simulate", f"{tmp}/sim", str(args.sim_seconds))
        speed = args.sim_seconds / sim["seconds"]
        rows.append((f"simulate {args.sim_seconds:.0f} s → MCAP (200 Hz IMU)",
                     f"{sim['seconds']:.1f} s", f"{speed:.0f}× real time", "≥ 50×",
                     f"{sim['peak_mb']:.0f}"))
        for hours in args.hours:
            bag = f"{tmp}/bag{hours}"
            gen = _child("simulate", bag, str(hours * 3600))
            des = _child("deserialise", bag)
            ide = _child("identify", bag)
            rows.append((f"rosbags deserialise {hours:g} h ({des['messages']:.0f} msgs)",
                         f"{des['seconds']:.1f} s", f"{des['messages'] / des['seconds']:.0f} msg/s",
                         "", f"{des['peak_mb']:.0f}"))
            rows.append((f"dampest identify {hours:g} h, end to end",
                         f"{ide['seconds']:.1f} s",
                         f"{ide['seconds'] / des['seconds']:.2f}× deserialise time",
                         "≤ 1×, ≤ 400 MB", f"{ide['peak_mb']:.0f}"))
            del gen
    print(table(("benchmark", "time", "figure", "goal", "peak MB"), rows))
    print(f"\nmachine: {os.cpu_count()} cores, Python {sys.version.split()[0]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
