"""The smoother's node store beyond its memory limit: memory-mapped arrays
(:class:`insgnss.io.spill.SpillAllocator`) give the same filter and smoother results as the
store in memory, on the Python path and on the compiled high-rate path."""

from __future__ import annotations

import gc
import os

import numpy as np
import pandas as pd
import pytest
from filter_sim import car_truth, corrupt_imu, gnss_from_truth, perturbed_initial

from insgnss.filter import FilterConfig, GnssPosition, Zaru, Zupt, run_filter
from insgnss.imu import grade
from insgnss.io.spill import SPILL_PREFIX, SpillAllocator


def _mapped(a) -> bool:
    """Whether ``a`` views a memory-mapped file."""
    while a is not None:
        if isinstance(a, np.memmap):
            return True
        a = a.base
    return False


def test_allocator_keeps_the_limit_of_live_arrays_and_leaves_no_file(tmp_path):
    alloc = SpillAllocator(1000.0, tmp_path)
    a = alloc((100,), float)  # 800 bytes: in memory
    assert not _mapped(a) and alloc.in_memory == 800
    b = alloc((10, 3), float)  # 240 more: over the limit, mapped
    assert alloc.spilled == 240 and alloc.in_memory == 800
    assert _mapped(b) and type(b) is np.ndarray
    b[:] = np.arange(30.0).reshape(10, 3)
    assert b.sum() == 435.0
    if os.name == "posix":  # unlinked at once: nothing in the folder
        assert not list(tmp_path.glob(f"{SPILL_PREFIX}*"))
    del a
    gc.collect()
    assert alloc.in_memory == 0  # released arrays no longer count
    c = alloc((100,), float)
    assert not _mapped(c)
    assert alloc((0, 15), float).shape == (0, 15)  # empty: in memory, never mapped


def test_allocator_without_its_folder_uses_the_temporary_folder(tmp_path):
    alloc = SpillAllocator(0.0, tmp_path / "missing")
    a = alloc((4, 4), np.int64)
    a[:] = 7
    assert a.sum() == 112 and alloc.spilled == 128
    assert not (tmp_path / "missing").exists()  # nothing created


@pytest.mark.parametrize("high_rate", [False, True])
def test_spilled_store_gives_the_same_results(tmp_path, high_rate):
    truth = car_truth(120.0, 60.0, stops_after=(0,), stop_duration=10.0)
    rng = np.random.default_rng(3)
    imu, _ = corrupt_imu(truth, grade("tactical"), rng)
    gnss = gnss_from_truth(truth, rng)
    gnss = gnss[(gnss.index < 50.0) | (gnss.index > 70.0)]
    init, _ = perturbed_initial(truth, rng, 1.0, 0.1, (0.005, 0.005, 0.02))
    t = imu.index.to_numpy()
    ts = t[truth["stationary"].to_numpy(bool)][1:]

    def run(allocate):
        meas = [GnssPosition(gnss), Zupt(ts, std=0.01, high_rate=high_rate),
                Zaru(ts, std=1e-4, average=False, high_rate=high_rate)]
        cfg = FilterConfig(imu_model="tactical", initial_att_std=(0.005, 0.005, 0.02),
                           store_allocate=allocate)
        return run_filter(imu, init, meas, cfg)

    mem = run(None)
    alloc = SpillAllocator(0.0, tmp_path)  # every store array mapped
    mapped = run(alloc)
    assert alloc.spilled > mem.P_filtered.nbytes
    assert _mapped(mapped.P_filtered) and not _mapped(mem.P_filtered)
    if high_rate:
        assert mapped.high_rate is not None and mapped.high_rate["t"].size > 500
    pd.testing.assert_frame_equal(mem.forward, mapped.forward, check_exact=True)
    pd.testing.assert_frame_equal(mem.smoothed, mapped.smoothed, check_exact=True)
    np.testing.assert_array_equal(mem.P_smoothed, mapped.P_smoothed)
    pd.testing.assert_frame_equal(mem.innovations, mapped.innovations, check_exact=True)
    # the IMU-rate tables come from the same allocator: mapped too, same numbers
    assert _mapped(mapped.forward_array) and _mapped(mapped.smoothed_array)
    assert not _mapped(mem.forward_array)


def _resident_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2.0**20


