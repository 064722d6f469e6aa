"""dampest identify over several logs: each log reduced on a Dask worker, one pooled fit, the
drift of the damping between the logs (the maths: dampest_ros/core/identification/pool.py).

Workers read the logs themselves (paths as the workers see them), so nothing but the logs'
statistics travels: each log's samples stay on the worker that reduced them until the pooled
fit's passes over them have run there (only --report brings them here); a log named by URL is
copied to the worker that reads it (dampest_ros/io/remote.py). By default a LocalCluster of
--workers processes runs on this machine; --scheduler ADDRESS uses an existing Dask cluster.
A log that fails is reported with its reason and left out; the rest go on.
"""

from __future__ import annotations

import argparse
import contextlib
import glob
import io
import logging
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from dampest_ros.cli.common import table
from dampest_ros.cli.inputs import cut, load_samples, structure_of
from dampest_ros.cli.main import expected
from dampest_ros.core.identification.batch import Fit, FitOptions
from dampest_ros.core.identification.pool import Drift, LogStatistics, MapLogs, log_statistics
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.core.signals.extent import Extent
from dampest_ros.core.signals.samples import Samples
from dampest_ros.core.simulation.excitation import speed_limits
from dampest_ros.io.remote import glob_url, in_memory, is_url, local_log, local_name
from dampest_ros.io.yaml_io import load_vehicle

#: Characters that make an INPUT a glob pattern.
GLOB = "*?["


def expand_inputs(inputs: Sequence[str]) -> list[str]:
    """The logs INPUT names: a log itself, a glob pattern (sorted matches), or a ``.txt``
    file listing logs (one per line; blank lines and ``#`` comments skipped; relative paths
    from the list's directory). ``file://`` URLs are paths; other URLs (any fsspec
    filesystem, :mod:`dampest_ros.io.remote`) are logs too, globbed on their filesystem.

    Raises
    ------
    ConfigError
        A pattern that matches nothing, or a list that names nothing (name, reason and fix).
    """
    out: list[str] = []
    for given in inputs:
        item = local_name(given)
        if any(c in item for c in GLOB):
            found = glob_url(item) if is_url(item) else sorted(glob.glob(item))
            if not found:
                raise ConfigError(given, "the pattern matches no log (quote it so the shell "
                                         "does not expand it, check the path)")
            out += found
        elif item.endswith(".txt") and Path(item).is_file():
            base = Path(item).parent
            listed = [line.split("#", 1)[0].strip()
                      for line in Path(item).read_text(encoding="utf-8").splitlines()]
            listed = [str(base / x) if not (Path(x).is_absolute() or is_url(x)) else x
                      for x in listed if x]
            if not listed:
                raise ConfigError(given, "the list names no log (one path per line)")
            out += expand_inputs(listed)
        else:
            out.append(item)
    return out


def check_pooled_options(args: argparse.Namespace) -> None:
    """Options that take one log only, refused with the way to get the same result."""
    if args.method == "rls":
        raise ConfigError("--method rls", "replays one bag; give one log (or pool with a "
                                          "batch method)")
    if args.select:
        raise ConfigError("--select", "searches the structure on one log; run it on one "
                                      "log, then pool with --terms or --prior")
    if args.holdout is not None:
        raise ConfigError("--holdout", "takes one log; to score on unseen data, leave a log "
                                       "out and run dampest validate MODEL LOG")


def guarded(work: Callable[[str], Any], path: str, debug: bool) -> tuple[Any, str, str]:
    """``work(path)`` on a worker: its result (None when it failed), what it printed on
    stderr (progress bars dropped) and why it failed (one line, "" when it did not).
    Failures are returned, not raised, so that no worker prints a traceback; ``debug``
    (``--debug``) raises them."""
    captured = io.StringIO()
    try:
        with contextlib.redirect_stderr(captured):
            result = work(path)
        why = ""
    except Exception as exc:
        if debug:
            raise
        result, why = None, (str(exc) if expected(exc) else
                             f"unexpected {type(exc).__name__}: {exc} (--debug shows where)")
    notes = "\n".join(line for line in captured.getvalue().replace("\r", "\n").splitlines()
                      if line.strip() and "[" not in line)
    return result, notes, why


