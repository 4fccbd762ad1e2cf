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
