"""Benchmark: trajectory writers in MB/s (native CSV, Parquet, KF-GINS .nav) on a 1 h / 200 Hz
forward solution (720,000 rows), all columns (43, with biases, scale factors and their stds)
and the default lean set (nav + std, 19 columns).

Run: ``python bench/bench_writers.py [--rows N] [--repeat K]``. Prints numbers; not a timed
test. MB/s is file size over wall time (best of K). The .nav line is the one to compare with
the previous ``np.savetxt`` writer (45 MB/s in the speed issue); ``--savetxt`` also times that
writer here, on the same table.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

STD = ["east_std", "north_std", "up_std", "vel_e_std", "vel_n_std", "vel_u_std", "roll_std",
       "pitch_std", "heading_std"]
PAR = [f"{q}_{k}_{a}" for q in ("gyro", "accel") for k in ("bias", "scale") for a in "xyz"]


def trajectory(n: int) -> pd.DataFrame:
    rng = np.random.default_rng(0)
    t = 1436038461.0 + np.arange(n) / 200.0
    d = {"lat": np.radians(37.0) + 1e-7 * np.cumsum(rng.normal(0, 1, n)),
         "lon": np.radians(-122.0) + 1e-7 * np.cumsum(rng.normal(0, 1, n)),
         "height": 10 + np.cumsum(rng.normal(0, 1e-3, n)), "vel_e": rng.normal(0, 10, n),
         "vel_n": rng.normal(0, 10, n), "vel_u": rng.normal(0, 0.1, n),
         "roll": rng.normal(0, 0.02, n), "pitch": rng.normal(0, 0.02, n),
         "heading": rng.uniform(-np.pi, np.pi, n)}
    d.update({c: rng.uniform(0.01, 1, n) for c in STD})
    d.update({c: rng.normal(0, 1e-4, n) for c in PAR})
    d.update({f"{c}_std": rng.uniform(0, 1e-4, n) for c in PAR})
    df = pd.DataFrame(d, index=pd.Index(t, name="time"))
    df.attrs["time_base"] = "gps"
    return df


def savetxt_nav(df: pd.DataFrame, path: Path) -> None:
    """The previous .nav writer (np.savetxt), for comparison."""
    from insgnss.attitude import euler_to_ned, ned_to_enu
    from insgnss.io.gpstime import week_sow_from_gps_seconds

    wk, sow = week_sow_from_gps_seconds(np.asarray(df.index, float))
    vned = ned_to_enu(df[["vel_e", "vel_n", "vel_u"]].to_numpy(float))
    r, p, y = euler_to_ned(df["roll"].to_numpy(), df["pitch"].to_numpy(), df["heading"].to_numpy())
    table = np.column_stack([wk, sow, np.degrees(df["lat"]), np.degrees(df["lon"]), df["height"],
                             vned, np.degrees(r), np.degrees(p), np.degrees(y)])
    fmt = ["%d", "%.6f", "%.10f", "%.10f", "%.5f", "%.5f", "%.5f", "%.5f", "%.8f", "%.8f", "%.8f"]
    np.savetxt(path, table, fmt=fmt, delimiter=" ")


def timed(write, path: Path, repeat: int) -> tuple[float, int]:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        write(path)
        best = min(best, time.perf_counter() - t0)
    return best, path.stat().st_size


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rows", type=int, default=720_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--savetxt", action="store_true", help="also time the np.savetxt .nav writer")
    args = ap.parse_args()
    from insgnss.io import native
    from insgnss.io.kfgins import write_kfgins_nav

    df = trajectory(args.rows)
    lean = df[["lat", "lon", "height", "vel_e", "vel_n", "vel_u", "roll", "pitch", "heading"] + STD]
    cases = [("csv, all 43 columns", lambda p: native.write_table(df, p), "t.csv"),
             ("csv, nav+std 19 columns", lambda p: native.write_table(lean, p), "t.csv")]
    if hasattr(native, "write_parquet"):
        cases += [("parquet, all 43 columns", lambda p: native.write_parquet(df, p), "t.parquet"),
                  ("parquet, nav+std 19", lambda p: native.write_parquet(lean, p), "t.parquet")]
    cases.append((".nav (KF-GINS text)", lambda p: write_kfgins_nav(df, p), "t.nav"))
    if args.savetxt:
        cases.append((".nav, np.savetxt (old)", lambda p: savetxt_nav(df, p), "old.nav"))
    print(f"{args.rows:,} rows (1 h at 200 Hz = 720,000); best of {args.repeat}")
    print(f"{'writer':28s} {'MB':>8s} {'s':>7s} {'MB/s':>7s} {'rows/s':>12s}")
    with tempfile.TemporaryDirectory() as tmp:
        for name, write, fname in cases:
            dt, size = timed(write, Path(tmp) / fname, args.repeat)
            print(f"{name:28s} {size / 1e6:8.1f} {dt:7.2f} {size / 1e6 / dt:7.0f} "
                  f"{args.rows / dt:12,.0f}")


if __name__ == "__main__":
    main()