def reduce_log(path: str, args: argparse.Namespace, prior: np.ndarray | None,
               prior_std: np.ndarray | None) -> tuple[Samples, LogStatistics]:
    """Preprocess one log (a path, or a URL copied here first) and reduce it (runs on a
    worker): its samples, which stay there, and their statistics, which travel."""
    vehicle = load_vehicle(args.vehicle)
    model, _ = structure_of(args, vehicle)
    with local_log(path) as local:
        samples = cut(load_samples(local, vehicle, args), args)
    extent = Extent.of(samples)
    options = FitOptions(method=args.method, cutoff=args.cutoff, speed_range=tuple(
        speed_limits(vehicle, force=extent.force)))
    return samples, log_statistics(path, samples, model, vehicle.body, options, prior,
                                   prior_std, extent)


#: How to get what pooling needs: the 'pool' extra of setup.py (Dask has no rosdep key).
POOL_HINT = "pip install dask distributed fsspec (dampest_ros's optional 'pool' extra)"


def need_dask() -> None:
    """Refuse, in one line saying how to install it, when Dask is missing.

    Raises
    ------
    ConfigError
        Naming the logs option and :data:`POOL_HINT`.
    """
    try:
        import dask.distributed  # noqa: F401
    except ImportError as exc:
        raise ConfigError("LOG LOG ...", f"several logs are read on Dask, which is not "
                                          f"installed ({exc}); {POOL_HINT}") from exc


def _client(args: argparse.Namespace, paths: Sequence[str]) -> Any:
    """A Dask client: on --scheduler, or on a LocalCluster of :func:`local_workers`
    processes (threads of this process when a log is in memory: :func:`in_memory`)."""
    from dask.distributed import Client
    if args.workers is not None and args.workers < 1:
        raise ConfigError("--workers", f"{args.workers}: needs at least 1 worker")
    if args.scheduler:
        try:
            return Client(args.scheduler, timeout="10s")
        except OSError as exc:
            raise ConfigError("--scheduler", f"{args.scheduler}: no Dask scheduler answers "
                                             f"({exc}); start one or leave the option out "
                                             "for a local cluster") from exc
    here = [p for p in paths if in_memory(p)]
    if here:
        print(f"note: {here[0]} is in memory, which worker processes do not share: the logs "
              "are read by threads of this process", file=sys.stderr)
    return Client(local_cluster(local_workers(args.workers, len(paths)), processes=not here))


def local_workers(asked: int | None, n_logs: int) -> int:
    """The local cluster's worker count: ``asked`` (--workers, default the CPU count), at
    most one per log and one per CPU (each worker reads one log at a time, and workers beyond
    the CPUs only compete for them and are slow to start); a cap of ``asked`` is noted on
    stderr."""
    cpus = os.cpu_count() or 1
    workers = min(asked or cpus, n_logs, cpus)
    if asked is not None and workers < asked:
        print(f"note: --workers {asked} capped to {workers} (one per log and per CPU: "
              f"{n_logs} logs, {cpus} CPUs)", file=sys.stderr)
    return workers


def local_cluster(workers: int, processes: bool = True) -> Any:
    """A Dask LocalCluster of ``workers`` single-threaded processes (threads of this
    process if not ``processes``), quiet; its scheduler's HTTP server (which runs whatever
    the dashboard option says) on a free port, so that two commands at once do not warn
    that port 8787 is taken.

    Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_ set, which also fixes glibc's
    mmap threshold: every array over 128 kB is then mapped and unmapped afresh, and the
    preprocessing and regression (many such temporaries) take 1.6× as long (2.9 s instead
    of 1.8 s per 600 s log). Our workers start without it; memory returns to the system
    when a task's arrays are freed all the same (they are mmapped or trimmed by glibc).

    Each worker process imports this module (numpy, scipy, the readers and the
    preprocessing: 0.5 s of CPU) as it starts, not in its first log: the cluster is ready
    when it is up, and a log's time is its own work (the first log of each worker took
    0.5 s longer, which no number of workers shares out).

    Dask's statistical profiler is off in our workers: it samples the running task's stack
    every 10 ms, and with as many workers as CPUs it takes that time from the tasks (a
    600 s log's reduction: 0.38–0.44 s with it, 0.35–0.40 s without, on 2 workers and
    2 CPUs; 0.35 s on 1 worker)."""
    import dask
    from dask.distributed import LocalCluster
    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                          "distributed.worker.profile.enabled": False}):
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=processes,
                            dashboard_address=":0", silence_logs=logging.CRITICAL,
                            preload=[__name__] if processes else [])


