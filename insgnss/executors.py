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

__all__ = ["DaskCluster", "Executor", "ForkedHelpers", "InProcess", "LocalPool", "Outcome",
           "TaskError", "call_guarded", "call_pooled", "fork_map", "fork_workers",
           "make_executor", "usable_cores"]


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


#: whether :func:`fork_map` may fork helpers in this process (not in a pool's or a cluster's
#: worker: the pool already runs a task per core)
_HELPERS = True


def call_pooled(fn: Callable, index: int, label: Any, args: tuple) -> Outcome:
    """:func:`call_guarded` in a worker of a pool or cluster (:class:`LocalPool`,
    :class:`DaskCluster`): the task forks no helpers of its own (:func:`fork_workers`)."""
    global _HELPERS
    _HELPERS = False
    return call_guarded(fn, index, label, args)


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
        futs = {pool.submit(call_pooled, fn, i, lab, args): (i, lab)
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

        futs = self.client.map(call_pooled, [fn] * len(tasks), range(len(tasks)), labels,
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


# --- forked helpers for work that cannot be pickled ----------------------------------------------

def fork_workers(n_items: int, limit: int = 3) -> int:
    """Helpers :func:`fork_map` forks for ``n_items`` items: one per further usable core (at
    most ``limit`` and ``n_items - 1``); none without ``fork``, in a task of a pool or cluster
    of this module (:func:`call_pooled`: it already runs a task per core) or in a daemonic
    process (a ``multiprocessing.Pool`` worker, which may not have children)."""
    import multiprocessing

    if n_items < 2 or not _HELPERS or "fork" not in multiprocessing.get_all_start_methods() \
            or multiprocessing.current_process().daemon:
        return 0
    return max(0, min(usable_cores() - 1, limit, n_items - 1))


def _take(fn, items, order, nxt) -> dict:
    """``{index: fn(item)}`` of the items of ``order`` taken from the shared counter ``nxt``
    until none is left; an item whose call raised is left out (the caller computes it)."""
    out = {}
    while True:
        with nxt.get_lock():
            k = nxt.value
            nxt.value += 1
        if k >= len(order):
            return out
        i = order[k]
        try:
            out[i] = fn(items[i])
        except Exception:  # noqa: BLE001,S112 - raised again by the caller, in its process
            continue


def _fork_helper(conn, fn, items, order, nxt) -> None:
    try:
        conn.send(_take(fn, items, order, nxt))
    except KeyboardInterrupt:  # Ctrl-C reaches the whole group: the caller reports it
        pass
    finally:
        conn.close()


def fork_map(fn: Callable[[Any], Any], items: Sequence, workers: int | None = None, *,
             order: Sequence[int] | None = None,
             meanwhile: Callable[[], None] | None = None) -> list:
    """``[fn(x) for x in items]``, computed by this process and ``workers`` helper processes
    forked for the call (default :func:`fork_workers`).

    For work whose function or data cannot be pickled (a closure over a job's inputs, a
    figure's description): the helpers inherit ``fn`` and ``items`` when they are forked, and
    only their results come back (pickled, all of a helper's at its end). Every process takes
    the next item of ``order`` (default: the items' order; put the costliest first) from one
    shared counter, so that none waits while another still has several items. ``meanwhile()``
    runs here once the helpers have started, before this process takes items.

    The values are those of the serial loop: an item whose call raised, or that a helper took
    and did not return (it died), is computed again here, in the items' order, so that the
    first failing item raises its exception in this process with its own traceback. Without
    helpers it is the serial loop over ``order`` (after ``meanwhile()``).
    """
    import multiprocessing

    items = list(items)
    order = list(range(len(items))) if order is None else list(order)
    workers = fork_workers(len(items)) if workers is None else int(workers)
    results: dict = {}
    if workers > 0 and "fork" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("fork")
        nxt = ctx.Value("q", 0)
        helpers, done = [], False
        try:
            for _ in range(workers):
                here, there = ctx.Pipe(duplex=False)
                proc = ctx.Process(target=_fork_helper, args=(there, fn, items, order, nxt),
                                   daemon=True)
                proc.start()
                there.close()
                helpers.append((proc, here))
            if meanwhile is not None:
                meanwhile()
            results = _take(fn, items, order, nxt)
            for _, conn in helpers:
                try:
                    results.update(conn.recv())
                except (EOFError, OSError):  # it died: what it held is computed below
                    pass
            done = True
        finally:
            for proc, conn in helpers:
                conn.close()
                if not done:  # an error or Ctrl-C here: the helpers' work is not wanted
                    proc.terminate()
                proc.join()
    else:
        if meanwhile is not None:
            meanwhile()
        for i in order:
            results[i] = fn(items[i])
    return [results[i] if i in results else fn(items[i]) for i in range(len(items))]


def _serve(conn, fn) -> None:
    """A :class:`ForkedHelpers` process: ``{index: fn(item)}`` for each batch ``[(index, item),
    ...]`` received (an item whose call raised is left out: the caller computes it), until
    ``None`` or a closed connection."""
    try:
        while (batch := conn.recv()) is not None:
            out = {}
            for i, item in batch:
                try:
                    out[i] = fn(item)
                except Exception:  # noqa: BLE001,S112 - raised again by the caller, in its process
                    continue
            conn.send(out)
    except (EOFError, OSError, KeyboardInterrupt):  # the caller went (or Ctrl-C: it reports it)
        pass
    finally:
        conn.close()


def _end(proc, wait: float) -> None:
    """Wait ``wait`` seconds for a helper process to exit, then terminate it."""
    proc.join(wait)
    if proc.is_alive():
        proc.terminate()
        proc.join()


class ForkedHelpers:
    """:func:`fork_map` for many small batches of one function: helper processes forked once,
    at the first batch of two or more items, that compute ``fn(item)`` for every later
    :meth:`map` until :meth:`close` (or the end of a ``with`` block).

    Forking for each batch copies the page tables of a large process and makes both processes
    copy every page either of them then writes (copy-on-write faults): on the real drive's
    self-tuning a pair of filter runs took 0.55-0.77 s forked for the pair, against 0.42 s for
    one run. Helpers forked once pay that once. ``fn`` and what it reads are inherited at the
    fork (so must not change after it: the self-tuning's filter run for a parameter set);
    the items and the results are pickled.

    The values are those of the serial loop, as with :func:`fork_map`: an item whose call
    raised in a helper, or that a helper which died held, is computed again here (a dead
    helper is not replaced), so that the first failing item raises in this process."""

    def __init__(self, fn: Callable[[Any], Any], workers: int | None = None):
        self.fn = fn
        self._workers = workers
        self._helpers: list | None = None  # [(process, connection)] once forked

    def _start(self) -> list:
        import multiprocessing

        if self._helpers is None:
            n = fork_workers(4) if self._workers is None else int(self._workers)
            self._helpers = []
            if n > 0 and "fork" in multiprocessing.get_all_start_methods():
                ctx = multiprocessing.get_context("fork")
                for _ in range(n):
                    here, there = ctx.Pipe()
                    proc = ctx.Process(target=_serve, args=(there, self.fn), daemon=True)
                    proc.start()
                    there.close()
                    self._helpers.append((proc, here))
        return self._helpers

    def map(self, items: Sequence) -> list:
        """``[fn(x) for x in items]``: the items dealt in turn to this process and the helpers
        (equal shares: items of about equal cost)."""
        items = list(items)
        helpers = self._start() if len(items) > 1 else []
        k = len(helpers) + 1
        results: dict = {}
        sent = []
        for h, (proc, conn) in enumerate(helpers):
            share = [(i, items[i]) for i in range(h + 1, len(items), k)]
            if not share:
                break
            try:
                conn.send(share)
                sent.append((proc, conn))
            except (OSError, ValueError):  # it died: its share is computed below
                self._drop(proc, conn)
        for i in range(0, len(items), k):
            results[i] = self.fn(items[i])
        for proc, conn in sent:
            try:
                results.update(conn.recv())
            except (EOFError, OSError):  # it died: what it held is computed below
                self._drop(proc, conn)
        return [results[i] if i in results else self.fn(items[i]) for i in range(len(items))]

    def _drop(self, proc, conn) -> None:
        conn.close()
        _end(proc, 0.1)
        self._helpers = [h for h in self._helpers if h[0] is not proc]

    def close(self) -> None:
        """End the helpers (they exit on the closed connection; terminated after a second)."""
        helpers, self._helpers = self._helpers or [], None
        for _, conn in helpers:
            try:
                conn.send(None)
            except (OSError, ValueError):
                pass
            conn.close()
        for proc, _ in helpers:
            _end(proc, 1.0)

    def __enter__(self) -> ForkedHelpers:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


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
