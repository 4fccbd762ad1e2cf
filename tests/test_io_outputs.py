"""Output tables: native CSV/Parquet writers without a table copy, the fixed-decimal .nav text,
output column groups and decimation (issue: outputs that fit the use)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from insgnss import columns as C
from insgnss.errors import ConfigError, InputFormatError
from insgnss.io import native
from insgnss.io.gpstime import week_sow_from_gps_seconds
from insgnss.io.kfgins import NAV_DECIMALS, read_kfgins_nav, write_kfgins_nav
from insgnss.io.native import (
    decimate_table,
    decimation_rows,
    fixed_decimal_text,
    output_rate,
    read_table,
    select_output_columns,
    write_parquet,
    write_table,
)


def _trajectory(n=500, rate=200.0, t0=1436038461.0, seed=0, params=True) -> pd.DataFrame:
    """A filter-like output table: NAV_COLS, STD_COLS, biases, scale factors and their stds."""
    rng = np.random.default_rng(seed)
    t = t0 + np.arange(n) / rate
    d = {"lat": np.radians(37.0 + 1e-4 * np.sin(np.arange(n) / 50)), "lon": np.radians(-122.1),
         "height": 10 + rng.normal(0, 1, n), "vel_e": rng.normal(0, 5, n),
         "vel_n": rng.normal(0, 5, n), "vel_u": rng.normal(0, 1e-6, n),  # tiny: "-0.00000"
         "roll": rng.normal(0, 0.05, n), "pitch": rng.normal(0, 0.05, n),
         "heading": rng.uniform(-np.pi, np.pi, n)}
    d.update({c: rng.uniform(0.01, 1, n) for c in C.STD_COLS})
    if params:
        for c in ("gyro_bias_x", "gyro_bias_y", "gyro_bias_z", "accel_bias_x", "accel_bias_y",
                  "accel_bias_z", "gyro_scale_x", "accel_scale_z"):
            d[c], d[f"{c}_std"] = rng.normal(0, 1e-4, n), rng.uniform(0, 1e-4, n)
    df = pd.DataFrame(d, index=pd.Index(t, name="time"))
    df.attrs["time_base"] = "gps"
    return df


# --- fixed-decimal text (.nav) -------------------------------------------------------------------

def test_fixed_decimal_text_is_printf():
    rng = np.random.default_rng(3)
    hard = [0.5, 1.5, 2.5, -2.5, 0.125, 0.375, 1e-7, -1e-7, -0.0, 0.0, -4e-6, 4.5e-6, 5e-6,
            np.nan, np.inf, -np.inf, 1e20, -3e18, 243298.4995, 1.0000005, 2.675, 89.99999999995]
    for d in (0, 1, 2, 5, 6, 8, 10):
        base = [rng.normal(0, 10.0 ** rng.integers(-6, 6), 3000),
                np.round(rng.normal(0, 100, 3000), d) + 0.5 * 10.0**-d,  # exact decimal ties
                np.array(hard)]
        v = np.concatenate(base)
        got = fixed_decimal_text(v, d).to_pylist()
        assert got == [f"{x:.{d}f}" for x in v], d
    with pytest.raises(ValueError, match="decimals"):
        fixed_decimal_text(np.ones(2), 13)


def _nav_savetxt(df, path):
    """The previous writer: np.savetxt with the .nav formats (the format to keep)."""
    from insgnss.attitude import euler_to_ned, ned_to_enu

    wk, sow = week_sow_from_gps_seconds(np.asarray(df.index, float))
    vned = ned_to_enu(df[["vel_e", "vel_n", "vel_u"]].to_numpy(float))
    r, p, y = euler_to_ned(df["roll"].to_numpy(), df["pitch"].to_numpy(), df["heading"].to_numpy())
    table = np.column_stack([wk, sow, np.degrees(df["lat"]), np.degrees(df["lon"]), df["height"],
                             vned, np.degrees(r), np.degrees(p), np.degrees(y)])
    fmt = ["%d"] + [f"%.{d}f" for d in NAV_DECIMALS[1:]]
    np.savetxt(path, table, fmt=fmt, delimiter=" ")


def test_nav_writer_byte_identical_to_savetxt(tmp_path, monkeypatch):
    df = _trajectory(n=3000, params=False)
    _nav_savetxt(df, tmp_path / "old.nav")
    write_kfgins_nav(df, tmp_path / "new.nav")
    old, new = (tmp_path / "old.nav").read_bytes(), (tmp_path / "new.nav").read_bytes()
    assert b"-0.00000" in old  # the small negative velocities keep their sign
    assert new == old
    back = read_kfgins_nav(tmp_path / "new.nav")
    np.testing.assert_allclose(back.index.to_numpy(), df.index.to_numpy(), atol=5e-7)
    np.testing.assert_allclose(back["lat"], df["lat"], atol=np.radians(5e-11))


def test_nav_writer_batches(tmp_path, monkeypatch):
    """Rows are formatted a batch at a time; the text does not depend on the batch size."""
    import insgnss.io.kfgins as kf

    df = _trajectory(n=1000, params=False)
    write_kfgins_nav(df, tmp_path / "one.nav")
    cols = kf._nav_columns(df, *week_sow_from_gps_seconds(np.asarray(df.index, float)))
    kf._write_nav_text(cols, tmp_path / "many.nav", rows=77)
    assert (tmp_path / "one.nav").read_bytes() == (tmp_path / "many.nav").read_bytes()
    assert len((tmp_path / "many.nav").read_text().splitlines()) == 1000
    write_kfgins_nav(df.iloc[:0], tmp_path / "empty.nav")
    assert (tmp_path / "empty.nav").read_bytes() == b""


# --- native CSV and Parquet -------------------------------------------------------------------------

def test_csv_round_trip_and_input_untouched(tmp_path, monkeypatch):
    df = _trajectory(n=1000)
    df.iloc[5, 3] = np.nan
    before = df.copy()
    p = write_table(df, tmp_path / "t.csv")
    pd.testing.assert_frame_equal(df, before)  # no rename or conversion in place
    header = p.read_text().splitlines()[0].split(",")
    assert header[:4] == ["time", "lat_deg", "lon_deg", "height"] and "heading_std_deg" in header
    back = read_table(p)
    assert list(back.columns) == list(df.columns)
    np.testing.assert_array_equal(back.index.to_numpy(), df.index.to_numpy())
    # shortest round-trip floats: exact after the degree conversion and back
    np.testing.assert_allclose(back.to_numpy(), df.to_numpy(), rtol=1e-15, atol=0)
    assert np.isnan(back.iloc[5, 3])
    monkeypatch.setattr(native, "BATCH_ROWS", 33)
    write_table(df, tmp_path / "b.csv")
    assert (tmp_path / "b.csv").read_bytes() == p.read_bytes()


def test_parquet_round_trip(tmp_path):
    df = _trajectory(n=700)
    df.attrs["gps_week"] = 2374
    p = write_parquet(df, tmp_path / "t.parquet")
    names = pq.read_schema(p).names
    assert names[:3] == ["time", "lat_deg", "lon_deg"]  # the same columns as the CSV
    back = read_table(p)
    np.testing.assert_array_equal(back.index.to_numpy(), df.index.to_numpy())
    np.testing.assert_allclose(back.to_numpy(), df.to_numpy(), rtol=1e-15, atol=0)
    assert back.attrs["time_base"] == "gps" and back.attrs["gps_week"] == 2374
    assert write_table(df, tmp_path / "u.parquet").read_bytes()[:4] == b"PAR1"
    bad = tmp_path / "bad.parquet"
    bad.write_text("time,lat\n1,2\n")
    with pytest.raises(InputFormatError, match="not a readable Parquet file"):
        read_table(bad)


@pytest.mark.parametrize("writer", [write_table, write_parquet])
def test_writers_do_not_copy_the_table(tmp_path, monkeypatch, writer):
    """Peak numpy memory while writing stays a small fraction of the table (the old writer
    copied it whole, and once more per renamed angle column)."""
    monkeypatch.setattr(native, "BATCH_ROWS", 2000)
    df = _trajectory(n=100_000)
    size = df.to_numpy().nbytes
    tracemalloc.start()
    try:
        writer(df, tmp_path / ("t.parquet" if writer is write_parquet else "t.csv"))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 0.05 * size, (peak, size)


# --- column groups ----------------------------------------------------------------------------------

def test_column_groups():
    df = _trajectory(n=10)
    assert list(select_output_columns(df, ["nav", "std"]).columns) == C.NAV_COLS + C.STD_COLS
    assert list(select_output_columns(df, C.DEFAULT_OUTPUT_GROUPS).columns) == \
        C.NAV_COLS + C.STD_COLS
    assert list(select_output_columns(df, ["nav"]).columns) == C.NAV_COLS
    par = list(select_output_columns(df, ["params"]).columns)
    assert par[0] == "gyro_bias_x" and "accel_scale_z_std" in par and len(par) == 16
    assert not set(par) & (set(C.NAV_COLS) | set(C.STD_COLS))
    assert select_output_columns(df, ["all"]) is df
    assert select_output_columns(df, ["nav", "std", "params"]) is df
    view = select_output_columns(df, ["nav"])
    assert np.shares_memory(view["lat"].to_numpy(), df["lat"].to_numpy())
    with pytest.raises(ConfigError, match="outputs.columns"):
        select_output_columns(df, ["nav", "biases"])
    df["segment"] = 1  # split runs: the row label stays with every group
    assert list(select_output_columns(df, ["nav"]).columns) == C.NAV_COLS + ["segment"]
    assert list(select_output_columns(df, ["params"]).columns) == par + ["segment"]


def test_column_names_are_the_engines():
    """One list of names: the mechanization and the filter output use the same as
    :mod:`insgnss.columns` (until they import them from there)."""
    from insgnss.filter.smoother import STD_COLS
    from insgnss.mechanization.strapdown import NAV_COLS

    assert C.NAV_COLS == NAV_COLS and C.STD_COLS == STD_COLS


# --- decimation -------------------------------------------------------------------------------------

def test_decimation_grid():
    t = 100.0037 + np.arange(2001) / 200.0  # 10 s at 200 Hz, not starting on a tick
    rows = decimation_rows(t, 10.0)
    kept = t[rows]
    # the first sample at or after each 0.1 s tick, plus the first and the last sample
    ticks = np.arange(np.ceil(t[0] * 10), np.floor(t[-1] * 10) + 1) / 10
    expect = np.unique(np.r_[t[0], t[np.searchsorted(t, ticks - 1e-9)], t[-1]])
    np.testing.assert_array_equal(kept, expect)
    assert 100 <= len(rows) <= 102
    assert decimation_rows(t, "imu") is None and decimation_rows(t, None) is None
    assert decimation_rows(t, 500.0) is None  # above the data rate: every row
    for bad in (0, -1.0, float("nan"), float("inf"), "10", True):
        with pytest.raises(ConfigError, match="outputs.rate_hz"):
            output_rate(bad)
    assert output_rate(" IMU ") is None and output_rate(4) == 4.0
    assert output_rate("auto") == C.DEFAULT_OUTPUT_RATE == 10.0
    assert output_rate("auto", "foot") is None  # foot INS: every sample
    assert decimation_rows(t, "auto", preset="foot") is None


def test_decimation_keeps_what_interpolation_at_the_epochs_sees():
    """A forward solution jumps at each update; at the measurement/reference epochs a scorer
    interpolating the decimated table must see what it sees on the full table."""
    rate = 100.0
    t = 1000.0 + np.arange(6000) / rate
    epochs = 1000.249 + np.arange(0, 60, 0.25)  # 4 Hz, between IMU samples
    x = 0.3 * t + 0.02 * np.sin(t)
    x += 0.05 * np.cumsum(np.isin(np.arange(t.size), np.searchsorted(t, epochs)))  # jumps
    df = pd.DataFrame({"x": x}, index=pd.Index(t, name="time"))
    full = np.interp(epochs, t, x)
    plain = decimate_table(df, 10.0)
    assert np.abs(np.interp(epochs, plain.index, plain["x"]) - full).max() > 1e-3
    dec = decimate_table(df, 10.0, keep_times=[epochs])
    assert len(dec) < 0.3 * len(df)
    np.testing.assert_array_equal(np.interp(epochs, dec.index, dec["x"]), full)
    assert decimate_table(df, "imu") is df


def test_decimation_error_bound():
    """Between kept samples the linear-interpolation error is at most a dt^2 / 8."""
    rate, out_rate, A, w = 200.0, 10.0, 50.0, 0.4  # |a| <= A w^2 = 8 m/s^2
    t = np.arange(0, 60, 1 / rate)
    df = pd.DataFrame({"x": A * np.sin(w * t)}, index=pd.Index(t, name="time"))
    dec = decimate_table(df, out_rate)
    err = np.abs(np.interp(t, dec.index, dec["x"]) - df["x"].to_numpy())
    dt = np.diff(dec.index).max()
    assert dt == pytest.approx(1 / out_rate, abs=1 / rate)
    assert 0.5 * A * w**2 * dt**2 / 8 < err.max() <= A * w**2 * dt**2 / 8


# --- job keys and the written set ------------------------------------------------------------------

def test_output_keys_checked_at_load():
    from insgnss.config import load_job_dict

    job = load_job_dict({})
    assert job["outputs"]["columns"] == ["nav", "std"] and job["outputs"]["rate_hz"] == "auto"
    ok = load_job_dict({"outputs": {"formats": ["parquet", "nav"], "columns": ["all"],
                                    "rate_hz": 50}})
    assert ok["outputs"]["rate_hz"] == 50
    for key, value, found in (("formats", ["csv", "cvs"], "'cvs'"),
                              ("columns", ["nav", "bias"], "'bias'"),
                              ("rate_hz", 0, "0"), ("rate_hz", "fast", "'fast'"),
                              ("rate_hz", [10], "list")):
        with pytest.raises(ConfigError, match=f"outputs.{key}") as exc:
            load_job_dict({"outputs": {key: value}})
        assert found in str(exc.value)


def test_written_trajectories_follow_the_output_keys(tmp_path):
    """Defaults: nav + std columns at 10 Hz plus the samples around the GNSS epochs; Parquet
    holds what the CSV holds; ``columns = ["all"]``, ``rate_hz = "imu"`` write everything."""
    import warnings

    from robustness_helpers import small_job

    from insgnss.pipeline import run_job, write_outputs

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = run_job(small_job(outputs='formats = ["csv", "parquet", "nav"]'), progress=False)
    write_outputs(res, tmp_path / "lean")
    fwd = res.filter.forward
    csv, par = read_table(tmp_path / "lean" / "forward.csv"), read_table(tmp_path / "lean" /
                                                                            "forward.parquet")
    assert list(csv.columns) == C.NAV_COLS + C.STD_COLS and len(fwd.columns) > 18
    pd.testing.assert_frame_equal(csv, par, check_exact=False, rtol=1e-15)
    t, tw = fwd.index.to_numpy(), csv.index.to_numpy()
    gnss = res.inputs.gnss.index.to_numpy()
    n_ticks = int(np.floor(t[-1] * 10) - np.ceil(t[0] * 10)) + 1
    assert n_ticks <= len(tw) <= n_ticks + 2 * len(gnss) + 2 and len(tw) < len(t) / 3
    gnss = gnss[(gnss >= t[0]) & (gnss <= t[-1])]
    assert np.isin(gnss, tw).all()  # the epochs are IMU samples here: kept without a bracket
    for c in ("lat", "vel_e", "heading"):  # at the epochs the file gives the full-rate values
        np.testing.assert_allclose(np.interp(gnss, tw, csv[c]), np.interp(gnss, t, fwd[c]),
                                   rtol=1e-14)
    np.testing.assert_allclose(csv["lat"], fwd.loc[tw, "lat"], rtol=1e-15)
    nav = (tmp_path / "lean" / "forward.nav").read_text().splitlines()
    assert len(nav) == len(tw)

    res.job.settings["outputs"].update(columns=["all"], rate_hz="imu", formats=["csv"])
    write_outputs(res, tmp_path / "full")
    full = read_table(tmp_path / "full" / "forward.csv")
    assert list(full.columns) == list(fwd.columns) and len(full) == len(fwd)
    assert not (tmp_path / "full" / "forward.parquet").exists()  # the previous set's files go