def sent(reduced: tuple[Any, str, str], send: Callable[[Any], Any]) -> tuple[Any, str, str]:
    """:func:`guarded`'s result with ``send`` of its work's result (None stays None): what
    of a kept result travels (run where the result is)."""
    result, notes, why = reduced
    return (None if result is None else send(result)), notes, why


@contextlib.contextmanager
def map_logs_on_dask(paths: Sequence[str], work: Callable[[str], Any], args: argparse.Namespace,
                     verb: str = "read", keep: Callable[[Any], Any] | None = None
                     ) -> Iterator[tuple[Any, dict[str, Any], dict[str, str], dict[str, Any]]]:
    """Run ``work(path)`` for every log on Dask (--workers, --scheduler), with a progress line
    on stderr and each log's notes prefixed by its path.

    Yields the client, the result of each log that worked, in the given order, the reason
    of each that failed, and, with ``keep``, each worked log's future: its result stays on
    the worker that made it until the block ends (to run more work there, where it is held),
    and only ``keep`` of it is sent here. Otherwise the workers keep nothing: their memory
    does not grow with the number of logs. The cluster lives until the block ends.
    """
    need_dask()
    from dask.distributed import as_completed
    client = _client(args, paths)
    done: dict[str, Any] = {}
    failed: dict[str, str] = {}
    held: dict[str, Any] = {}
    try:
        made = {p: client.submit(guarded, work, p, args.debug, pure=False) for p in paths}
        # with keep, what is sent is made where the result is, which stays there
        futures = {(client.submit(sent, f, keep, pure=False) if keep else f): p
                   for p, f in made.items()}
        if not keep:
            made.clear()  # each result is forgotten once it is here
        for k, future in enumerate(as_completed(futures), 1):
            path = futures.pop(future)  # the worker may forget the result once it is here
            result, notes, why = future.result()
            for line in notes.splitlines():
                print(f"{path}: {line}", file=sys.stderr)
            if result is None:
                failed[path] = why
            else:
                done[path] = result
                if keep:
                    held[path] = made[path]
            sys.stderr.write(f"\rlogs [{'#' * (25 * k // len(paths)):25s}] {k}/{len(paths)}"
                             f" {verb}, {len(failed)} failed")
            sys.stderr.flush()
        sys.stderr.write("\n")
        for path, why in failed.items():
            print(f"left out: {path}: {why}", file=sys.stderr)
        if not done:
            raise ConfigError("INPUT", "none of the logs could be read (reasons above)")
        made.clear()  # the held futures keep their results on the workers, no other
        yield client, {p: done[p] for p in paths if p in done}, failed, held
    finally:
        cluster = getattr(client, "cluster", None)
        client.close()
        if cluster is not None and not args.scheduler:
            cluster.close()


def on_reduced(reduced: tuple[tuple[Samples, LogStatistics], str, str], k: int,
               fn: Callable[[Samples, int], Any]) -> Any:
    """``fn(samples, k)`` on the worker holding ``reduced``, :func:`guarded`'s result of
    :func:`reduce_log` for log k."""
    return fn(reduced[0][0], k)


def samples_of(samples: Samples, k: int) -> Samples:
    """A log's samples themselves (the :data:`MapLogs` call that brings them here)."""
    return samples


def statistics_of(reduced: tuple[Samples, LogStatistics]) -> LogStatistics:
    """What of :func:`reduce_log`'s result is sent: the statistics."""
    return reduced[1]