@pytest.mark.skipif(not os.path.exists("/proc/self/statm"), reason="needs /proc (Linux)")
def test_release_gives_back_the_pages_and_keeps_the_contents(tmp_path):
    from insgnss.io.spill import blocks, is_mapped, release

    alloc = SpillAllocator(0.0, tmp_path)
    a = alloc((200_000, 40), float)  # 61 MiB, mapped
    assert is_mapped(a) and is_mapped(a[10:20, 3]) and not is_mapped(np.ones(3))
    before = _resident_mib()
    a[:] = np.arange(40.0)
    a[:, 0] = np.arange(200_000.0)
    grown = _resident_mib()
    assert grown - before > 50  # written pages are resident
    release(a, 0, 100_000)
    half = _resident_mib()
    assert 20 < grown - half < 40  # about half of them given back
    release(a[:, 5])  # a column view: the pages of all its rows
    assert _resident_mib() - before < 5
    assert a[123_456, 0] == 123_456.0 and a[7, 39] == 39.0  # read back from the file
    assert a[:, 0].sum() == 200_000 * 199_999 / 2
    release(np.ones((10, 3)))  # in memory: nothing happens
    assert list(blocks(10, 8, 24)) == [(0, 3), (3, 6), (6, 9), (9, 10)]
    assert list(blocks(0, 8)) == []
    # the blocks holding rows start .. stop-1 only, with the bounds of all of them
    assert list(blocks(10, 8, 24, start=4, stop=7)) == [(3, 6), (6, 9)]
    assert list(blocks(10, 8, 24, start=9, stop=50)) == [(9, 10)]
    assert list(blocks(10, 8, 24, start=5, stop=5)) == []


def test_table_take_reads_rows_and_columns_in_blocks(tmp_path, monkeypatch):
    from insgnss.filter.store import Table
    from insgnss.io import spill

    monkeypatch.setattr(spill, "BLOCK_BYTES", 1000)  # many blocks
    alloc = SpillAllocator(0.0, tmp_path)
    v = alloc((1000, 4), float)
    v[:] = np.arange(4000.0).reshape(1000, 4)
    tab = Table(np.arange(1000) * 0.01, v, ["a", "b", "c", "d"])
    rows = np.array([0, 31, 32, 500, 999])
    part = tab.take(rows, ["d", "b"])
    assert list(part.columns) == ["b", "d"]  # the table's order
    np.testing.assert_array_equal(part.to_numpy(), v[rows][:, [1, 3]])
    np.testing.assert_array_equal(part.index.to_numpy(), rows * 0.01)
    pd.testing.assert_frame_equal(tab.take(), tab.frame(), check_exact=True)
    assert len(tab) == 1000
    # a few rows of a long table visit (and give back) the blocks they lie in, not every one
    seen = []
    monkeypatch.setattr(spill, "release", lambda a, i=0, j=None: seen.append((i, j)))
    np.testing.assert_array_equal(tab.take(np.arange(500, 520), ["a"]).to_numpy()[:, 0],
                                  v[500:520, 0])
    assert 1 <= len(seen) <= 2 and seen[0][0] <= 500 and seen[-1][1] >= 520
    assert tab.take(np.array([], np.int64)).shape == (0, 4)


