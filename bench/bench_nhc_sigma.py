"""Simulated cars whose NHC is violated by a time-correlated slip: which NHC sigma the one-step
innovation likelihood of the self-tuning prefers, and what each sigma does to the outage drift.

The truth is the suspension-squatting car of the filter tests (3 deg/g, consumer IMU, gyro noise
at engine-vibration level, 4 Hz RTK, 15 s outages every 45 s) whose body additionally slips
sideways and heaves: lateral and vertical body velocities that are first-order Gauss-Markov
(``--slip`` m/s lateral, half of it vertical, correlation time ``--tau`` s, smoothed over 0.5 s
as a body's inertia does), realised as small yaw and pitch motions of the body about its path,
so the IMU measures them. The filter has the car profile's NHC (every 0.25 s, pitch-compliance
and misalignment states) with a white sigma from a grid; for each it prints the one-step
composite log-likelihood of the innovation log (``insgnss.autotune.innovation_terms``, the
self-tuning's stage-1 objective, types weighted by their row counts), the forward
end-of-outage error and the smoothed in-outage RMS.

    PYTHONPATH=. python bench/bench_nhc_sigma.py [--seeds 3] [--slip 0.1] [--tau 2]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from filter_sim import car_outage_setup, car_truth, outage_end_error, outage_rms  # noqa: E402

from insgnss.attitude import dcm_to_euler, euler_to_dcm, rotvec_to_dcm  # noqa: E402
from insgnss.autotune import innovation_terms  # noqa: E402
from insgnss.filter import BodyVelocity, run_filter  # noqa: E402

KAPPA = np.radians(3.0) / 9.80665
GRID = (0.025, 0.05, 0.1, 0.2, 0.4)
#: white sigmas of the filter with violation states
GRID_V = (0.01, 0.02, 0.05, 0.1)


def slipping_car(rng, slip: float, tau: float, duration: float = 300.0, rate: float = 50.0):
    """Squatting car whose body yaws and pitches about its path by ``(v_lat, v_up) / v`` with
    ``v_lat``, ``v_up`` Gauss-Markov (sigma ``slip``, ``slip / 2``; ``tau``) smoothed over 0.5 s."""
    truth = car_truth(duration, rate, heading0=rng.uniform(0, 2 * np.pi))
    t = truth.index.to_numpy()
    vel = truth[["vel_e", "vel_n", "vel_u"]].to_numpy()
    C = euler_to_dcm(truth["roll"].to_numpy(), truth["pitch"].to_numpy(),
                     truth["heading"].to_numpy())
    a = np.gradient(vel, t, axis=0)
    n = int(0.5 * rate)
    box = np.ones(n) / n
    a_f = np.convolve(np.einsum("ki,ki->k", a, C[:, :, 1]), box, mode="same")
    Cv = euler_to_dcm(truth["roll"].to_numpy(), truth["pitch"].to_numpy() + KAPPA * a_f,
                      truth["heading"].to_numpy())
    dt = 1.0 / rate
    ar = np.exp(-dt / tau)
    w = rng.standard_normal((t.size, 2)) * np.sqrt(1 - ar * ar) * np.array([slip, slip / 2])
    g = lfilter([1.0], [1.0, -ar], w, axis=0)
    g = np.stack([np.convolve(g[:, k], box, mode="same") for k in range(2)], axis=1)
    g *= np.array([slip, slip / 2]) / g.std(axis=0)  # the smoothed process keeps its sigma
    v = np.linalg.norm(vel, axis=1)
    # body lateral velocity v_lat: the forward axis turned by -v_lat / v about up; heave
    # v_up: pitched down by v_up / v about right
    mu = np.stack([-g[:, 1] / v, np.zeros_like(v), g[:, 0] / v], axis=1)
    Cb = np.einsum("kij,kjl->kil", Cv, np.stack([rotvec_to_dcm(m) for m in mu]))
    r, p, h = dcm_to_euler(Cb)
    out = truth.copy()
    out["roll"], out["pitch"], out["heading"] = r, p, h
    return out


def row(grid, x, f: str) -> str:
    """``sigma:value`` pairs over ``grid``."""
    return " ".join(f"{g}:{v:{f}}" for g, v in zip(grid, x, strict=True))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=300)
    ap.add_argument("--slip", type=float, default=0.1)
    ap.add_argument("--tau", type=float, default=2.0)
    ap.add_argument("--violation-tau", type=float, default=None,
                    help="filter with Gauss-Markov violation states of this correlation time "
                         "(the grid is then their white part)")
    ap.add_argument("--violation-std", type=float, default=0.1)
    args = ap.parse_args()
    t0 = time.perf_counter()
    grid = GRID if args.violation_tau is None else GRID_V
    ll = np.zeros((args.seeds, len(grid)))
    end = np.zeros_like(ll)
    srms = np.zeros_like(ll)
    for i in range(args.seeds):
        rng = np.random.default_rng(args.first_seed + i)
        truth = slipping_car(rng, args.slip, args.tau)
        outages = [(40.0 + 45 * k, 55.0 + 45 * k) for k in range(6)]
        imu, init, gnss, tn, cfg = car_outage_setup(truth, rng, outages, smoother=True)
        weights = None
        for j, s in enumerate(grid):
            extra = {} if args.violation_tau is None else {
                "violation_state": "slip", "violation_std": [args.violation_std] * 2,
                "violation_tau": args.violation_tau}
            nhc = BodyVelocity(tn, 0.0, axes=(0, 2), std=[s, s], name="nhc",
                               pitch_compliance_state="kappa", misalignment_state="mis",
                               **extra)
            res = run_filter(imu, init, [*gnss, nhc], cfg)
            terms = innovation_terms(res.innovations)
            if weights is None:
                weights = {k: n for k, (n, _) in terms.items()}
            ll[i, j] = sum(weights[k] * terms[k][1] for k in weights if k in terms)
            end[i, j] = outage_end_error(res.forward, truth, outages)
            srms[i, j] = outage_rms(res.smoothed, truth, outages)
        print(f"seed {args.first_seed + i}: one-step ML sigma {grid[int(np.argmax(ll[i]))]}, "
              f"least drift at {grid[int(np.argmin(end[i]))]}", flush=True)
        print(f"   end [m] {row(grid, end[i], '.2f')}\n   smoothed in-outage RMS [m] "
              f"{row(grid, srms[i], '.3f')}\n   dLL {row(grid, ll[i] - ll[i].max(), '.0f')}", flush=True)
    print(f"mean end-of-outage [m]: {row(grid, end.mean(axis=0), '.3f')}")
    print(f"mean smoothed in-outage RMS [m]: {row(grid, srms.mean(axis=0), '.3f')}")
    print(f"true slip sigma {args.slip} m/s (lateral), tau {args.tau} s; "
          f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
