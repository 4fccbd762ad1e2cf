"""Execution back-ends for many independent runs (Monte Carlo, batch) behind one small interface.

An :class:`Executor` maps a picklable top-level function over a list of argument tuples and
returns one :class:`Outcome` per task, in task order::

    with make_executor(workers=2) as ex:
        outcomes = ex.run(fn, [(job, seed) for seed in seeds], progress=True, desc="runs")

Back-ends:

- :class:`InProcess` runs the tasks one after the other in this process (debugging, profiling,
  and the reference the parallel back-ends must reproduce bit for bit);
- :class:`LocalPool` is a ``concurrent.futures.ProcessPoolExecutor`` with the ``spawn`` start
  method (safe with numba, threads and macOS/Windows; the workers import insgnss afresh);
- :class:`DaskCluster` submits to Dask distributed: ``dask.distributed.Client(address)`` for an
  existing scheduler, or a ``LocalCluster`` of ``n_workers`` single-threaded workers that it
  starts and stops itself. Dask is an optional extra (``pip install insgnss[dask]``).

Failure policy: a task that raises is caught *inside* the worker (:func:`call_guarded`) and comes
back as an :class:`Outcome` with a :class:`TaskError` (exception type, message, traceback and the
task's ``label``, e.g. its seed); the other tasks go on. A worker that dies (killed, out of
memory) fails only the tasks it held (reported the same way). Ctrl-C cancels what has not
started. A ``tqdm`` bar counts finished tasks.

Work units must be self-contained: the function is pickled by reference (module and name), the
arguments by value, so the workers need the same insgnss version and any files the arguments
name (docs/montecarlo.md).
"""

from __future__ import annotations

import os
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["DaskCluster", "Executor", "InProcess", "LocalPool", "Outcome", "TaskError",
           "call_guarded", "make_executor"]


@dataclass
class TaskError:
    """Why a task failed: exception type and message, formatted traceback."""

    type: str
    message: str
    traceback: str = ""

    def __str__(self) -> str:
        return f"{self.type}: {self.message}"


@dataclass
class Outcome:
    """Result of one task: ``value`` or ``error``; ``label`` identifies it in reports (a seed,
    a job file); ``elapsed`` and ``cpu`` are the wall and CPU (process) time of the call in the
    worker [s]; ``worker`` names the worker process (``host:pid``)."""

    index: int
    label: Any = None
    value: Any = None
    error: TaskError | None = None
    elapsed: float = 0.0
    worker: str = ""
    cpu: float = 0.0

    @property
    def ok(self) -> bool:
        return self.error is None


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity on Linux, else ``os.cpu_count``)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _worker_name() -> str:
    import socket

    return f"{socket.gethostname()}:{os.getpid()}"


def call_guarded(fn: Callable, index: int, label: Any, args: tuple) -> Outcome:
    """Call ``fn(*args)`` and wrap the value, or the exception, in an :class:`Outcome`.

    Runs in the worker, so an exception never reaches the scheduler (which could retry it or
    cancel the batch); ``KeyboardInterrupt``/``SystemExit`` still propagate.
    """
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        value = fn(*args)
    except Exception as exc:  # noqa: BLE001 - any failure of one run is reported, not raised
        return Outcome(index, label, None,
                       TaskError(type(exc).__name__, str(exc), traceback.format_exc()),
                       time.perf_counter() - t0, _worker_name(), time.process_time() - c0)
    return Outcome(index, label, value, None, time.perf_counter() - t0, _worker_name(),
                   time.process_time() - c0)


def _lost(index: int, label: Any, exc: BaseException) -> Outcome:
    """Outcome of a task whose worker failed outside :func:`call_guarded` (died, lost)."""
    return Outcome(index, label, None, TaskError(type(exc).__name__, str(exc) or repr(exc),
                                                 "".join(traceback.format_exception(exc))))


def _bar(total: int, progress: bool, desc: str):
    from tqdm.auto import tqdm

    return tqdm(total=total, disable=not progress, desc=desc, unit="run", smoothing=0.1)


