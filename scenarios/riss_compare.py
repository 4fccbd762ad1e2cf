"""Comparison experiment: full IMU versus RISS (1 vertical gyro + 2 horizontal accelerometers +
odometer) aided by GNSS with periodic outages of 30, 60 and 120 s, for a consumer MEMS and a
tactical-grade IMU.

The same simulated drive (``insgnss.simulate``: a 20-minute land-vehicle trajectory with turns,
hills below 10 % and a stop, the full IMU error model of the grade - turn-on bias, Gauss-Markov
instability, white noise, scale factors, non-orthogonality -, 1 Hz GNSS position and velocity,
a 10 Hz odometer with a 1 % scale-factor error and 0.05 m/s noise) feeds both filters:

- full IMU: :func:`insgnss.filter.run_filter` (15 + 6 states with scale factors);
- RISS: :func:`insgnss.filter.riss_model.run_riss_filter` (odometer as the process input, vertical
  gyro scale factor estimated).

Both start from the true attitude with a heading error drawn from N(0, 2 deg) and use the forward
(causal) solution. Per outage: horizontal error at its last epoch (``end``), maximum and RMS
inside it. Prints a Markdown table and writes ``riss_compare.csv``, ``riss_compare_end.png``
(mean end-of-outage error per outage length) and ``riss_compare_growth.png`` (median error growth
inside the 120 s outages).

    python scenarios/riss_compare.py [--seeds 3] [--out out/riss_compare]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from insgnss.earth import radii
from insgnss.filter import FilterConfig, GnssPosition, GnssVelocity, run_filter
from insgnss.filter.riss_model import RissConfig, run_riss_filter
from insgnss.mechanization.strapdown import NavState
from insgnss.simulate.scenario import simulate_scenario

GRADES = ("consumer", "tactical")
OUTAGES = (30.0, 60.0, 120.0)
GAP = 90.0  # GNSS time between outages [s]
FIRST = 150.0  # first outage start [s]
DURATION = 1200.0


def scenario(grade: str) -> dict:
    """The simulated drive (insgnss scenario table, degrees in the file convention)."""
    segs = [{"type": "static", "duration": 20.0},
            {"type": "accelerate", "speed": 15.0, "acceleration": 1.5}]
    v = 15.0
    for k in range(12):
        target = [20.0, 12.0, 17.0][k % 3]
        segs += [{"type": "hold", "duration": 20.0},
                 {"type": "turn", "angle": [90.0, -90.0, 45.0, -135.0][k % 4], "rate": 10.0},
                 {"type": "climb" if k % 2 == 0 else "descend", "height_change": 12.0,
                  "rate": 1.0},
                 {"type": "hold", "duration": 15.0},
                 {"type": "accelerate" if target > v else "decelerate", "speed": target,
                  "acceleration": 1.0}]
        v = target
    segs += [{"type": "decelerate", "speed": 0.0, "acceleration": 1.5},
             {"type": "static", "duration": 20.0},
             {"type": "accelerate", "speed": 15.0, "acceleration": 1.5},
             {"type": "hold", "duration": 600.0}]
    return {
        "scenario": {"name": f"riss_compare_{grade}", "imu_rate": 100.0, "duration": DURATION},
        "trajectory": {"vehicle": "land", "lat": 51.08, "lon": -114.13, "height": 1100.0,
                       "heading": 30.0, "roll_gain": 0.3, "segments": segs},
        "imu": {"grade": grade},
        "gnss": {"rate": 1.0, "horizontal_std": 1.0, "vertical_std": 2.0, "velocity": True,
                 "velocity_std": 0.05},
        "odometer": {"rate": 10.0, "output": "speed", "scale_factor": 0.01, "noise_std": 0.05},
    }


def windows(length: float) -> list[tuple[float, float]]:
    out, s = [], FIRST
    while s + length <= DURATION - 30.0:
        out.append((s, s + length))
        s += length + GAP
    return out


def horizontal_error(sol: pd.DataFrame, truth: pd.DataFrame) -> pd.Series:
    tr = truth.reindex(sol.index, method="nearest")
    lat = tr["lat"].to_numpy()
    M, N = radii(lat)
    h = tr["height"].to_numpy()
    dn = (sol["lat"].to_numpy() - lat) * (M + h)
    de = (sol["lon"].to_numpy() - tr["lon"].to_numpy()) * (N + h) * np.cos(lat)
    return pd.Series(np.hypot(de, dn), index=sol.index)


def run_case(grade: str, length: float, seed: int) -> tuple[list[dict], dict]:
    sim = simulate_scenario(scenario(grade), seed=seed)
    truth, imu = sim.truth, sim.imu
    win = windows(length)
    g = sim.gnss
    tg = g.index.to_numpy()
    keep = np.ones(tg.size, bool)
    for a, b in win:
        keep &= ~((tg >= a) & (tg < b))
    g = g[keep].drop(columns=["q"], errors="ignore")
    meas = [GnssPosition(g), GnssVelocity(g)]
    rng = np.random.default_rng(seed + 1000)
    r0 = truth.iloc[0]
    init = NavState.from_euler(r0.lat, r0.lon, r0.height, (r0.vel_e, r0.vel_n, r0.vel_u),
                               r0.roll, r0.pitch, r0.heading + rng.normal(0.0, np.radians(2.0)))
    cfg = FilterConfig(imu_model=sim.imu_model, scale_factors=True, smoother=False,
                       initial_att_std=(np.radians(0.5), np.radians(0.5), np.radians(2.0)))
    t0 = time.perf_counter()
    full = run_filter(imu, init, meas, cfg)
    t1 = time.perf_counter()
    riss = run_riss_filter(imu, sim.odometer, init, meas, cfg,
                           RissConfig(odometer_speed_std=0.05, odometer_rate=10.0, gyro_scale=True))
    t2 = time.perf_counter()
    rows, growth = [], {}
    for model, res in (("full IMU", full), ("RISS", riss)):
        err = horizontal_error(res.forward, truth)
        curves = []
        for a, b in win:
            inside = err[(err.index >= a) & (err.index < b)]
            if not len(inside):
                continue
            rows.append({"grade": grade, "outage_s": length, "seed": seed, "model": model,
                         "start": a, "end_h_m": float(inside.iloc[-1]),
                         "max_h_m": float(inside.max()),
                         "rms_h_m": float(np.sqrt(np.mean(inside.to_numpy() ** 2))),
                         "complete": bool(res.complete)})
            curves.append(np.interp(np.arange(0.0, length, 1.0), inside.index.to_numpy() - a,
                                    inside.to_numpy()))
        growth[model] = np.array(curves)
    print(f"  {grade:8s} {length:5.0f} s seed {seed}: full IMU {t1 - t0:.1f} s, RISS {t2 - t1:.1f} s")
    return rows, growth


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--out", default="out/riss_compare")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows, growth = [], {}
    for grade in GRADES:
        for length in OUTAGES:
            for seed in range(args.seeds):
                r, gr = run_case(grade, length, seed)
                rows += r
                for model, c in gr.items():
                    growth.setdefault((grade, length, model), []).append(c)
    df = pd.DataFrame(rows)
    df.to_csv(out / "riss_compare.csv", index=False)
    summ = (df.groupby(["grade", "outage_s", "model"])
            .agg(n=("end_h_m", "size"), end_mean=("end_h_m", "mean"),
                 end_median=("end_h_m", "median"), end_max=("end_h_m", "max"),
                 rms_mean=("rms_h_m", "mean")).reset_index())
    print("\nHorizontal error in GNSS outages (forward filter), metres; n = outages x seeds\n")
    print("| grade | outage [s] | model | n | end mean | end median | end max | in-outage RMS |")
    print("|---|---|---|---|---|---|---|---|")
    for _, r in summ.iterrows():
        print(f"| {r.grade} | {r.outage_s:.0f} | {r.model} | {r.n} | {r.end_mean:.2f} | "
              f"{r.end_median:.2f} | {r.end_max:.2f} | {r.rms_mean:.2f} |")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover
        return 0
    fig, axes = plt.subplots(1, len(GRADES), figsize=(10, 4), sharey=True)
    for ax, grade in zip(axes, GRADES, strict=True):
        s = summ[summ.grade == grade]
        x = np.arange(len(OUTAGES))
        for i, model in enumerate(("full IMU", "RISS")):
            v = [float(s[(s.outage_s == L) & (s.model == model)].end_mean.iloc[0]) for L in OUTAGES]
            ax.bar(x + (i - 0.5) * 0.38, v, 0.38, label=model)
        ax.set_xticks(x, [f"{L:.0f} s" for L in OUTAGES])
        ax.set_yscale("log")
        ax.set_title(f"{grade} IMU")
        ax.set_xlabel("GNSS outage length")
        ax.grid(True, axis="y", which="both", alpha=0.3)
    axes[0].set_ylabel("mean end-of-outage horizontal error [m]")
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(out / "riss_compare_end.png", dpi=120)
    fig, ax = plt.subplots(figsize=(7, 4))
    for grade in GRADES:
        for model, ls in (("full IMU", "-"), ("RISS", "--")):
            c = np.vstack(growth[(grade, 120.0, model)])
            ax.plot(np.arange(c.shape[1]), np.median(c, axis=0), ls, label=f"{model}, {grade}")
    ax.set_yscale("log")
    ax.set_xlabel("time since outage start [s]")
    ax.set_ylabel("median horizontal error [m]")
    ax.set_title("Error growth in 120 s GNSS outages")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "riss_compare_growth.png", dpi=120)
    print(f"\nwritten: {out / 'riss_compare.csv'}, riss_compare_end.png, riss_compare_growth.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
