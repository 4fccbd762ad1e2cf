"""Loosely vs tightly coupled INS/GNSS on the rtklibexplorer walk (docs/tight.md).

Runs the job ``scenarios/walk_0827_tight.toml`` (raw u-blox stream, consumer IMU, ZUPT, the
data author's two 15 s outage windows) in these variants and scores each forward solution with
the shared scorer ``../shared/eval/drive_outage.py`` (walk rule, Q=1 RTK epochs at the antenna):

- ``tight, 3 sats``: pseudorange + Doppler per satellite, only the 3 highest satellites inside
  the windows (the job as written);
- ``tight, 0 sats``: the same with nothing inside the windows (a full outage);
- ``loose, SPP``: the single-point fixes (position + Doppler velocity) of the same stream,
  nothing inside the windows (with 3 satellites there is no fix); ``loose, SPP pos``: their
  positions only;
- ``loose, RTK``: the receiver's RTK fixes (``gnss_1730_sf.pos``, Q 1 and 2), nothing inside
  the windows (the walk job of the loosely coupled benchmark; its reference is the same file).

The reference's datum is (6, 5) m away from what the broadcast orbits give (docs/tight.md,
"Results"), so every solution aided by the raw data carries that offset. The scorer's
numbers are therefore given twice: as the scorer prints them, and "relative to the run's own
non-outage accuracy": the solution shifted by its own mean horizontal error over the scorer's
non-outage epochs (a constant; nothing inside the windows is used), then scored again.

    python bench/bench_tight.py [--keep-outputs DIR]

Prints one row per variant; timings are wall-clock on a shared machine.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd

from insgnss.config import load_job_dict
from insgnss.earth import geodetic_to_enu
from insgnss.io import read_rtklib_pos
from insgnss.job.run import process

ROOT = Path(__file__).resolve().parents[1]
JOB = ROOT / "scenarios" / "walk_0827_tight.toml"
SCORER = ROOT.parent / "shared" / "eval" / "drive_outage.py"
SETTLE, GUARD = 10.0, 1.0  # the scorer's non-outage rule (shared/eval/README.md)


def variants(base: dict) -> dict[str, dict]:
    pos = str(Path(base["inputs"]["reference"]["path"]))
    out = {}
    tight = json.loads(json.dumps(base))
    out["tight, 3 sats"] = tight
    t0 = json.loads(json.dumps(base))
    t0["outages"]["keep_satellites"] = 0
    out["tight, 0 sats"] = t0
    loose = json.loads(json.dumps(base))
    loose["aiding"] = {k: v for k, v in loose["aiding"].items() if k != "doppler"}
    loose["aiding"].update(gnss="loose", gnss_velocity=True)
    del loose["outages"]["keep_satellites"]
    out["loose, SPP"] = loose
    pos_only = json.loads(json.dumps(loose))
    pos_only["aiding"]["gnss_velocity"] = False
    out["loose, SPP pos"] = pos_only
    rtk = json.loads(json.dumps(loose))
    del rtk["inputs"]["gnss_raw"]
    rtk["inputs"]["gnss"].update(format="rtklib_pos", path=pos)
    rtk["aiding"].update(gnss_velocity=False, gnss_min_std=0.03, q_scale={"1": 1.0, "2": 3.0})
    out["loose, RTK"] = rtk
    return out


def score(csv: Path, ref: Path) -> dict:
    res = subprocess.run([sys.executable, str(SCORER), str(csv), "--ref", str(ref), "--json"],
                         capture_output=True, text=True, check=True)
    return json.loads(res.stdout)


def debiased(csv: Path, ref: pd.DataFrame, windows, out: Path) -> tuple[Path, np.ndarray]:
    """The solution shifted by its mean horizontal error over the scorer's non-outage
    epochs (Q=1, ``t >= first + 10 s``, outside the windows and 1 s after their ends)."""
    sol = pd.read_csv(csv)
    t = sol["time_gpst_s"].to_numpy(float)
    tr = ref.index.to_numpy(float)
    use = (ref["q"].to_numpy() == 1) & (tr >= tr[0] + SETTLE) & (tr >= t[0]) & (tr <= t[-1])
    for a, b in windows:
        use &= ~((tr >= a) & (tr < b + GUARD))
    lat0, lon0 = float(ref["lat"].iloc[0]), float(ref["lon"].iloc[0])
    lat = np.interp(tr[use], t, np.radians(sol["lat_deg"].to_numpy()))
    lon = np.interp(tr[use], t, np.radians(sol["lon_deg"].to_numpy()))
    e, n, _ = geodetic_to_enu(lat, lon, 0.0 * lat, lat0, lon0, 0.0)
    e2, n2, _ = geodetic_to_enu(ref["lat"].to_numpy()[use], ref["lon"].to_numpy()[use],
                                0.0 * lat, lat0, lon0, 0.0)
    off = np.array([np.mean(e - e2), np.mean(n - n2)])
    # a horizontal shift of a few metres: local spherical scaling is exact to micrometres
    R = 6378137.0
    sol["lat_deg"] -= np.degrees(off[1] / R)
    sol["lon_deg"] -= np.degrees(off[0] / (R * np.cos(lat0)))
    sol.to_csv(out, index=False)
    return out, off


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--keep-outputs", type=Path, default=None,
                    help="write each variant's outputs below this folder")
    args = ap.parse_args()
    with open(JOB, "rb") as f:
        base = tomllib.load(f)
    ref_path = (JOB.parent / base["inputs"]["reference"]["path"]).resolve()
    ref = read_rtklib_pos(ref_path)
    windows = base["outages"]["windows"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep_outputs or Path(tmp)
        for name, data in variants(base).items():
            job = load_job_dict(data, JOB)
            out = root / name.replace(", ", "_").replace(" ", "_")
            c = time.perf_counter()
            res, _ = process(job, out, progress=False)
            wall = time.perf_counter() - c
            csv = out / "forward_eval.csv"
            s = score(csv, ref_path)
            shifted, off = debiased(csv, ref, windows, Path(tmp) / "shifted.csv")
            d = score(shifted, ref_path)
            rows.append((name, s, d, off, wall, res))
    print("walk_0827, forward solutions, scored by shared/eval/drive_outage.py (2 windows of 15 s)")
    print(f"{'variant':15s} {'end mean':>9s} {'end max':>8s} {'non-out':>8s} | "
          f"{'rel end':>8s} {'rel max':>8s} {'rel non':>8s} | {'offset E,N':>13s} {'complete':>8s} "
          f"{'wall':>6s}")
    for name, s, d, off, wall, res in rows:
        o, od = s["outage_summary"], d["outage_summary"]
        print(f"{name:15s} {o['end_h_err_m']['mean']:9.2f} {o['end_h_err_m']['max']:8.2f} "
              f"{s['non_outage']['rms_h_err_m']:8.2f} | {od['end_h_err_m']['mean']:8.2f} "
              f"{od['end_h_err_m']['max']:8.2f} {d['non_outage']['rms_h_err_m']:8.2f} | "
              f"{off[0]:6.2f},{off[1]:6.2f} {str(res.filter.complete):>8s} {wall:5.1f}s")
    print("end: end-of-outage horizontal error [m] (mean, max over the windows); non-out: the "
          "non-outage horizontal RMS; rel: the same after removing the run's own mean "
          "non-outage horizontal error (offset E,N)")


if __name__ == "__main__":
    main()