class Executor:
    """Interface: ``run(fn, tasks, labels=None, progress=False, desc="") -> list[Outcome]``.

    ``tasks`` is a sequence of argument tuples for ``fn`` (a module-level function, so that it
    pickles by reference); ``labels`` (same length) name the tasks in failure reports.
    Executors are context managers; ``close()`` releases workers and clusters.
    """

    name = "executor"
    workers = 1

    def run(self, fn: Callable, tasks: Sequence[tuple], *, labels: Sequence | None = None,
            progress: bool = False, desc: str = "") -> list[Outcome]:
        labels = list(labels) if labels is not None else list(range(len(tasks)))
        if len(labels) != len(tasks):
            raise ValueError("labels and tasks differ in length")
        out: list[Outcome | None] = [None] * len(tasks)
        with _bar(len(tasks), progress, desc or self.name) as bar:
            for o in self._iter(fn, list(tasks), labels):
                out[o.index] = o
                bar.update(1)
                if not o.ok:
                    bar.write(f"task {o.index} ({o.label}) failed: {o.error}")
        return out  # type: ignore[return-value]

    def _iter(self, fn, tasks, labels) -> Iterable[Outcome]:  # pragma: no cover - abstract
        raise NotImplementedError

    def describe(self) -> dict:
        """JSON-ready description (recorded in summaries)."""
        return {"backend": self.name, "workers": self.workers}

    def close(self) -> None:
        """Release resources (pools, clusters)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


class InProcess(Executor):
    """Run every task here, in order (the reference back-end)."""

    name = "in-process"

    def _iter(self, fn, tasks, labels):
        for i, (args, lab) in enumerate(zip(tasks, labels, strict=True)):
            yield call_guarded(fn, i, lab, args)


class LocalPool(Executor):
    """A local process pool (``concurrent.futures``, spawn start method) of ``workers``
    processes."""

    name = "local-pool"

    def __init__(self, workers: int | None = None, start_method: str = "spawn"):
        import multiprocessing as mp

        self.workers = int(workers or os.cpu_count() or 1)
        if self.workers < 1:
            raise ValueError("workers must be at least 1")
        self._ctx = mp.get_context(start_method)
        self._pool = None

    def _get_pool(self):
        from concurrent.futures import ProcessPoolExecutor

        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=self._ctx)
        return self._pool

    def _iter(self, fn, tasks, labels):
        from concurrent.futures import as_completed

        pool = self._get_pool()
        futs = {pool.submit(call_guarded, fn, i, lab, args): (i, lab)
                for i, (args, lab) in enumerate(zip(tasks, labels, strict=True))}
        try:
            for f in as_completed(futs):
                i, lab = futs[f]
                try:
                    yield f.result()
                except Exception as exc:  # noqa: BLE001 - worker died: BrokenProcessPool etc.
                    yield _lost(i, lab, exc)
                    if self._pool is not None and getattr(self._pool, "_broken", False):
                        self._pool.shutdown(wait=False, cancel_futures=True)
                        self._pool = None  # a fresh pool for the next run() call
        except BaseException:
            for f in futs:
                f.cancel()
            raise

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


class DaskCluster(Executor):
    """Dask distributed: an existing scheduler (``address``, e.g. ``tcp://10.0.0.5:8786``) or a
    ``LocalCluster`` of ``n_workers`` single-threaded workers started here.

    ``processes=False`` runs the local workers as threads of this process (fast start, but the
    runs then share one interpreter lock); ``processes=True`` starts worker processes.
    ``client`` may be an existing ``dask.distributed.Client`` (not closed by :meth:`close`).
    """

    name = "dask"

    def __init__(self, address: str | None = None, *, n_workers: int | None = None,
                 processes: bool = True, client=None, **cluster_kwargs):
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:  # pragma: no cover - depends on the environment
            from .errors import ConfigError

            raise ConfigError("the Dask back-end needs dask.distributed: "
                              "pip install 'insgnss[dask]'") from None
        self._own_client = client is None
        self._cluster = None
        if client is not None:
            self.client = client
        elif address:
            self.client = Client(address)
        else:
            n = int(n_workers or os.cpu_count() or 1)
            kw = {"n_workers": n, "threads_per_worker": 1, "processes": processes,
                  "dashboard_address": None}
            kw.update(cluster_kwargs)
            self._cluster = LocalCluster(**kw)
            self.client = Client(self._cluster)
        self.address = self.client.scheduler.address
        self.workers = max(len(self.client.scheduler_info().get("workers", {})), 1)

    def describe(self) -> dict:
        return {"backend": self.name, "workers": self.workers, "scheduler": self.address,
                "local_cluster": self._cluster is not None}

    def _iter(self, fn, tasks, labels):
        from dask.distributed import as_completed

        futs = self.client.map(call_guarded, [fn] * len(tasks), range(len(tasks)), labels,
                               tasks, pure=False, retries=0)
        where = {f.key: i for i, f in enumerate(futs)}
        try:
            for f in as_completed(futs):
                i = where[f.key]
                try:
                    yield f.result()
                except Exception as exc:  # noqa: BLE001 - KilledWorker, lost data, ...
                    yield _lost(i, labels[i], exc)
                f.release()
        except BaseException:
            self.client.cancel(futs)
            raise

    def close(self) -> None:
        if self._own_client:
            self.client.close()
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None


def make_executor(workers: int | None = None, scheduler: str | None = None,
                  local_cluster: int | None = None, processes: bool = True) -> Executor:
    """The back-end the CLI options ask for: ``scheduler`` (a Dask scheduler address), else
    ``local_cluster`` (a Dask LocalCluster of that many workers), else ``workers`` > 1 (a local
    process pool), else in-process."""
    given = [x is not None for x in (workers, scheduler, local_cluster)]
    if sum(given) > 1:
        raise ValueError("give at most one of workers, scheduler and local_cluster")
    if scheduler:
        return DaskCluster(scheduler)
    if local_cluster:
        return DaskCluster(n_workers=local_cluster, processes=processes)
    if workers is not None and workers > 1:
        return LocalPool(workers)
    return InProcess()
