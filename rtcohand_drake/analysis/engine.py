"""Many independent runs on a distributed engine: Dask distributed, or this process without it.

A study or a benchmark sweep is a list of independent tasks: one closed-loop
run each, returning a small summary (and writing its run log where the
caller says). `run_tasks` runs them

- on an existing Dask cluster, with `address` ("tcp://host:8786", a
  scheduler started by `dask scheduler` / `dask worker`, or any Dask
  deployment), so the same command scales from a laptop to a cluster;
- by default, on a local cluster it starts and stops itself: `workers`
  single-threaded worker processes on this machine;
- with `workers=0`, or when the `distributed` extra is not installed
  (`pip install -e ".[distributed]"`), one after the other in this process,
  with a one-line note.

Dask distributed is the engine because it is a pure-Python install of a few
MB whose local cluster starts in about a second on a laptop, and whose
client submits ordinary functions of an importable module (the run
command's own code) with no change to them; the same `Client(address)` joins
a cluster. Ray would do the same with a much larger install and start-up.

A task that raises is retried once (a fresh attempt, possibly on another
worker); if it raises again it is reported with its error, never dropped.
Progress (done, failed, and an estimate of the time left) goes to stderr.

With `runs_per_worker=N` on Dask, the tasks run in batches of N per worker,
and the workers are restarted (fresh processes) between batches: a worker's
memory grows with the runs it has done (Drake 1.51.1 never frees a Python
LeafSystem with ports or events), and each task reports its process's peak
memory to size N by.
"""

from __future__ import annotations

import dataclasses as dc
import sys
import time
from typing import Any, Callable, Hashable, Sequence

RETRIES = 1


@dc.dataclass
class Outcome:
    """One task's result: its `value`, or, after `attempts` tries, its `error` (one line)."""

    key: Hashable
    value: Any = None
    error: str | None = None
    attempts: int = 0
    seconds: float = 0.0  # wall time of the successful (or last) attempt
    peak_memory_gb: float | None = None  # the peak resident memory of the process that ran it, after it ran

    @property
    def ok(self) -> bool:
        return self.error is None


@dc.dataclass
class EngineReport:
    """What ran where: the engine, its workers, the wall time and the outcomes in task order."""

    engine: str
    workers: int
    wall_s: float
    outcomes: list[Outcome]

    @property
    def failed(self) -> list[Outcome]:
        return [o for o in self.outcomes if not o.ok]

    def peak_memory_gb(self) -> float | None:
        """The largest peak resident memory of a process that ran a task (None where unknown).

        A worker's memory grows with the runs it has done: Drake 1.51.1 never frees a Python
        LeafSystem that declares ports or events (docs/studies.md)."""
        values = [o.peak_memory_gb for o in self.outcomes if o.peak_memory_gb is not None]
        return max(values) if values else None

    def throughput_per_worker_h(self) -> float:
        """Tasks completed per worker-hour over the whole wall time (start-up included)."""
        done = sum(o.ok for o in self.outcomes)
        return done / max(self.workers, 1) / max(self.wall_s, 1e-9) * 3600.0


def _timed(fn: Callable, args: tuple) -> tuple[Any, float, float | None]:
    """(value, wall seconds, the process's peak resident memory in GB after the task)."""
    t0 = time.perf_counter()
    value = fn(*args)
    return value, time.perf_counter() - t0, _peak_memory_gb()


def _peak_memory_gb() -> float | None:
    try:
        import resource
    except ImportError:  # not a Unix
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # kB on Linux, bytes on macOS
    return peak / (1e9 if sys.platform == "darwin" else 1e6)


def _one_line(err: BaseException) -> str:
    text = f"{type(err).__name__}: {err}".strip().splitlines()
    return text[0] if text else type(err).__name__


def distributed_available() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


class _Progress:
    """done / failed / time left, on stderr (tqdm), plus one line per finished task."""

    def __init__(self, total: int, label: str, show: bool, describe: Callable[[Outcome], str] | None):
        from tqdm import tqdm

        self._bar = tqdm(total=total, desc=label, unit="run", file=sys.stderr, disable=not show, dynamic_ncols=True)
        self._failed = 0
        self._describe = describe
        self._show = show

    def retrying(self, key: Hashable, error: str) -> None:
        if self._show:
            self._bar.write(f"retrying {key}: {error}", file=sys.stderr)

    def finished(self, outcome: Outcome) -> None:
        self._failed += not outcome.ok
        self._bar.set_postfix(failed=self._failed, refresh=False)
        self._bar.update(1)
        if self._show:
            if not outcome.ok:
                line = f"{outcome.key}: failed after {outcome.attempts} attempts: {outcome.error}"
            else:
                line = self._describe(outcome) if self._describe else f"{outcome.key}: done"
            self._bar.write(line, file=sys.stderr)

    def close(self) -> None:
        self._bar.close()


