"""Bad input on the real drive: GNSS jumps and bursts, dropped IMU samples and gaps.

Runs ``scenarios/drive_0708.toml`` on inputs corrupted in memory (the reference stays the clean
Q=1 RTK file) and prints, per case, the errors relative to the clean run and what the gate did:

- ``jumps sN``: 5 % of the GNSS epochs outside the outages moved 30-100 m (independent epochs,
  seed N);
- ``bursts``: the same 5 % as bursts of 2-8 consecutive epochs (0.5-2 s at 4 Hz), one random
  30-100 m offset per burst (a float solution that jumps and stays);
- ``long burst Ts``: one burst of T seconds with a constant 40 m offset, T below and above the
  filter's ``gate_recovery`` (5 s): longer bursts are eventually accepted by design (after
  ``gate_recovery`` seconds of continuous rejection the filter trusts the GNSS again);
- ``imu drop @Ts``: 1 % of the IMU samples dropped plus a 0.5 s gap T s after the start
  (200 s: driving between two outages; 270 s: driving inside an outage).

Run: ``python bench/bench_robustness_drive.py``.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from insgnss.config import load_job
from insgnss.earth import enu_displacement_to_geodetic
from insgnss.outages import in_windows
from insgnss.pipeline import load_inputs, outage_windows, run_job

REPO = Path(__file__).resolve().parents[1]
JOB = REPO / "scenarios" / "drive_0708.toml"


def _move(g, idx, east, north):
    lat, lon = g["lat"].to_numpy().copy(), g["lon"].to_numpy().copy()
    dlat, dlon, _ = enu_displacement_to_geodetic(lat[idx], g["height"].to_numpy()[idx], east,
                                                 north, 0.0 * east)
    lat[idx] += dlat
    lon[idx] += dlon
    g = g.copy()
    g["lat"], g["lon"] = lat, lon
    return g


def _candidates(job, base):
    t = base.gnss.index.to_numpy()
    t_imu = base.imu.index.to_numpy()
    return np.flatnonzero(~in_windows(t, outage_windows(job, base.gnss)) & (t > t_imu[0] + 40.0)
                          & (t < t_imu[-1]))


def jumps(job, base, seed):
    cand = _candidates(job, base)
    rng = np.random.default_rng(seed)
    k = np.sort(rng.choice(cand, size=int(round(0.05 * cand.size)), replace=False))
    mag, az = rng.uniform(30, 100, k.size), rng.uniform(0, 2 * np.pi, k.size)
    return _move(base.gnss, k, mag * np.sin(az), mag * np.cos(az)), k


def bursts(job, base, seed):
    cand = _candidates(job, base)
    rng = np.random.default_rng(seed)
    cset, chosen = set(cand.tolist()), []
    target = int(round(0.05 * cand.size))
    east, north = [], []
    while len(chosen) < target:
        start, length = int(rng.choice(cand)), int(rng.integers(2, 9))
        run = [i for i in range(start, start + length) if i in cset and i not in chosen]
        m, a = rng.uniform(30, 100), rng.uniform(0, 2 * np.pi)
        chosen += run
        east += [m * np.sin(a)] * len(run)
        north += [m * np.cos(a)] * len(run)
    k = np.asarray(chosen)
    return _move(base.gnss, k, np.asarray(east), np.asarray(north)), k


def long_burst(job, base, seconds, at=230.0):
    t = base.gnss.index.to_numpy()
    t0 = base.imu.index[0] + at
    k = np.flatnonzero((t >= t0) & (t < t0 + seconds))
    return _move(base.gnss, k, np.full(k.size, 40.0), np.zeros(k.size)), k


def imu_drop(base, at, seed=8):
    imu = base.imu
    t = imu.index.to_numpy()
    rng = np.random.default_rng(seed)
    i0 = int(np.searchsorted(t, t[0] + at))
    gap = np.arange(i0, i0 + 50)
    inner = np.setdiff1d(np.arange(1, len(imu) - 1), gap)
    drop = np.union1d(rng.choice(inner, size=len(imu) // 100, replace=False), gap)
    return imu.drop(index=imu.index[drop])


def main() -> None:
    job = load_job(JOB)
    job.settings["filter"]["autotune"] = False  # one model for clean and corrupted inputs
    warnings.simplefilter("ignore")
    base = load_inputs(job)
    c0 = time.perf_counter()
    clean = run_job(job, progress=False, inputs=replace(base))
    print(f"clean run {time.perf_counter() - c0:.1f} s")
    keys = [("smoothed", "rms_h_m"), ("smoothed", "rms_h_err_m_mean"), ("forward", "rms_h_m"),
            ("forward", "end_h_err_m_mean")]
    e0 = clean.summary["evaluation"]
    print(f"{'case':18s} {'n bad':>6s} {'rejected':>9s} {'bad acc.':>8s} {'recov.':>6s}  "
          + "  ".join(f"{n[:3]} {k:>18s}" for n, k in keys))
    print(f"{'clean':18s} {'':>6s} {'':>9s} {'':>8s} {'':>6s}  "
          + "  ".join(f"    {e0[n][k]:8.4f} m         " for n, k in keys))
    cases = [(f"jumps s{s}", lambda s=s: jumps(job, base, s)) for s in (1, 2, 8)]
    cases += [(f"bursts s{s}", lambda s=s: bursts(job, base, s)) for s in (1, 2)]
    cases += [(f"long burst {T:g}s", lambda T=T: long_burst(job, base, T)) for T in (4.0, 8.0)]
    for name, make in cases:
        gnss, k = make()
        res = run_job(job, progress=False, inputs=replace(base, gnss=gnss))
        inn = res.filter.innovations
        gi = inn[inn["type"] == "gnss_pos"]
        tb = gnss.index.to_numpy()[k]
        bad = np.isin(np.round(gi["time"].to_numpy(), 3), np.round(tb, 3))
        e1 = res.summary["evaluation"]
        print(f"{name:18s} {k.size:6d} {int((~gi['accepted']).sum()):9d} "
              f"{int((bad & gi['accepted'].to_numpy()).sum()):8d} {int(gi['recovered'].sum()):6d}  "
              + "  ".join(f"    {e1[n][kk]:8.4f} m ({e1[n][kk] / e0[n][kk] - 1:+6.1%})"
                          for n, kk in keys))
    for at in (200.0, 270.0):
        res = run_job(job, progress=False, inputs=replace(base, imu=imu_drop(base, at)))
        e1 = res.summary["evaluation"]
        gaps = res.summary["imu"]["gaps"]
        inn = res.filter.innovations
        gi = inn[inn["type"] == "gnss_pos"]
        print(f"{'imu drop @' + f'{at:g}s':18s} {len(gaps):6d} {int((~gi['accepted']).sum()):9d} "
              f"{'':>8s} {int(gi['recovered'].sum()):6d}  "
              + "  ".join(f"    {e1[n][kk]:8.4f} m ({e1[n][kk] / e0[n][kk] - 1:+6.1%})"
                          for n, kk in keys))


if __name__ == "__main__":
    main()
