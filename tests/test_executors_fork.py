"""insgnss.executors.fork_map: the values of the serial loop, whoever computes them."""

import multiprocessing
import os
import signal
import time

import pytest

from insgnss import executors
from insgnss.executors import fork_map, fork_workers

needs_fork = pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(),
                                reason="forked helpers need fork")


def _square_with_pid(x):
    time.sleep(0.01)
    return x * x, os.getpid()


@needs_fork
@pytest.mark.parametrize("workers", [0, 1, 2])
def test_values_in_the_items_order(workers):
    seen = []
    out = fork_map(_square_with_pid, range(12), workers, order=list(range(11, -1, -1)),
                   meanwhile=lambda: seen.append(os.getpid()))
    assert [v for v, _ in out] == [x * x for x in range(12)]
    assert seen == [os.getpid()]  # once, here
    pids = {p for _, p in out}
    assert os.getpid() in pids and len(pids) <= workers + 1
    if workers:  # the helpers took part (12 items of 10 ms each)
        assert len(pids) > 1


@needs_fork
def test_a_closure_is_not_pickled():
    data = {"offset": 3}

    def add(x):  # a closure over local data: forked, not pickled
        return x + data["offset"]

    assert fork_map(add, [1, 2, 3, 4], 1) == [4, 5, 6, 7]


class _Unpicklable(Exception):
    def __init__(self, item, *, why):  # keyword-only: does not unpickle from its args
        super().__init__(f"item {item}: {why}")


@needs_fork
def test_the_first_failing_item_raises_here():
    calls = []

    def fail_on_odd(x):
        calls.append(x)  # in this process only for the items computed here
        if x % 2:
            raise _Unpicklable(x, why="odd")
        time.sleep(0.01)
        return x

    with pytest.raises(_Unpicklable, match="item 1: odd"):
        fork_map(fail_on_odd, range(8), 1)
    assert 1 in calls  # raised by the call in this process, with its own traceback


@needs_fork
def test_a_helper_that_dies_is_made_up_for():
    parent = os.getpid()

    def die_in_helper(x):
        if os.getpid() != parent:
            os.kill(os.getpid(), signal.SIGKILL)
        time.sleep(0.01)
        return -x

    assert fork_map(die_in_helper, range(6), 1) == [0, -1, -2, -3, -4, -5]


def test_helpers_follow_the_cores(monkeypatch):
    monkeypatch.setattr(executors, "usable_cores", lambda: 4)
    if "fork" not in multiprocessing.get_all_start_methods():
        assert fork_workers(10) == 0
        return
    assert fork_workers(10) == 3 and fork_workers(10, limit=1) == 1
    assert fork_workers(2) == 1 and fork_workers(1) == 0
    monkeypatch.setattr(executors, "usable_cores", lambda: 1)
    assert fork_workers(10) == 0


def _helpers_in_task(n):
    return fork_workers(n)


def test_no_helpers_inside_a_pool_task(monkeypatch):
    """A task of a process pool runs on a core of its own: it forks no helpers."""
    from insgnss.executors import LocalPool

    monkeypatch.setattr(executors, "_HELPERS", True)
    with LocalPool(1) as pool:
        (o,) = pool.run(_helpers_in_task, [(10,)])
    assert o.ok and o.value == 0
    assert executors._HELPERS  # this process still may


@needs_fork
def test_forked_helpers_serve_many_batches_with_the_serial_values():
    """:class:`insgnss.executors.ForkedHelpers`: helpers forked once (the same processes for
    every batch), the values of the serial loop in the items' order, one item alone computed
    here; after close the helpers are gone."""
    data = {"offset": 3}

    def add(x):  # a closure over local data: inherited at the fork, not pickled
        time.sleep(0.01)
        return x + data["offset"], os.getpid()

    with executors.ForkedHelpers(add, workers=2) as helpers:
        batches = [helpers.map(range(k, k + 7)) for k in (0, 10, 20)]
        procs = [p for p, _ in helpers._helpers]
        assert helpers.map([5]) == [(8, os.getpid())]
    for k, out in zip((0, 10, 20), batches, strict=True):
        assert [v for v, _ in out] == [x + 3 for x in range(k, k + 7)]
    pids = [{p for _, p in out} for out in batches]
    assert pids[0] == pids[1] == pids[2] and len(pids[0]) == 3 and os.getpid() in pids[0]
    assert len(procs) == 2 and not any(p.is_alive() for p in procs)


@needs_fork
def test_forked_helpers_raise_here_and_make_up_for_a_dead_helper():
    parent = os.getpid()

    def fail_on_odd(x):
        if x % 2:
            raise _Unpicklable(x, why="odd")
        return x

    with executors.ForkedHelpers(fail_on_odd, workers=1) as helpers:
        assert helpers.map([0, 2, 4, 6]) == [0, 2, 4, 6]
        with pytest.raises(_Unpicklable, match="item 1: odd"):
            helpers.map([0, 1, 2, 3])  # item 1 went to the helper: raised again here

    def die_in_helper(x):
        if os.getpid() != parent:
            os.kill(os.getpid(), signal.SIGKILL)
        return -x

    with executors.ForkedHelpers(die_in_helper, workers=1) as helpers:
        assert helpers.map(range(6)) == [0, -1, -2, -3, -4, -5]
        assert helpers._helpers == []  # not replaced: the next batches run here
        assert helpers.map(range(3)) == [0, -1, -2]