def run_tasks(fn: Callable, tasks: Sequence[tuple[Hashable, tuple]], *, workers: int = 2, address: str | None = None,
              label: str = "runs", progress: bool = True,
              describe: Callable[[Outcome], str] | None = None, runs_per_worker: int = 0) -> EngineReport:
    """Run `fn(*args)` for each `(key, args)` of `tasks` (module docstring); outcomes in task order.

    `fn` must be a function of an importable module (workers import it by name).
    """
    if not tasks:
        return EngineReport("nothing to run", 0, 0.0, [])
    keys = [k for k, _ in tasks]
    if len(set(keys)) != len(keys):
        raise ValueError("run_tasks: task keys must be unique")
    if runs_per_worker < 0:
        raise ValueError("run_tasks: runs_per_worker must be 0 (no restarts) or more")
    t0 = time.perf_counter()
    bar = _Progress(len(tasks), label, progress, describe)
    try:
        if address is None and workers > 0 and not distributed_available():
            print("note: the distributed extra is not installed; running in this process "
                  "(pip install -e \".[distributed]\" for a local or remote Dask cluster)", file=sys.stderr)
            workers = 0
        if address is None and workers == 0:
            outcomes = _run_here(fn, tasks, bar)
            engine, n_workers = "in-process", 1
        else:
            outcomes, n_workers = _run_dask(fn, tasks, bar, workers, address, runs_per_worker)
            engine = f"dask ({address})" if address else f"dask local cluster"
    finally:
        bar.close()
    return EngineReport(engine, n_workers, time.perf_counter() - t0, outcomes)


def _run_here(fn: Callable, tasks, bar: _Progress) -> list[Outcome]:
    outcomes = []
    for key, args in tasks:
        outcome = Outcome(key)
        for attempt in range(1, RETRIES + 2):
            outcome.attempts = attempt
            t0 = time.perf_counter()
            try:
                outcome.value, outcome.seconds, outcome.peak_memory_gb = _timed(fn, tuple(args))
                outcome.error = None
                break
            except Exception as err:  # reported, retried once
                outcome.error, outcome.seconds = _one_line(err), time.perf_counter() - t0
                if attempt <= RETRIES:
                    bar.retrying(key, outcome.error)
        bar.finished(outcome)
        outcomes.append(outcome)
    return outcomes


def _run_dask_batch(client, fn: Callable, tasks, outcomes: dict, index: dict, bar: _Progress) -> None:
    from distributed import as_completed

    args_of = dict(tasks)
    # pure=False: a retry is a new task, not the cached failure.
    futures = {client.submit(_timed, fn, tuple(args), key=f"run-{index[key]}-a1", pure=False): (key, 1)
               for key, args in tasks}
    pending = as_completed(list(futures))
    for future in pending:
        key, attempt = futures.pop(future)
        outcome = outcomes[key]
        outcome.attempts = attempt
        try:
            outcome.value, outcome.seconds, outcome.peak_memory_gb = future.result()
            outcome.error = None
        except Exception as err:
            outcome.error = _one_line(err)
            if attempt <= RETRIES:
                bar.retrying(key, outcome.error)
                retry = client.submit(_timed, fn, tuple(args_of[key]), key=f"run-{index[key]}-a{attempt + 1}",
                                      pure=False)
                futures[retry] = (key, attempt + 1)
                pending.add(retry)
                continue
        bar.finished(outcome)


def _run_dask(fn: Callable, tasks, bar: _Progress, workers: int, address: str | None,
              runs_per_worker: int = 0) -> tuple[list[Outcome], int]:
    import logging

    from distributed import Client, LocalCluster

    # The cluster's own chatter (ports, nanny restarts) would bury the progress lines.
    for name in ("distributed", "distributed.nanny", "distributed.scheduler", "distributed.worker"):
        logging.getLogger(name).setLevel(logging.ERROR)
    cluster = None
    if address is None:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    else:
        client = Client(address)
    try:
        n_workers = max(len(client.scheduler_info().get("workers", {})), 1)
        outcomes = {key: Outcome(key) for key, _ in tasks}
        index = {key: i for i, (key, _) in enumerate(tasks)}
        size = runs_per_worker * n_workers if runs_per_worker > 0 else len(tasks)
        for start in range(0, len(tasks), size):
            if start > 0:  # fresh worker processes: what the last batch's runs left in memory goes
                client.restart(wait_for_workers=True)
            _run_dask_batch(client, fn, tasks[start:start + size], outcomes, index, bar)
        return [outcomes[key] for key, _ in tasks], n_workers
    finally:
        client.close()
        if cluster is not None:
            cluster.close()

