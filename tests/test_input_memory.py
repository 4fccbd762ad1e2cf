"""Memory layout of the inputs of a long log: the IMU triads held as (N, 3) arrays that the
filter uses without a copy, a reference on a memory-mapped file read and released in blocks,
and the block-wise helpers of the evaluation give the same numbers as the whole-array code."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import insgnss.outages as outages
from insgnss.errors import InvalidValueError
from insgnss.imu import increments, triad_blocks
from insgnss.io.spill import SpillAllocator, is_mapped, release_frame
from insgnss.io.tracks import read_trajectory_csv, write_trajectory_csv
from insgnss.job.evaluation import position_nees
from insgnss.validate import check_finite


def _reader_table(n: int = 500, extra: bool = True) -> pd.DataFrame:
    """An increment table laid out as a reader makes it: one column-major block of all fields."""
    rng = np.random.default_rng(7)
    v = np.empty((8 if extra else 7, n)).T
    v[:] = rng.normal(size=v.shape)
    v[:, 0] = np.arange(n) * 0.005
    cols = ["dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z"] + (["pressure"] if extra else [])
    df = pd.DataFrame(v[:, 1:], index=pd.Index(v[:, 0], name="time"), columns=cols, copy=False)
    df.attrs["source"] = "imu.csv"
    return df


def test_triad_blocks_keep_the_table_and_give_the_increments_as_views():
    df = _reader_table()
    _, dth0, dv0 = increments(df)
    assert not dth0.flags["C_CONTIGUOUS"]  # the reader's layout: the model would copy
    out = triad_blocks(df)
    pd.testing.assert_frame_equal(out, df)
    assert out.attrs == df.attrs and list(out.columns) == list(df.columns)
    t, dth, dv = increments(out)
    assert dth.flags["C_CONTIGUOUS"] and dv.flags["C_CONTIGUOUS"]
    assert np.shares_memory(dth, out["dtheta_y"].to_numpy())
    assert np.shares_memory(dv, out["dv_z"].to_numpy())
    np.testing.assert_array_equal(dth, dth0)
    np.testing.assert_array_equal(dv, dv0)
    # slices of the processing window keep the layout (views, no copy)
    _, dth_w, _ = increments(out.loc[0.5:])
    assert dth_w.flags["C_CONTIGUOUS"] and np.shares_memory(dth_w, dth)
    assert dth_w.shape == (int(round((df.index[-1] - 0.5) / 0.005)) + 1, 3)


def test_check_finite_on_columns_finds_the_first_value_in_row_order():
    v = np.ones((10, 5))
    v[7, 1] = np.nan
    v[5, 3] = np.inf
    v[5, 4] = np.nan  # the same row, a later column
    v[2, 0] = np.nan  # not a checked column
    rows = np.arange(10) + 2
    with pytest.raises(InvalidValueError) as e:
        check_finite(v, ["b", "d", "e"], rows, "f.csv", columns=[1, 3, 4])
    assert e.value.row == 7 and e.value.column == "d" and "inf" in str(e.value)
    with pytest.raises(InvalidValueError) as e:  # the whole-array form: the same rule
        check_finite(v[:, [1, 3, 4]], ["b", "d", "e"], rows, "f.csv")
    assert e.value.row == 7 and e.value.column == "d"
    check_finite(v, ["b"], rows, "f.csv", columns=[2])  # a clean column passes


def _write_reference(path, n: int = 4000) -> pd.DataFrame:
    t = np.arange(n) * 0.005
    ref = pd.DataFrame(
        {
            "lat": 0.84 + 1e-7 * np.arange(n),
            "lon": 0.2 + 2e-7 * np.arange(n),
            "height": 500.0 + np.sin(t),
            "vel_e": np.cos(t),
            "heading": np.linspace(0.0, 3.0, n),
        },
        index=pd.Index(t, name="time"),
    )
    write_trajectory_csv(ref, path)
    return ref


def test_a_reference_on_a_mapped_file_reads_the_same_values(tmp_path):
    path = tmp_path / "truth.csv"
    _write_reference(path)
    mem = read_trajectory_csv(path)
    mapped = read_trajectory_csv(path, allocate=SpillAllocator(0, tmp_path))
    assert not is_mapped(mem["lat"].to_numpy())
    assert all(is_mapped(mapped[c].to_numpy()) for c in mapped.columns)
    pd.testing.assert_frame_equal(mapped, mem)
    release_frame(mapped, 100, 3000)  # pages go back, the contents stay
    release_frame(mapped)
    pd.testing.assert_frame_equal(mapped, mem)
    np.testing.assert_array_equal(mapped.attrs["source_rows"], mem.attrs["source_rows"])


def test_rows_of_a_mapped_reference_taken_in_blocks_equal_iloc(tmp_path, monkeypatch):
    """select_rows on a DataFrame on a mapped file takes its rows a block at a time (each
    block's pages given back): the same frame as ``iloc``, for rows spread over many blocks,
    rows inside one block, and a column subset."""
    import insgnss.io.spill as spill
    from insgnss.filter.store import select_rows

    path = tmp_path / "truth.csv"
    _write_reference(path)
    mem = read_trajectory_csv(path)
    mapped = read_trajectory_csv(path, allocate=SpillAllocator(0, tmp_path))
    monkeypatch.setattr(spill, "BLOCK_BYTES", 8 * mapped.shape[1] * 333)  # 333 rows a block
    for rows in (np.arange(0, len(mem), 7), np.array([5, 6, 300]), np.array([3999])):
        got = select_rows(mapped, lambda t, r=rows: r)
        pd.testing.assert_frame_equal(got, mem.iloc[rows])
        got = select_rows(mapped, lambda t, r=rows: r, ("lat", "heading"))
        pd.testing.assert_frame_equal(got, mem.iloc[rows][["lat", "heading"]])
    pd.testing.assert_frame_equal(select_rows(mapped, lambda t: None), mem)


def test_window_index_in_blocks_equals_the_whole_array(monkeypatch):
    t = np.arange(0.0, 100.0, 0.01)
    windows = [(10.0, 20.0), (30.005, 40.0), (55.0, 55.01), (90.0, 200.0)]
    whole = outages.window_index(t, windows)
    monkeypatch.setattr(outages, "_BLOCK", 777)
    blocked = outages.window_index(t, windows)
    np.testing.assert_array_equal(blocked, whole)
    assert (blocked == 0).sum() == 1000 and (blocked == 2).sum() == 1
    assert blocked[t.searchsorted(30.0)] == -1 and blocked[-1] == 3
    np.testing.assert_array_equal(outages.in_windows(t, windows), whole >= 0)


def test_position_nees_by_columns_equals_the_row_sum():
    rng = np.random.default_rng(3)
    n = 2000
    e = rng.normal(size=(n, 3))
    sd = rng.uniform(0.5, 2.0, size=(n, 3))
    sd[5, 1] = 0.0  # not a usable epoch
    e[9, 2] = np.nan
    t = np.arange(n) * 0.1
    err = pd.DataFrame(
        np.column_stack([e, sd]),
        index=pd.Index(t, name="time"),
        columns=["east", "north", "up", "east_std", "north_std", "up_std"],
    )
    out = position_nees(err, [(50.0, 80.0)])
    with np.errstate(divide="ignore", invalid="ignore"):
        nees = np.sum((e / sd) ** 2, axis=1)
    ok = np.isfinite(nees) & np.all(sd > 0, axis=1)
    assert out["nees_pos_n"] == int(ok.sum()) == n - 2
    assert out["nees_pos_mean"] == float(np.mean(nees[ok]))
    assert out["nees_pos_median"] == float(np.median(nees[ok]))
    inside = ok & (t >= 50.0) & (t < 80.0)
    assert out["nees_pos_outage_n"] == int(inside.sum()) == 300
    assert out["nees_pos_outage_mean"] == float(np.mean(nees[inside]))


def test_report_state_errors_in_blocks_equal_one_block(monkeypatch):
    import insgnss.report_data as rd

    n = 3000
    t = np.arange(n) * 0.01
    rng = np.random.default_rng(11)
    base = {
        "lat": 0.84 + 1e-8 * np.arange(n),
        "lon": 0.2 + 1e-8 * np.arange(n),
        "height": 300.0 + np.sin(t),
        "vel_e": np.cos(t),
        "vel_n": np.sin(t),
        "vel_u": 0.1 * t,
        "roll": 0.01 * np.sin(t),
        "pitch": 0.02 * np.cos(t),
        "heading": np.linspace(-3.0, 3.0, n),
    }
    ref = pd.DataFrame(base, index=pd.Index(t, name="time"))
    sol = ref + rng.normal(scale=1e-6, size=ref.shape)
    for c in (
        "east_std",
        "north_std",
        "up_std",
        "vel_e_std",
        "vel_n_std",
        "vel_u_std",
        "roll_std",
        "pitch_std",
        "heading_std",
    ):
        sol[c] = rng.uniform(0.1, 1.0, n)
    kinds = ("position", "velocity", "attitude")
    one = rd._state_errors(sol, ref.iloc[::3], kinds)
    monkeypatch.setattr(rd, "STATE_BLOCK", 97)
    blocked = rd._state_errors(sol, ref.iloc[::3], kinds)
    pd.testing.assert_frame_equal(blocked[0], one[0], check_exact=True)
    np.testing.assert_array_equal(blocked[1], one[1])
    np.testing.assert_array_equal(blocked[2], one[2])
    assert one[1].shape == (1000, 9) and np.isfinite(one[1]).all()


def test_trim_heap_gives_back_pyarrows_pool(monkeypatch):
    """trim_heap also empties pyarrow's own pool (where the CSV writer's buffers go), once
    pyarrow is imported, and does not import it when it is not."""
    import sys

    import pyarrow as pa

    from insgnss.io.spill import trim_heap

    calls = []

    class Pool:
        def release_unused(self):
            calls.append(True)

    monkeypatch.setattr(pa, "default_memory_pool", lambda: Pool())
    trim_heap()
    assert calls == [True]
    monkeypatch.delitem(sys.modules, "pyarrow")
    trim_heap()  # pyarrow not imported: left alone
    assert calls == [True] and "pyarrow" not in sys.modules
