"""The pooled rows (group ``pool``): eight bags identified pooled on 1 and 2 Dask workers."""

from __future__ import annotations

import argparse

from dampest_ros.bench.offline import quiet_identify
from dampest_ros.bench.runner import VEHICLE, child


def pool(workers: str, *bags: str) -> dict[str, float]:
    """``dampest identify BAG ...`` end to end on the LocalCluster of ``workers`` processes
    ``dampest identify --workers`` starts (passed as --scheduler so that it outlives the
    command), then the workers' peak RSS."""
    import resource

    from dask.distributed import Client

    from dampest_ros.cli.pool import local_cluster

    cluster = local_cluster(int(workers))
    try:
        t = quiet_identify([*bags, "--vehicle", VEHICLE, "--scheduler",
                             cluster.scheduler_address])
        with Client(cluster) as client:
            peak = client.run(lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
    finally:
        cluster.close()
    return {**t, "worker_peak_mb": max(peak.values()) / 1024}


def pool_rows(args: argparse.Namespace, tmp: str) -> list[tuple[str, ...]]:
    """Eight protocol-B bags (seeds 1–8) identified pooled on 1 and on 2 Dask workers, and
    the workers' peak memory for 4 and for 8 bags (2 workers)."""
    seconds = args.pool_seconds
    bags = [f"{tmp}/pool{k}" for k in range(1, 9)]
    for k, bag in enumerate(bags, 1):
        child("offline.simulate", bag, str(seconds), "native", str(k))
    one, two = child("pool.pool", "1", *bags), child("pool.pool", "2", *bags)
    four = child("pool.pool", "2", *bags[:4])
    name = f"identify 8 × {seconds:.0f} s bags pooled (Dask)"
    return [(f"{name}, 1 worker", f"{one['seconds']:.1f} s", "", "",
             f"{one['worker_peak_mb']:.0f} (worker)"),
            (f"{name}, 2 workers", f"{two['seconds']:.1f} s",
             f"{one['seconds'] / two['seconds']:.2f}× 1 worker", "≥ 1.6×",
             f"{two['worker_peak_mb']:.0f} (worker)"),
            ("  the same, 4 bags on 2 workers", f"{four['seconds']:.1f} s",
             f"worker peak {four['worker_peak_mb']:.0f} MB (4 bags) vs "
             f"{two['worker_peak_mb']:.0f} MB (8)", "flat", "")]
