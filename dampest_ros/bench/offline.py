"""The offline rows: the simulator, rosbags deserialisation against ``dampest identify`` on
long bags, and ``--select`` against plain identify (groups ``simulate``, ``identify``,
``select``)."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from dampest_ros.bench.runner import MUJOCO_VEHICLE, VEHICLE, child


def simulate(out: str, duration: str, backend: str = "native", seed: str = "1"
              ) -> dict[str, float]:
    from dampest_ros.core.simulation.excitation import make_excitation
    from dampest_ros.core.simulation.sensors import measure
    from dampest_ros.core.simulation.simulate import run
    from dampest_ros.io.bag import write_bag
    from dampest_ros.io.yaml_io import load_vehicle

    vehicle = load_vehicle(VEHICLE if backend == "native" else MUJOCO_VEHICLE)
    t0 = time.perf_counter()
    traj = run(vehicle, make_excitation("B", vehicle, float(duration), seed=int(seed)),
               backend=backend)
    t1 = time.perf_counter()
    rec = measure(traj, vehicle.body.rho, vehicle.body.gravity, seed=int(seed))
    t2 = time.perf_counter()
    write_bag(out, rec)
    t3 = time.perf_counter()
    return {"seconds": t3 - t0, "integrate": t1 - t0, "sensors": t2 - t1, "write": t3 - t2,
            "messages": float(sum(len(s) for s in rec.values()))}


def deserialise(bag: str) -> dict[str, float]:
    from rosbags.highlevel import AnyReader

    t0 = time.perf_counter()
    n = 0
    with AnyReader([Path(bag)]) as reader:
        for conn, _, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)
            n += 1
    return {"seconds": time.perf_counter() - t0, "messages": float(n)}


def identify(bag: str, vehicle: str = VEHICLE, *options: str) -> dict[str, float]:
    return quiet_identify([bag, "--vehicle", vehicle, *options])


def quiet_identify(argv: list[str]) -> dict[str, float]:
    """``dampest identify ARGV`` with its output discarded: seconds and exit status."""
    from dampest_ros.cli.main import main

    t0 = time.perf_counter()
    with open(os.devnull, "w") as null:
        stdout, stderr, sys.stdout, sys.stderr = sys.stdout, sys.stderr, null, null
        try:
            status = main(["identify", *argv])
        finally:
            sys.stdout, sys.stderr = stdout, stderr
    return {"seconds": time.perf_counter() - t0, "status": float(status)}


def refuse_big_csv(path: str, gigabytes: str) -> dict[str, float]:
    """``dampest identify`` of a sparse CSV of ``gigabytes`` GB (a header, one row, a hole):
    seconds to its refusal and the exit status."""
    with open(path, "w") as f:
        f.write("time,u,v,w,p,q,r\n0,0,0,0,0,0,0\n")
    os.truncate(path, int(float(gigabytes) * 1e9))
    try:
        return quiet_identify([path, "--vehicle", VEHICLE])
    finally:
        os.remove(path)


def limits_rows(args: argparse.Namespace, tmp: str) -> list[tuple[str, ...]]:
    """A CSV over the size limit, refused before it is read."""
    big = child("offline.refuse_big_csv", f"{tmp}/big.csv", "2")
    return [("dampest identify of a 2 GB (sparse) CSV: refused by size",
             f"{big['seconds']:.2f} s", f"exit status {big['status']:.0f}", "< 2 s, < 300 MB",
             f"{big['peak_mb']:.0f}")]


def simulate_rows(args: argparse.Namespace, tmp: str) -> list[tuple[str, ...]]:
    """The simulator, native and MuJoCo, writing an MCAP bag."""
    sim = child("offline.simulate", f"{tmp}/sim", str(args.sim_seconds))
    rows: list[tuple[str, ...]] = [
        (f"simulate {args.sim_seconds:.0f} s → MCAP (200 Hz IMU)", f"{sim['seconds']:.1f} s",
         f"{args.sim_seconds / sim['seconds']:.0f}× real time", "≥ 50×", f"{sim['peak_mb']:.0f}")]
    sim = child("offline.simulate", f"{tmp}/mj", str(args.sim_seconds), "mujoco")
    rows.append((f"simulate --backend mujoco {args.sim_seconds:.0f} s ({MUJOCO_VEHICLE}) → MCAP",
                 f"{sim['seconds']:.1f} s", f"{args.sim_seconds / sim['seconds']:.0f}× real time",
                 "≥ 20×", f"{sim['peak_mb']:.0f}"))
    return rows


def identify_rows(args: argparse.Namespace, tmp: str) -> list[tuple[str, ...]]:
    """rosbags deserialisation against ``dampest identify`` end to end, per ``--hours``."""
    rows: list[tuple[str, ...]] = []
    for hours in args.hours:
        bag = f"{tmp}/bag{hours}"
        child("offline.simulate", bag, str(hours * 3600))
        des = child("offline.deserialise", bag)
        ide = child("offline.identify", bag)
        rows.append((f"rosbags deserialise {hours:g} h ({des['messages']:.0f} msgs)",
                     f"{des['seconds']:.1f} s", f"{des['messages'] / des['seconds']:.0f} msg/s",
                     "", f"{des['peak_mb']:.0f}"))
        rows.append((f"dampest identify {hours:g} h, end to end", f"{ide['seconds']:.1f} s",
                     f"identify / deserialise = {ide['seconds'] / des['seconds']:.2f}",
                     "≤ 0.4, ≤ 400 MB", f"{ide['peak_mb']:.0f}"))
    return rows


def select_rows(args: argparse.Namespace, tmp: str) -> list[tuple[str, ...]]:
    """The default ``dampest identify`` (library terms added where the preset misfits) and
    ``--select`` (the whole library) against ``--no-select`` (the preset's terms) on a MuJoCo
    bag."""
    from dampest_ros.core.physics.terms import library

    bag = f"{tmp}/select"
    child("offline.simulate", bag, str(args.sim_seconds), "mujoco")
    preset = child("offline.identify", bag, MUJOCO_VEHICLE, "--no-select")
    default = child("offline.identify", bag, MUJOCO_VEHICLE)
    select = child("offline.identify", bag, MUJOCO_VEHICLE, "--select")
    return [(f"identify --no-select {args.sim_seconds:.0f} s {MUJOCO_VEHICLE} (MuJoCo)",
             f"{preset['seconds']:.1f} s", "", "", f"{preset['peak_mb']:.0f}"),
            ("  the default (library terms where the preset misfits)",
             f"{default['seconds']:.1f} s",
             f"{default['seconds'] / preset['seconds']:.2f}× --no-select", "≤ 2×",
             f"{default['peak_mb']:.0f}"),
            (f"  the same with --select ({len(library())} library terms)",
             f"{select['seconds']:.1f} s",
             f"{select['seconds'] / preset['seconds']:.2f}× --no-select", "≤ 3×",
             f"{select['peak_mb']:.0f}")]
