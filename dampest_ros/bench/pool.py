"""The pooled rows (group ``pool``): eight bags identified pooled on 1 and 2 Dask workers.

On a shared machine the wall-clock ratio of the two runs says more about the other load than
about the pooling, so the rows also give the 2-worker run's speed-up bound from CPU times:
(S + Σ jobs) / (S + Σ_maps max_w Σ jobs of worker w), S the CPU time of the thread that runs
``dampest identify`` (the serial part, and the receiving of the logs' statistics), a job a
log's reduction (with the picking of what of it is sent) or its part of one pass of the
pooled fit (CPU time on its worker), and each
map (the reduction, every pass) a barrier; and the same with the 1-worker run's S + Σ jobs
above the line, which also counts what each worker repeats (what it imports, say). CPU times
hardly depend on the other load; the scheduler's event loop, in the same process, is left out
(0.03 s of CPU per second of wall clock, idle or not).
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict

from dampest_ros.bench.offline import quiet_identify
from dampest_ros.bench.runner import VEHICLE, child


def maps(jobs: dict[str, list[tuple[str, float, float]]], logs: int
         ) -> list[dict[str, float]]:
    """The jobs' CPU (s) per map and worker, from each worker's (name, start, CPU) of its
    jobs: the reductions (and the picking of what of each is sent), then the passes of the
    pooled fit (``logs`` jobs each, in start order: every log reduced)."""
    timed = sorted((start, name, w, cpu) for w, js in jobs.items() for name, start, cpu in js)
    reduce: dict[str, float] = defaultdict(float)
    passes: list[dict[str, float]] = []
    in_passes = 0
    for _, name, w, cpu in timed:
        if name in ("guarded", "sent"):  # a log's reduction, what is sent (cli/pool.py)
            reduce[w] += cpu
            continue
        if in_passes % logs == 0:
            passes.append(defaultdict(float))
        passes[-1][w] += cpu
        in_passes += 1
    return [reduce, *passes]


def pool(workers: str, *bags: str) -> dict[str, float]:
    """``dampest identify BAG ...`` end to end on the LocalCluster of ``workers`` processes
    ``dampest identify --workers`` starts (passed as --scheduler so that it outlives the
    command), then the workers' peak RSS, the CPU time of the thread that ran the command
    (``serial_cpu``), the jobs' CPU summed (``jobs_cpu``) and the busiest worker's, map by
    map (``busiest_cpu``)."""
    import resource

    from dask.distributed import Client

    from dampest_ros.bench.job_cpu import NAME, JobCpu, worker_jobs
    from dampest_ros.cli.pool import local_cluster

    cluster = local_cluster(int(workers))
    try:
        with Client(cluster) as client:
            client.register_plugin(JobCpu(), name=NAME)
            cpu = time.thread_time()
            t = quiet_identify([*bags, "--vehicle", VEHICLE, "--scheduler",
                                 cluster.scheduler_address])
            cpu = time.thread_time() - cpu
            peak = client.run(lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
            per_map = maps(client.run(worker_jobs), len(bags))
    finally:
        cluster.close()
    return {**t, "worker_peak_mb": max(peak.values()) / 1024, "serial_cpu": cpu,
            "jobs_cpu": sum(sum(m.values()) for m in per_map),
            "busiest_cpu": sum(max(m.values(), default=0.0) for m in per_map)}


#: Alternated 1- and 2-worker runs of the pooled rows.
PAIRS = 5


def pool_rows(args: argparse.Namespace, tmp: str) -> list[tuple[str, ...]]:
    """Eight protocol-B bags (seeds 1–8) identified pooled on 1 and on 2 Dask workers
    (:data:`PAIRS` alternated pairs, the median pair reported), and the workers' peak memory
    for 4 and for 8 bags (2 workers)."""
    import os

    seconds = args.pool_seconds
    bags = [f"{tmp}/pool{k}" for k in range(1, 9)]
    for k, bag in enumerate(bags, 1):
        child("offline.simulate", bag, str(seconds), "native", str(k))
    # alternated pairs: a run varies by ±0.1 s with the machine's other work, so the row
    # gives the median pair (by the ratio of its walls) and every pair's ratio
    pairs = sorted(((child("pool.pool", "1", *bags), child("pool.pool", "2", *bags))
                    for _ in range(PAIRS)), key=lambda r: r[0]["seconds"] / r[1]["seconds"])
    one, two = pairs[len(pairs) // 2]
    ratios = ", ".join(f"{a['seconds'] / b['seconds']:.2f}" for a, b in pairs)
    load = os.getloadavg()[0]
    four = child("pool.pool", "2", *bags[:4])
    # (S + Σ jobs) / (S + Σ_maps busiest worker) of the 2-worker run, and with the 1-worker
    # run's S + Σ jobs above the line
    below = two["serial_cpu"] + two["busiest_cpu"]
    bound = (two["serial_cpu"] + two["jobs_cpu"]) / below
    across = (one["serial_cpu"] + one["jobs_cpu"]) / below
    name = f"identify 8 × {seconds:.0f} s bags pooled (Dask)"
    return [(f"{name}, 1 worker", f"{one['seconds']:.1f} s",
             f"CPU: jobs {one['jobs_cpu']:.1f} s, serial {one['serial_cpu']:.1f} s", "",
             f"{one['worker_peak_mb']:.0f} (worker)"),
            (f"{name}, 2 workers", f"{two['seconds']:.1f} s",
             f"bound {bound:.2f}× 1 worker ({across:.2f}× over the 1-worker run's CPU); wall "
             f"{one['seconds'] / two['seconds']:.2f}× (median of {PAIRS} alternated pairs: "
             f"{ratios}) at load {load:.1f}", "≥ 1.7×",
             f"{two['worker_peak_mb']:.0f} (worker)"),
            ("  the same, 4 bags on 2 workers", f"{four['seconds']:.1f} s",
             f"worker peak {four['worker_peak_mb']:.0f} MB (4 bags) vs "
             f"{two['worker_peak_mb']:.0f} MB (8)", "flat", "")]
