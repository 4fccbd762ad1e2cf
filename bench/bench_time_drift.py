#!/usr/bin/env python3
"""Decision study of the IMU-GNSS time-drift estimate (``inputs.imu.estimate_time_drift``).

Simulated cars (decided here; reported on the real drive in docs/generalization.md): a consumer
MEMS IMU at 100 Hz and RTK-like GNSS at 4 Hz (1-2 cm) on a 10-minute town drive with turns and
stops, processed with the car profile (its noise model; self-tuning off so that only the time
model differs) with the data author's outage rule of the drive (15 s every 45 s from 40 s).
The IMU time stamps are corrupted the way a logger does it: a sample taken at true time ``t``
is stamped ``t - offset - drift (t - t_mid)``. Each seed is run with the constant offset
(``estimate_time_drift = false``, the behaviour before) and with the drift; printed: the
estimated drift, forward end-of-outage mean and smoothed in-outage RMS mean against the truth.

Usage: ``python bench/bench_time_drift.py [--seeds 1 2 3] [--drift-ppm -300 0]``
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from insgnss.config import load_job_dict  # noqa: E402
from insgnss.io.tracks import read_trajectory_csv, write_trajectory_csv  # noqa: E402
from insgnss.pipeline import run_job  # noqa: E402
from insgnss.simulate.scenario import simulate_scenario  # noqa: E402

LEG = [
    {"type": "accelerate", "speed": 12.0, "acceleration": 1.5},
    {"type": "turn", "angle": 70.0, "rate": 14.0},
    {"type": "hold", "duration": 8.0},
    {"type": "decelerate", "speed": 5.0, "acceleration": 1.8},
    {"type": "turn", "angle": -110.0, "rate": 20.0},
    {"type": "accelerate", "speed": 14.0, "acceleration": 1.2},
    {"type": "turn", "angle": 40.0, "rate": 10.0},
    {"type": "decelerate", "speed": 0.0, "acceleration": 2.0},
    {"type": "static", "duration": 6.0},
]

SCENARIO = {
    "scenario": {"name": "car_time_drift", "imu_rate": 100.0, "duration": 600.0},
    "trajectory": {"vehicle": "land", "lat": 40.1, "lon": -105.1, "height": 1600.0,
                   "heading": 350.0, "roll_gain": 0.5,
                   "segments": [{"type": "static", "duration": 35.0}] + LEG * 12},
    "imu": {"grade": "consumer"},
    "gnss": {"rate": 4.0, "horizontal_std": 0.015, "vertical_std": 0.03, "velocity": True,
             "velocity_std": 0.03, "vertical_velocity_std": 0.05, "q": 1},
}


def job(folder: Path, imu: str, drift: bool) -> dict:
    return {
        "job": {"name": "car_time_drift", "platform": "car", "time_base": "run"},
        "inputs": {"imu": {"format": "native", "path": str(folder / imu),
                           "estimate_time_drift": drift},
                   "gnss": {"format": "native", "path": str(folder / "gnss.csv")},
                   "reference": {"format": "native", "path": str(folder / "truth.csv"),
                                 "point": "imu"}},
        "outages": {"periodic": {"start": 40.0, "length": 15.0, "gap": 30.0,
                                 "stop_before_end": 30.0}},
        "filter": {"imu_grade": "consumer", "autotune": False},
        "outputs": {"report": False},
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--drift-ppm", type=float, nargs="+", default=[-300.0, 0.0])
    ap.add_argument("--offset", type=float, default=0.05, help="constant part [s]")
    a = ap.parse_args(argv)
    print(f"{'seed':>4} {'true ppm':>8} | {'model':8} {'est. ppm':>8} {'fwd end [m]':>11} "
          f"{'sm RMS [m]':>10}")
    rows = []
    for seed in a.seeds:
        sim = simulate_scenario(SCENARIO, seed)
        with tempfile.TemporaryDirectory() as tmp:
            d = Path(tmp)
            sim.write(d)
            imu = read_trajectory_csv(d / "imu.csv", required=())
            t = imu.index.to_numpy(float)
            t_mid = 0.5 * (t[0] + t[-1])
            for ppm in a.drift_ppm:
                rec = imu.set_axis(t - a.offset - ppm * 1e-6 * (t - t_mid), axis=0)
                rec.attrs = {}
                write_trajectory_csv(rec, d / f"imu_{ppm:g}.csv")
                for drift in (False, True):
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        res = run_job(load_job_dict(job(d, f"imu_{ppm:g}.csv", drift), d / "job.toml"),
                                      progress=False)
                    est = res.summary["preprocessing"].get("imu_time_drift_ppm", 0.0)
                    fwd = res.evaluation["forward"]["summary"]["end_h_err_m_mean"]
                    smo = res.evaluation["smoothed"]["summary"]["rms_h_err_m_mean"]
                    rows.append((seed, ppm, drift, fwd, smo))
                    print(f"{seed:4d} {ppm:8.0f} | {'drift' if drift else 'constant':8} "
                          f"{est:8.1f} {fwd:11.3f} {smo:10.3f}", flush=True)
    r = np.array([(p, dr, f, s) for _, p, dr, f, s in rows], float)
    for ppm in a.drift_ppm:
        for drift in (0.0, 1.0):
            m = (r[:, 0] == ppm) & (r[:, 1] == drift)
            print(f"mean over seeds, {ppm:5.0f} ppm, {'drift' if drift else 'constant':8}: "
                  f"forward end {r[m, 2].mean():.3f} m, smoothed RMS {r[m, 3].mean():.3f} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