@contextlib.contextmanager
def reduce_all(paths: Sequence[str], args: argparse.Namespace, prior: np.ndarray | None,
               prior_std: np.ndarray | None
               ) -> Iterator[tuple[list[LogStatistics], dict[str, str], MapLogs]]:
    """Map :func:`reduce_log` over the logs on Dask (:func:`map_logs_on_dask`).

    Yields the statistics of the logs that worked (in the given order), the reason of each
    that failed, and a :data:`~dampest_ros.core.identification.pool.MapLogs` that runs a
    function on the samples of each log in that list (which may shrink) on the worker that
    holds them (the pooled fit's passes over the samples).
    """
    work = partial(reduce_log, args=args, prior=prior, prior_std=prior_std)
    with map_logs_on_dask(paths, work, args, "reduced", keep=statistics_of) as (
            client, done, failed, held):
        logs: list[LogStatistics] = list(done.values())

        def map_logs(fn: Callable[[Samples, int], Any]) -> list[Any]:
            # each call on the worker that reduced the log and holds it: no log travels again
            return list(client.gather([client.submit(on_reduced, held[g.name], k, fn,
                                                     pure=False)
                                       for k, g in enumerate(logs)]))

        yield logs, failed, map_logs


def drift_table(d: Drift, pooled: Fit) -> str:
    """Per coefficient: the pooled estimate, the test of change and where it changed."""
    rows: list[tuple[str | float, ...]] = []
    for j, name in enumerate(d.names):
        where = ""
        if d.moved[j]:
            k = int(d.change_after[j])
            where = (f"after {Path(d.logs[k]).name}: {d.shift[j]:+.4g} ± "
                     f"{d.shift_std[j]:.2g}")
        verdict = "CHANGED" if d.moved[j] else "no change"
        if d.dof[j] == 0:  # fewer than two logs identify it: nothing to compare
            n = int(np.isfinite(d.theta[:, j]).sum())
            verdict = f"not tested: identified in {n} of {len(d.logs)} logs"
        rows.append((name, float(pooled.theta[j]), float(pooled.std[j]), float(d.chi2[j]),
                     int(d.dof[j]), float(d.p_value[j]), verdict, where))
    return table(("parameter", "pooled", "std", "chi2", "dof", "p", "drift", "where"), rows)


def log_table(d: Drift) -> str:
    """Per log, in start order: its estimates of the coefficients that moved."""
    moved = np.flatnonzero(d.moved)
    header = ("log", "start (s)", *(d.names[j] for j in moved))
    rows = [(Path(name).name, float(d.start[b]),
             *(f"{d.theta[b, j]:.4g} ± {d.std[b, j]:.2g}" for j in moved))
            for b, name in enumerate(d.logs)]
    return table(header, rows)


def plot_drift(path: Path, d: Drift, pooled: Fit, units: dict[str, str]) -> None:
    """Each coefficient's per-log estimate ± 2σ, each log at its own x (its start time after
    the first log's, or its index when two logs start at the same time) and colour, named in
    the legend, with the pooled estimate; changed coefficients titled as such (PNG)."""
    import numpy as np
    from matplotlib.figure import Figure

    p = len(d.names)
    cols = min(p, 4)
    rows = -(-p // cols)
    fig = Figure(figsize=(3.2 * cols, 2.4 * rows + 0.3 * (len(d.logs) // 4 + 1)))
    axes = fig.subplots(rows, cols, squeeze=False)
    by_start = len(np.unique(d.start)) == len(d.start)
    x = d.start - d.start[0] if by_start else np.arange(len(d.logs), dtype=float)
    for j, ax in enumerate(axes.flat):
        if j >= p:
            ax.set_visible(False)
            continue
        for b, log in enumerate(d.logs):
            ax.errorbar(x[b], d.theta[b, j], yerr=2 * d.std[b, j], fmt="o", ms=3, capsize=2,
                        color=f"C{b % 10}", label=log)
        ax.axhline(pooled.theta[j], color="k", lw=0.8, ls="--", label="pooled")
        ax.set_title(d.names[j] + (" (changed)" if d.moved[j] else ""), fontsize=9)
        ax.set_xlabel("log start − first log start (s)" if by_start else "log", fontsize=7)
        if not by_start:
            ax.set_xticks(x)
        ax.set_ylabel(f"{d.names[j]} ({units.get(d.names[j], 'SI')})", fontsize=7)
        ax.ticklabel_format(axis="y", style="plain", useOffset=False)
        ax.tick_params(labelsize=7)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncols=min(len(labels), 4), fontsize=7)
    fig.tight_layout(rect=(0, 0.3 * (len(d.logs) // 4 + 1) / fig.get_figheight(), 1, 1))
    fig.savefig(path, dpi=90)