@pytest.mark.parametrize("high_rate", [False, True])
def test_smoothed_table_formed_at_the_rows_read_is_the_whole_table(monkeypatch, high_rate):
    """The smoothed IMU-rate table (:class:`insgnss.filter.store.AssembledTable`) formed only
    at the rows and columns read - contiguous, scattered, across block ends, the compiled
    high-rate path's rows included - holds the values of the whole table formed at once."""
    from insgnss.filter.store import AssembledTable
    from insgnss.io import spill

    truth = car_truth(120.0, 60.0, stops_after=(0,), stop_duration=10.0)
    rng = np.random.default_rng(5)
    imu, _ = corrupt_imu(truth, grade("tactical"), rng)
    gnss = gnss_from_truth(truth, rng)
    init, _ = perturbed_initial(truth, rng, 1.0, 0.1, (0.005, 0.005, 0.02))
    ts = imu.index.to_numpy()[truth["stationary"].to_numpy(bool)][1:]
    res = run_filter(imu, init, [GnssPosition(gnss), Zupt(ts, std=0.01, high_rate=high_rate)],
                     FilterConfig(imu_model="tactical", initial_att_std=(0.005, 0.005, 0.02)))
    if high_rate:
        assert res.high_rate is not None and res.high_rate["t"].size > 500
    tab = res.smoothed_table
    assert isinstance(tab, AssembledTable) and tab._values is None
    monkeypatch.setattr(spill, "BLOCK_BYTES", 3000)  # blocks of 8 rows or so
    n = len(tab)
    rows = np.unique(np.concatenate([np.arange(0, n, 37), np.arange(500, 700), [n - 1]]))
    cols = [tab.columns[k] for k in (0, 2, 5, 9, len(tab.columns) - 1)]
    part = tab.take(rows, cols)
    position_parts = [(pos, tab.take(rows, pos)) for pos in (
        ["lat", "lon", "height", "east_std", "north_std", "up_std"], ["lon", "up_std"])]
    whole_rows = tab.take()
    assert tab._values is None  # nothing above formed the whole table
    whole = tab.values  # the whole table at once (what a DataFrame of it holds)
    np.testing.assert_array_equal(whole_rows.to_numpy(), whole)
    np.testing.assert_array_equal(part.to_numpy(), whole[np.ix_(rows, [tab.columns.index(c)
                                                                      for c in cols])])
    np.testing.assert_array_equal(part.index.to_numpy(), tab.time[rows])
    # the evaluation's columns alone (the assembly forms only those): the same values
    for pos, got in position_parts:
        assert list(got.columns) == pos
        np.testing.assert_array_equal(got.to_numpy(), whole[np.ix_(rows, [tab.columns.index(c)
                                                                         for c in pos])])
    pd.testing.assert_frame_equal(res.smoothed, tab.take(), check_exact=True)
    assert np.isfinite(whole[:, :9]).all() and not np.array_equal(whole[:, :9],
                                                                   res.forward_array[:, :9])


def test_row_segments_give_back_the_rows_nodes_and_flags_exactly():
    """:class:`insgnss.filter.store.RowSegments`: node runs, high-rate runs (values falling by
    one per row), adjacent high-rate segments, a node right after a high-rate run with the
    same key, post flags at run ends; any rows, slices across block ends."""
    from insgnss.filter.store import RowSegments
    from insgnss.io import spill

    seg = np.array([0, 1, 1, 1, -1, -2, -3, 2, 2, -4, -5, -8, -9, 6, 6, 6, 7, -10, 7, 8],
                   np.int32)
    rng = np.random.default_rng(0)
    long = np.repeat(np.arange(200), rng.integers(1, 30, 200)).astype(np.int32)
    hr_at = rng.choice(long.size, 300, replace=False)
    long[np.sort(hr_at)] = -1 - np.arange(300)
    for s in (seg, long):
        post = rng.random(s.size) < 0.2
        for block in (spill.BLOCK_BYTES, 64):  # one block, and blocks of 4 rows
            with pytest.MonkeyPatch.context() as m:
                m.setattr(spill, "BLOCK_BYTES", block)
                rs = RowSegments(s, post, s.size)
            got_s, got_p = rs.rows(slice(0, s.size))
            assert got_s.dtype == s.dtype
            np.testing.assert_array_equal(got_s, s)
            np.testing.assert_array_equal(got_p, post)
            rows = np.sort(rng.choice(s.size, s.size // 3, replace=False))
            np.testing.assert_array_equal(rs.rows(rows)[0], s[rows])
            np.testing.assert_array_equal(rs.rows(rows)[1], post[rows])
            assert rs.starts.size < s.size  # runs, not rows
            for i in range(0, s.size - 1, 3):  # the extremes of any block lie on its edges
                j = min(s.size, i + 1 + int(rng.integers(1, 40)))
                e = rs.rows(rs.edges(i, j))[0]
                for part in (lambda v: v[v >= 0], lambda v: v[v < 0]):
                    whole = part(s[i:j])
                    assert (whole.size == 0) == (part(e).size == 0)
                    if whole.size:
                        assert (part(e).min(), part(e).max()) == (whole.min(), whole.max())
        assert RowSegments(s, np.zeros(s.size, bool), s.size).rows(slice(3, 9))[1].sum() == 0
