"""RISS versus full IMU on the real car drive ``shared/data/gnss-imu-rtklibexplorer/drive_0708``,
under the data author's outage schedule (11 outages of 15 s, ``shared/eval/README.md``), scored
with the shared scorer ``shared/eval/drive_outage.py`` (run, not copied).

**The drive has no odometer.** This script builds a *pseudo-odometer* and says so everywhere:

1. RTK velocity from the RTKLIB positions (Q = 1 or 2) by differences of consecutive epochs
   (<= 0.3 s apart), assigned to the mid-epoch times (the .pos velocity column lags by half an
   epoch, see ``scenarios/drive_0708.toml``);
2. projected on the vehicle forward axis, ``u = (sin A cos p, cos A cos p, sin p)`` with heading
   and pitch of the full-IMU smoothed solution (a reference attitude, used for nothing else);
3. multiplied by ``1 + 0.01`` (a 1 % scale-factor error, which the RISS filter must estimate)
   plus white noise of 0.05 m/s (seeded), at the 4 Hz of the RTK epochs.

The pseudo-odometer is available during the outages (it is derived from the reference, which is
the point of a pseudo-sensor); the GNSS *position* updates are withheld in the outage windows for
both filters. The full-IMU run is ``scenarios/drive_0708.toml`` as it is (strapdown with scale
factors, ZUPT/ZARU at the stops, NHC); the RISS run uses the same job with
``process_model = "riss"`` (its non-holonomic assumption is built in, so NHC is off; the vertical
gyro scale factor is estimated as the job estimates scale factors; the odometer noise is set to
the pseudo-odometer's 0.05 m/s) and the pseudo-odometer as its input. Both forward (causal)
and smoothed solutions are scored.

    python scenarios/riss_drive_0708.py [--out out/riss_drive_0708]
"""

from __future__ import annotations

import argparse
import copy
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
JOB = REPO / "scenarios" / "drive_0708.toml"
SCORER = REPO.parent / "shared" / "eval" / "drive_outage.py"
SCALE_ERROR = 0.01
NOISE_STD = 0.05


def pseudo_odometer(gnss: pd.DataFrame, attitude: pd.DataFrame, seed: int = 7) -> pd.DataFrame:
    """Forward speed [m/s] from RTK position differences projected on the forward axis of
    ``attitude`` (heading, pitch), with a 1 % scale error and 0.05 m/s white noise."""
    from insgnss.earth import geodetic_to_enu

    g = gnss[gnss["q"].isin([1, 2])] if "q" in gnss.columns else gnss
    t = g.index.to_numpy(float)
    e, n, u = geodetic_to_enu(g["lat"].to_numpy(), g["lon"].to_numpy(), g["height"].to_numpy(),
                              float(g["lat"].iloc[0]), float(g["lon"].iloc[0]),
                              float(g["height"].iloc[0]))
    p = np.column_stack([e, n, u])
    dt = np.diff(t)
    ok = (dt > 0) & (dt <= 0.3)
    tm = 0.5 * (t[1:] + t[:-1])[ok]
    v = (np.diff(p, axis=0) / dt[:, None])[ok]
    ta = attitude.index.to_numpy(float)
    hd = np.interp(tm, ta, np.unwrap(attitude["heading"].to_numpy(float)))
    pt = np.interp(tm, ta, attitude["pitch"].to_numpy(float))
    fwd = np.column_stack([np.sin(hd) * np.cos(pt), np.cos(hd) * np.cos(pt), np.sin(pt)])
    speed = np.einsum("ki,ki->k", v, fwd)
    rng = np.random.default_rng(seed)
    speed = (1.0 + SCALE_ERROR) * speed + rng.normal(0.0, NOISE_STD, speed.size)
    inside = (tm >= ta[0]) & (tm <= ta[-1])
    return pd.DataFrame({"speed": speed[inside]}, index=pd.Index(tm[inside], name="time"))


def score(path: Path) -> dict:
    r = subprocess.run([sys.executable, str(SCORER), str(path), "--json"], capture_output=True,
                       text=True, check=True)
    return json.loads(r.stdout)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(REPO.parent / "out" / "riss_drive_0708"))
    args = ap.parse_args(argv)
    from insgnss.config import load_job
    from insgnss.pipeline import run_job, write_outputs

    out = Path(args.out)
    job = load_job(JOB)
    job.settings["outputs"]["formats"] = ["csv", "eval"]
    job.settings["outputs"]["report"] = False
    full = run_job(job, progress=False)
    paths_full = write_outputs(full, out / "full_imu")

    inputs = full.inputs  # IMU already shifted by the estimated time offset
    odo = pseudo_odometer(inputs.gnss, full.filter.smoothed)
    inputs.odometer = odo
    job_r = copy.deepcopy(job)
    job_r.settings["filter"]["process_model"] = "riss"
    job_r.settings["aiding"]["nhc"] = False
    job_r.settings["inputs"]["imu"]["estimate_time_offset"] = False
    job_r.settings["aiding"]["odometer_std"] = NOISE_STD  # the pseudo-odometer's noise
    riss = run_job(job_r, progress=False, inputs=inputs)
    paths_riss = write_outputs(riss, out / "riss")
    odo.to_csv(out / "pseudo_odometer.csv")

    k = riss.filter.forward["odometer_scale"]
    print("drive_0708, 11 GNSS outages of 15 s (data author's schedule); pseudo-odometer from "
          f"RTK velocity on the forward axis, scale error {SCALE_ERROR:.0%}, noise {NOISE_STD} m/s")
    print(f"RISS odometer scale estimate at the end: {k.iloc[-1]:+.4f} +- "
          f"{riss.filter.forward['odometer_scale_std'].iloc[-1]:.4f} (applied {SCALE_ERROR:+.4f}"
          " on top of the RTK speed)")
    print("\nshared scorer (drive_outage.py), horizontal errors in metres:")
    print("| run | end mean | end median | end max | in-outage RMS mean | non-outage RMS |")
    print("|---|---|---|---|---|---|")
    for label, paths in (("full IMU", paths_full), ("RISS", paths_riss)):
        for name in ("forward", "smoothed"):
            r = score(paths[f"{name}_eval.csv"])
            s = r["outage_summary"]
            print(f"| {label} {name} | {s['end_h_err_m']['mean']:.2f} | "
                  f"{s['end_h_err_m']['median']:.2f} | {s['end_h_err_m']['max']:.2f} | "
                  f"{s['rms_h_err_m']['mean']:.2f} | {r['non_outage']['rms_h_err_m']:.3f} |")
    print(f"\noutputs in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
