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
