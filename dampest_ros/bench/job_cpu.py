"""A Dask worker plugin that notes each task's CPU time on its worker (the pooled rows'
speed-up bound, :mod:`dampest_ros.bench.pool`); imported only where Dask is."""

from __future__ import annotations

import time
from typing import Any

from dask.utils import key_split
from distributed.diagnostics.plugin import WorkerPlugin

#: The name the plugin is registered under.
NAME = "dampest-job-cpu"


class JobCpu(WorkerPlugin):  # type: ignore[misc]
    """Each task's CPU time (s): its worker's process CPU from the task's start to its end
    (one thread per worker), with the task's name and start time (s, UNIX)."""

    def setup(self, worker: Any) -> None:
        self.started: dict[Any, tuple[float, float]] = {}
        self.jobs: list[tuple[str, float, float]] = []

    def transition(self, key: Any, start: str, finish: str, **kwargs: Any) -> None:
        if finish == "executing":
            self.started[key] = (time.time(), time.process_time())
        elif start == "executing" and key in self.started:
            wall, cpu = self.started.pop(key)
            self.jobs.append((key_split(key), wall, time.process_time() - cpu))


def worker_jobs(dask_worker: Any) -> list[tuple[str, float, float]]:
    """The (name, start, CPU) of every task :class:`JobCpu` noted on this worker (for
    ``client.run``)."""
    jobs: list[tuple[str, float, float]] = dask_worker.plugins[NAME].jobs
    return jobs
