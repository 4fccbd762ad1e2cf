#!/usr/bin/env python3
"""Foot-mounted INS: end height and horizontal accuracy on the held-out foot tracks, and the
height error of each effect alone on a simulated level walk (docs/zupt.md, section 6).

Default mode: runs the foot preset (``insgnss.foot.FootConfig()``, or a ``[foot]`` table from a
TOML file) unchanged on

- x-io Gait-Tracking short / long walk (``shared/data/foot-xio-gait``): loop closure, the
  final horizontal displacement from the start [m]; level walk, so the end height error is the
  final ``up`` [m];
- UCR left / right foot (``shared/data/foot-ucr-zupt``): whole-track horizontal RMS after a 2-D
  rigid fit of (north, east) to the truth (x, y) (the truth frame is z-down, the mirror image
  of ENU; see its README); end height error against the truth's ``-z``;
- the 28 PyShoe Vicon trials (``shared/data/pyshoe-vicon``): end height error against the
  Vicon ``z`` (z up), and the 2-D ARMSE of the shared scorer.

and prints one table (the smoothed solution; ``--forward`` for the causal filter), with the
forward solution's raw path length beside its stance-to-stance distance
(``insgnss.strides.stance_distance``).

``--only sim``: the foot preset on a 100.8 m simulated level walk
(:mod:`insgnss.simulate.gait`) with one effect at a time (intra-interval motion at 200/100/60
Hz with and without the coning/sculling correction, ZUPT window timing, stance roll, clipping,
scale factors, non-orthogonality, g-sensitivity, gravity, noise).
``--only sensor``: the second round of sensor effects (docs/zupt.md section 6): anti-aliasing
filters, accelerometer size effect, rate-dependent gyro scale and accelerometer nonlinearity,
each applied on the simulated walk's 4 kHz grid, then compensated over a range of sizes on the
real tracks (end height and the RMS ZUPT innovation at stance entry).
``--only level_floor``: the default table without and with ``[foot] level_floor``
(:class:`insgnss.filter.height_aiding.LevelFloor` and the per-stride height noise, docs/zupt.md
section 7).
``--only phases``: where in the stride the height error of the forward filter accrues on the
PyShoe trials (Vicon; the marker's offset from the IMU fitted per trial): from stance release
to the heel strike, from the heel strike to the detected stance, and over the stance; with the
spread of the stance-to-stance height changes (what ``level_floor_max_step`` has to pass).
``--only skew``: an accelerometer-to-gyro time skew and a rigid accelerometer-to-gyro
misalignment on the simulated walk (end height and phase split), then an accelerometer lag
compensated over -8..+4 ms on the real walks (end height, ``J`` and its vertical part, mean
stance-to-stance height change, PyShoe phase split), and the forward accelerometer's size effect
compensated on six PyShoe walks.
``--only loading``: the loading phase (heel strike -> stance) of the PyShoe walks
(``bench/foot_loading.py``): accelerometer vibration rectification against the shock energy,
the pitch gyro's g-sensitivity and scale factor, the Vicon vertical velocity at the detected
stance onset; each also alone in simulation.

Usage::

    PYTHONPATH=. python bench/bench_foot_height.py [--config job.toml] [--forward] [--json]
        [--only xio|ucr|pyshoe|sim|sensor|level_floor|phases|skew|loading]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))
from foot_data import (  # noqa: E402  (the shared foot datasets)
    DATA,
    SITES,
    convert,
    read_ucr,
    read_xio,
    rigid_fit_2d,
    ucr_truth,
)
from run_pyshoe import load_config  # noqa: E402  (the [foot] table of a TOML job)

from insgnss.foot import FootConfig, run_foot_ins  # noqa: E402
from insgnss.strides import path_length, stance_distance  # noqa: E402


def stance_length(res) -> float:
    """Horizontal distance of the forward solution from stance to stance."""
    return stance_distance(res.forward[["east", "north"]].to_numpy(),
                           res.stillness.still.to_numpy(bool))


def _common(res, sol) -> dict:
    fwd = res.forward[["east", "north"]].to_numpy()
    lf = res.height_aiding.get("level_floor", {})
    return {"up_end": float(sol["up"].iloc[-1]), "length_raw": path_length(fwd),
            "length_stance": stance_length(res), "floor_applied": lf.get("applied", 0),
            "floor_skipped": lf.get("skipped", 0)}


def run_xio(cfg: FootConfig, forward: bool) -> list[dict]:
    out = []
    for name in ("short_walk", "long_walk"):
        imu = read_xio(name)
        res = run_foot_ins(imu, cfg, lat=SITES["xio"][0], lon=SITES["xio"][1],
                           height=SITES["xio"][2])
        sol = res.forward if forward else res.trajectory
        e, n = sol["east"].iloc[-1], sol["north"].iloc[-1]
        out.append({"track": f"xio {name.split('_')[0]}", "metric": "loop closure",
                    "horizontal": float(np.hypot(e, n)), "height_err": float(sol["up"].iloc[-1]),
                    **_common(res, sol)})
    return out


def run_ucr(cfg: FootConfig, forward: bool) -> list[dict]:
    out = []
    for side in ("left", "right"):
        imu = read_ucr(side)
        res = run_foot_ins(imu, cfg, lat=SITES["ucr"][0], lon=SITES["ucr"][1],
                           height=SITES["ucr"][2])
        sol = res.forward if forward else res.trajectory
        truth = ucr_truth(side)
        n = min(len(sol), len(truth))
        a = sol[["north", "east"]].to_numpy()[:n]  # the truth is the NED mirror of ENU
        b = truth[:n, :2]
        R, c = rigid_fit_2d(a, b)
        rms = float(np.sqrt(np.mean(np.sum((a @ R.T + c - b) ** 2, axis=1))))
        up_true = -(truth[:n, 2] - truth[0, 2])
        out.append({"track": f"ucr {side}", "metric": "RMS (fit)", "horizontal": rms,
                    "height_err": float(sol["up"].iloc[n - 1] - up_true[-1]),
                    **_common(res, sol)})
    return out


def run_pyshoe(cfg: FootConfig, forward: bool) -> list[dict]:
    """End height against the Vicon z; 2-D ARMSE from the shared scorer
    (``shared/eval/pyshoe_armse.py``, via ``scenarios/pyshoe/run_pyshoe.py``)."""
    import tempfile

    import run_pyshoe

    from insgnss.io.native import atomic_write

    out = []
    lat, lon, h = SITES["pyshoe"]
    with tempfile.TemporaryDirectory() as tmp:
        for mat in sorted((DATA / "pyshoe-vicon").glob("*.mat")):
            imu, truth = convert.to_insgnss(mat)
            res = run_foot_ins(imu, cfg, lat=lat, lon=lon, height=h)
            sol = res.forward if forward else res.trajectory
            ned = run_pyshoe.solution_ned(sol)
            atomic_write(Path(tmp) / f"{mat.stem}.csv",
                         lambda p, s=ned: s.to_csv(p, index=False, float_format="%.6f"))
            tz = truth["z"].to_numpy()
            out.append({"track": f"pyshoe {mat.stem}", "metric": "ARMSE",
                        "height_err": float(sol["up"].iloc[-1] - (tz[-1] - tz[0])),
                        "truth_dz": float(tz[-1] - tz[0]), **_common(res, sol)})
        scores = run_pyshoe.score(DATA / "pyshoe-vicon", Path(tmp))
    for r in out:
        r["horizontal"] = float(scores[r["track"].split()[1]]["ours"])
    return out


# --- simulation: each effect alone on a 100 m level walk -----------------------------------
SIM_STEPS = 72  # x 1.4 m = 100.8 m


def _sim(rate=200.0, oversample=20, **kw):
    from insgnss.simulate.gait import GaitParams, simulate_walk

    gait = {k: kw.pop(k) for k in list(kw) if k in GaitParams.__dataclass_fields__}
    return simulate_walk([{"type": "stand", "duration": 2.0},
                          {"type": "walk", "steps": SIM_STEPS, **gait},
                          {"type": "stand", "duration": 2.0}], rate=rate,
                         oversample=oversample, lat=np.radians(45.0), **kw)


def _sim_error(w, imu, cfg, still="truth", lat_offset=0.0) -> tuple[float, float]:
    """End height and horizontal error [m] of the foot INS on a simulated walk."""
    from insgnss.earth import geodetic_to_enu

    tr = w.truth
    mask = (tr.stationary.to_numpy() > 0.5) if isinstance(still, str) and still == "truth" \
        else still
    res = run_foot_ins(imu, cfg, still=mask, lat=tr.lat.iloc[0] + lat_offset,
                       lon=tr.lon.iloc[0], height=tr.height.iloc[0])
    e, n, u = geodetic_to_enu(tr.lat.values, tr.lon.values, tr.height.values,
                              tr.lat.iloc[0], tr.lon.iloc[0], tr.height.iloc[0])
    sol = res.trajectory
    return (float(sol.up.iloc[-1] - u[-1]),
            float(np.hypot(sol.east.iloc[-1] - e[-1], sol.north.iloc[-1] - n[-1])))


def _shift_mask(mask: np.ndarray, start: int, end: int) -> np.ndarray:
    """Each walking stance extended (>0) or cut (<0) by ``start`` samples before its start
    and ``end`` samples after its end (the first and last stand untouched)."""
    from insgnss.strides import still_runs

    out = mask.copy()
    for a, b in still_runs(mask)[1:-1]:
        if start > 0:
            out[a - start:a] = True
        elif start < 0:
            out[a:a - start] = False
        if end > 0:
            out[b:b + end] = True
        elif end < 0:
            out[b + end:b] = False
    return out


def sim_effects(cfg: FootConfig) -> list[dict]:
    """Height error after the 100 m walk for each effect alone (truth stance windows unless
    stated; the detector runs with VN-100 noise)."""
    from insgnss.imu import ImuErrorModel, coning_sculling, increments, increments_table
    from insgnss.simulate.sensors import simulate_imu

    rows = []

    def add(name, w, imu, config=None, **kw):
        dh, dxy = _sim_error(w, imu, config or cfg, **kw)
        rows.append({"effect": name, "dh": dh, "dxy": dxy})

    def cs(imu):
        t, dth, dv = increments(imu)
        return increments_table(t, *coning_sculling(dth, dv))

    w = _sim()
    still = w.truth.stationary.to_numpy() > 0.5
    add("exact dual increments, true stance", w, w.ideal)
    add("summed increments (coning/sculling) 200 Hz", w, w.imu)
    add("  + two-sample coning/sculling correction", w, cs(w.imu))
    for rate in (100.0, 60.0):
        wr = _sim(rate=rate, oversample=int(4000 / rate))
        add(f"summed increments {rate:.0f} Hz", wr, wr.imu)
        add("  + two-sample coning/sculling correction", wr, cs(wr.imu))
    for rate in (200.0, 100.0, 60.0):
        wr = _sim(rate=rate, oversample=int(4000 / rate), output="rates")
        add(f"rate samples (point), trapezoid, {rate:.0f} Hz", wr, wr.imu)
        add("  + two-sample coning/sculling correction", wr, cs(wr.imu))
    k = int(round(0.01 * 200))
    add("ZUPT window: late release +10 ms (toe rocker)", w, w.ideal, still=_shift_mask(still, 0, k))
    add("ZUPT window: early start -10 ms (heel rocker)", w, w.ideal, still=_shift_mask(still, k, 0))
    add("ZUPT window: late detection / early release 20 ms", w, w.ideal,
        still=_shift_mask(still, -2 * k, -2 * k))
    for pivot, lab in ((0.0, "heel"), (0.12, "sensor")):
        wl = _sim(stance_roll=np.radians(1.0), roll_pivot=pivot)
        noisy = simulate_imu(wl.ideal, ImuErrorModel(gyro_arw=6.1e-5, accel_vrw=1.4e-3), 1).imu
        add(f"stance roll 1 deg about the {lab}, detector", wl, noisy, still=None)
    wc = _sim(impact_time=0.005, heel_strike_velocity=(0.6, 0.6), accel_range=16 * 9.80665)
    wn = _sim(impact_time=0.005, heel_strike_velocity=(0.6, 0.6))
    add("hard heel strike (16 g at 200 Hz), no clipping", wn, cs(wn.imu))
    add("  same, clipped at 16 g (fine samples)", wc, cs(wc.imu))
    t, dth, dv = increments(w.ideal)
    for name, m in (("vertical accel scale 1000 ppm", np.diag([1, 1, 1.001])),
                    ("vertical accel scale 1 %", np.diag([1, 1, 1.01])),
                    ("accel y-z non-orthogonality 0.1 deg", np.eye(3) + np.radians(0.1) *
                     np.array([[0, 0, 0], [0, 0, 1], [0, 1, 0]]))):
        add(name, w, increments_table(t, dth, dv @ m.T))
    add("vertical accel scale 1 % + [foot] level_floor", w,
        increments_table(t, dth, dv @ np.diag([1, 1, 1.01]).T),
        config=replace(cfg, level_floor=True))
    G = np.radians(0.1) / 9.80665 * np.eye(3)  # gyro g-sensitivity 0.1 deg/s/g
    add("gyro g-sensitivity 0.1 deg/s/g", w, increments_table(t, dth + dv @ G.T, dv))
    add("gravity error 0.016 m/s^2 (latitude 20 deg off)", w, w.ideal,
        lat_offset=np.radians(20.0))
    noisy = simulate_imu(w.ideal, ImuErrorModel(gyro_arw=6.1e-5, accel_vrw=1.4e-3), 1).imu
    add("VN-100 noise, profile detector", w, noisy, still=None)
    tn, dthn, dvn = increments(noisy)
    add("  same + vertical accel scale 1 % + [foot] level_floor", w,
        increments_table(tn, dthn, dvn @ np.diag([1, 1, 1.01]).T),
        config=replace(cfg, level_floor=True), still=None)
    return rows


def print_sim(rows: list[dict]) -> None:
    print(f"simulated level walk, {SIM_STEPS} strides = {SIM_STEPS * 1.4:.1f} m, foot preset:")
    print(f"{'effect':52s} {'dh end [m]':>10s} {'dxy end [m]':>11s}")
    for r in rows:
        print(f"{r['effect']:52s} {r['dh']:+10.3f} {r['dxy']:11.3f}")


# --- the level floor on the real tracks (the foot INS with [foot] level_floor) -------------
def run_level_floor(cfg: FootConfig, forward: bool = False) -> list[dict]:
    """The default table twice: the foot INS without and with ``level_floor`` (and its
    per-stride height noise), on every track; rows carry ``level_floor``."""
    rows = []
    for lf in (False, True):
        rows += [{**r, "level_floor": lf} for r in run_all(replace(cfg, level_floor=lf), forward)]
    return rows


def print_level_floor(rows: list[dict]) -> None:
    off = {r["track"]: r for r in rows if not r["level_floor"]}
    print("foot INS without / with [foot] level_floor:")
    print(f"{'track':30s} {'metric':13s} {'horiz off':>9s} {'horiz on':>9s} {'dh off':>7s} "
          f"{'dh on':>7s} {'floor applied/skipped':>21s}")
    for r in rows:
        if r["level_floor"]:
            o = off[r["track"]]
            print(f"{r['track']:30s} {r['metric']:13s} {o['horizontal']:9.3f} "
                  f"{r['horizontal']:9.3f} {o['height_err']:+7.3f} {r['height_err']:+7.3f} "
                  f"{r['floor_applied']:14d}/{r['floor_skipped']}")
    for lf in (False, True):
        ps = [r for r in rows if r["track"].startswith("pyshoe") and r["level_floor"] == lf]
        if ps:
            dh = np.abs([r["height_err"] for r in ps])
            print(f"PyShoe level_floor={lf!s:5s}: mean ARMSE "
                  f"{np.mean([r['horizontal'] for r in ps]):.4f} m, |dh end| mean "
                  f"{dh.mean():.3f} max {dh.max():.3f} m, {int(np.sum(dh > 0.15))} above 0.15 m")


# --- second round: sensor effects (anti-aliasing, size effect, nonlinearity) ---------------
FINE = 20  # fine-grid samples per 200 Hz output interval (4 kHz)


def _size_effect(w, wdot, a, axis: int, r) -> np.ndarray:
    """Specific force of accelerometer ``axis`` at offset ``r`` [m] from the gyro point:
    ``f_i + [w' x r + w x (w x r)]_i`` (body frame)."""
    acc = np.cross(wdot, r) + np.cross(w, np.cross(w, r))
    out = a.copy()
    out[:, axis] += acc[:, axis]
    return out


def _lowpass(x, fc: float, fs: float) -> np.ndarray:
    """2nd-order Butterworth low-pass (causal, as an IMU's anti-aliasing filter), started at
    the first sample's value."""
    from scipy.signal import butter, lfilter

    b, a = butter(2, fc / (0.5 * fs))
    return lfilter(b, a, x - x[0], axis=0) + x[0]


def sensor_effects_sim(cfg: FootConfig) -> list[dict]:
    """End height error of the 100.8 m level walk with one sensor effect applied on the 4 kHz
    grid before point sampling at 200 Hz (truth stance windows)."""
    from insgnss.earth import geodetic_to_enu
    from insgnss.imu import ACCEL_COLS, GYRO_COLS, rates_table

    rate = 200.0
    fine = _sim(rate=rate * FINE, oversample=1, output="rates")
    w = fine.imu[GYRO_COLS].to_numpy()
    a = fine.imu[ACCEL_COLS].to_numpy()
    t = np.asarray(fine.imu.index, float)
    wdot = np.gradient(w, t, axis=0)
    tr = fine.truth.iloc[::FINE]
    still = tr.stationary.to_numpy() > 0.5
    site = (tr.lat.iloc[0], tr.lon.iloc[0], tr.height.iloc[0])
    e, n, u = geodetic_to_enu(tr.lat.values, tr.lon.values, tr.height.values, *site)
    rows = []

    def add(name, wf, af):
        imu = rates_table(t[::FINE], wf[::FINE], af[::FINE])
        sol = run_foot_ins(imu, cfg, still=still, lat=site[0], lon=site[1],
                           height=site[2]).trajectory
        rows.append({"effect": name, "dh": float(sol.up.iloc[-1] - u[-1]),
                     "dxy": float(np.hypot(sol.east.iloc[-1] - e[-1], sol.north.iloc[-1] - n[-1]))})

    fs = rate * FINE
    add("point rate samples, no effect", w, a)
    for fc in (100.0, 50.0, 20.0):
        add(f"anti-aliasing {fc:.0f} Hz on gyro and accel", _lowpass(w, fc, fs), _lowpass(a, fc, fs))
        add(f"  accel only {fc:.0f} Hz (gyro leads)", w, _lowpass(a, fc, fs))
        add(f"  gyro only {fc:.0f} Hz (gyro lags)", _lowpass(w, fc, fs), a)
    for mm in (1.0, 3.0):
        r = mm * 1e-3
        add(f"size effect: y accel {mm:.0f} mm up", w, _size_effect(w, wdot, a, 1, (0, 0, r)))
        add(f"size effect: z accel {mm:.0f} mm forward", w, _size_effect(w, wdot, a, 2, (0, r, 0)))
        add(f"size effect: z accel {mm:.0f} mm up", w, _size_effect(w, wdot, a, 2, (0, 0, r)))
    nw = np.linalg.norm(w, axis=1, keepdims=True)
    for k in (1e-4, 1e-3):
        add(f"gyro scale k|w|, k = {k:g} s/rad ({8 * k:.2%} at 8 rad/s)", w * (1 + k * nw), a)
    for k2 in (1e-4, 1e-3):
        add(f"accel quadratic k2 f^2, {k2 * 9.80665e3:.0f} mg/g^2", w, a + k2 * a**2)
    return rows


def _sensor_tracks():
    """The real tracks of the second round: x-io short/long, three PyShoe walks, UCR right."""
    out = {}
    for name in ("short_walk", "long_walk"):
        out[f"xio {name.split('_')[0]}"] = (read_xio(name), SITES["xio"], 0.0)
    for mat in sorted((DATA / "pyshoe-vicon").glob("2017-11-22-*.mat")):
        if mat.stem[-8:] in ("11-22-03", "11-37-47", "11-50-42"):
            imu, truth = convert.to_insgnss(mat)
            tz = truth["z"].to_numpy()
            out[f"pyshoe {mat.stem[-8:]}"] = (imu, SITES["pyshoe"], float(tz[-1] - tz[0]))
    out["ucr right"] = (read_ucr("right"), SITES["ucr"], None)
    return out


def _compensated(cfg, track, ctx, effect, size, wc, ac) -> dict:
    """One row of :func:`sensor_effects_real`: the preset on corrected rates."""
    from insgnss.detect import stance_entry_rms
    from insgnss.imu import rates_table

    t, still, site, up_true = ctx
    res = run_foot_ins(rates_table(t, wc, ac), cfg, still=still, lat=site[0], lon=site[1],
                       height=site[2])
    nu = res.innovations[["zupt_e", "zupt_n", "zupt_u"]].to_numpy()
    return {"track": track, "effect": effect, "size": size,
            "dh": float(res.trajectory.up.iloc[-1] - up_true),
            "J_mm_s": 1e3 * stance_entry_rms(nu, still)}


def sensor_effects_real(cfg: FootConfig) -> list[dict]:
    """Each effect *compensated* on the real tracks over a range of sizes, with the preset's
    stance windows: end height error and J, the RMS ZUPT innovation at stance entry."""
    from insgnss.detect import detect_arrays, imu_rates

    rows = []
    for track, (imu, site, dz_true) in _sensor_tracks().items():
        t, w, a = imu_rates(imu)
        fs = 1.0 / float(np.median(np.diff(t)))
        still, _, _ = detect_arrays(t, w, a, cfg.detector)
        wdot = np.gradient(w, t, axis=0)
        ctx = (t, still, site, 0.0 if dz_true is None else dz_true)
        rows.append(_compensated(cfg, track, ctx, "none", 0.0, w, a))
        for axis in range(3):
            for d in range(3):
                for mm in (-3.0, -1.0, 1.0, 3.0):
                    r = np.zeros(3)
                    r[d] = mm * 1e-3
                    rows.append(_compensated(
                        cfg, track, ctx, f"size effect: accel {'xyz'[axis]} along "
                        f"{'xyz'[d]} [mm]", mm, w, _size_effect(w, wdot, a, axis, -r)))
            for k2 in (-3e-4, -1e-4, 1e-4, 3e-4):
                ac = a.copy()
                ac[:, axis] -= k2 * a[:, axis] ** 2
                rows.append(_compensated(cfg, track, ctx, f"accel {'xyz'[axis]} quadratic "
                                         "[1/(m/s^2)]", k2, w, ac))
        nw = np.linalg.norm(w, axis=1, keepdims=True)
        for k in (-3e-3, -1e-3, 1e-3, 3e-3):
            rows.append(_compensated(cfg, track, ctx, "gyro scale k|w| [s/rad]", k,
                                     w / (1 + k * nw), a))
        for frac in (0.4, 0.25, 0.15, 0.1):
            fc = frac * fs
            rows.append(_compensated(cfg, track, ctx, "accel low-passed [Hz]", fc, w,
                                     _lowpass(a, fc, fs)))
            rows.append(_compensated(cfg, track, ctx, "gyro low-passed [Hz]", fc,
                                     _lowpass(w, fc, fs), a))
    return rows


def print_sensor(sim: list[dict], real: list[dict]) -> None:
    print("simulated level walk, 200 Hz point samples, one sensor effect:")
    for r in sim:
        print(f"  {r['effect']:52s} dh {r['dh']:+8.3f} m  dxy {r['dxy']:7.3f} m")
    print("real tracks, effect compensated (end height error [m], J [mm/s]):")
    for r in real:
        print(f"  {r['track']:16s} {r['effect']:42s} {r['size']:+10.4g}  dh {r['dh']:+7.3f}  "
              f"J {r['J_mm_s']:6.1f}")


# --- where in the stride the height error accrues (PyShoe, Vicon) ----------------------------
HEEL_STRIKE_SEARCH = 0.3  # s before the detected stance: the heel strike is the |f| peak there


def _runs(still: np.ndarray) -> list[tuple[int, int]]:
    """Still runs as (first, one past last) sample indices."""
    d = np.diff(np.r_[0, still.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def stride_phases(res, imu, truth_z: np.ndarray) -> dict:
    """Height error of the forward solution split by gait phase [m per stride].

    The Vicon marker sits at an unknown body offset ``r`` from the IMU, so its height differs
    from the IMU's by ``[C r]_up``; ``r`` is fitted by least squares over the swings
    (``z_vicon - up_ins = [C(t) r]_up + const`` per swing, three unknowns for the trial) and
    the truth of the IMU point is ``z_vicon - [C r]_up``. Phases of a stride: stance release
    -> heel strike (the peak of ``|f|`` in the last 0.3 s before the next stance) -> first
    sample of the next stance -> release.
    """
    from foot_loading import imu_point_truth

    d = imu_point_truth(res, truth_z)
    t, up, runs, swings, r = d["t"], d["up"], d["runs"], d["swings"], d["r"]
    err = up - d["z"]
    fn = np.linalg.norm(imu[["accel_x", "accel_y", "accel_z"]].to_numpy(), axis=1)
    dt = float(np.median(np.diff(t)))
    rows = []
    for (a, b), (a2, _) in zip(swings[:-1], swings[1:], strict=True):
        lo = max(a, b - int(round(HEEL_STRIKE_SEARCH / dt)))
        hs = lo + int(np.argmax(fn[lo:b + 1]))
        rows.append((err[hs] - err[a], err[b] - err[hs], err[a2] - err[b], t[b] - t[hs]))
    p = np.array(rows)
    dh = np.array([up[a1] - up[b0 - 1] for (_, b0), (a1, _) in zip(runs[:-1], runs[1:], strict=True)
                   if t[a1] - t[b0 - 1] > 0.25])
    return {"marker_offset_m": r.round(4).tolist(), "strides": len(p),
            "swing_to_heel_strike": float(p[:, 0].mean()),
            "heel_strike_to_stance": float(p[:, 1].mean()),
            "stance": float(p[:, 2].mean()), "loading_s": float(p[:, 3].mean()),
            "stride_dh_median_abs": float(np.median(np.abs(dh))),
            "stride_dh_max_abs": float(np.abs(dh).max()),
            "stride_dh_over_5cm": int(np.sum(np.abs(dh) > 0.05)),
            "stride_dh_over_10cm": int(np.sum(np.abs(dh) > 0.10))}


def run_phases(cfg: FootConfig) -> list[dict]:
    lat, lon, h = SITES["pyshoe"]
    out = []
    for mat in sorted((DATA / "pyshoe-vicon").glob("2017-11-2[27]-*.mat")):
        imu, truth = convert.to_insgnss(mat)
        res = run_foot_ins(imu, cfg, lat=lat, lon=lon, height=h)
        tz = truth["z"].to_numpy() - truth["z"].iloc[0]
        out.append({"track": mat.stem, "height_err": float(res.forward["up"].iloc[-1] - tz[-1]),
                    **stride_phases(res, imu, tz)})
    return out


def print_phases(rows: list[dict]) -> None:
    print("forward filter, height error per stride [mm]; stance-to-stance dh of the INS")
    print(f"{'trial':22s} {'dh end':>7s} {'n':>3s} {'rel->HS':>8s} {'HS->st':>7s} {'stance':>7s} "
          f"{'load ms':>7s} {'|dh| med':>8s} {'max':>6s} {'>5cm':>5s} {'>10cm':>5s}")
    for r in rows:
        print(f"{r['track']:22s} {r['height_err']:+7.3f} {r['strides']:3d} "
              f"{1e3 * r['swing_to_heel_strike']:+8.1f} {1e3 * r['heel_strike_to_stance']:+7.1f} "
              f"{1e3 * r['stance']:+7.1f} {1e3 * r['loading_s']:7.0f} "
              f"{1e3 * r['stride_dh_median_abs']:8.1f} {1e3 * r['stride_dh_max_abs']:6.0f} "
              f"{r['stride_dh_over_5cm']:5d} {r['stride_dh_over_10cm']:5d}")


# --- accelerometer-gyro timing and alignment during the foot roll (fourth round) ------------
SKEW_MS = (-8.0, -6.0, -4.0, -2.0, 0.0, 2.0, 4.0)  # assumed accelerometer lag [ms] on real data
SIZE_MM = (-6.0, -3.0, 3.0, 6.0)  # forward accelerometer above the gyro point [mm], fold A


def _accel_advanced(t: np.ndarray, a: np.ndarray, tau: float) -> np.ndarray:
    """Accelerometer that lags the gyro by ``tau`` [s] compensated: ``a_c(t) = a(t + tau)``
    (linear interpolation; ``tau < 0`` compensates an accelerometer that leads)."""
    return np.column_stack([np.interp(t + tau, t, a[:, i]) for i in range(a.shape[1])])


def _rotation(axis: int, deg: float) -> np.ndarray:
    from insgnss.attitude import rotvec_to_dcm

    v = np.zeros(3)
    v[axis] = np.radians(deg)
    return rotvec_to_dcm(v)


def skew_sim(cfg: FootConfig) -> list[dict]:
    """The simulated level walk (200 Hz point samples from the 4 kHz grid, truth stances) with
    the accelerometer delayed against the gyro, ``f_meas(t) = f(t - tau)``, its triad rotated
    rigidly against the gyro triad, or one axis displaced (size effect); end height and the
    per-stride phase split of the forward filter (:func:`stride_phases` against the simulated
    height)."""
    from insgnss.earth import geodetic_to_enu
    from insgnss.imu import ACCEL_COLS, GYRO_COLS, rates_table

    rate = 200.0
    fine = _sim(rate=rate * FINE, oversample=1, output="rates")
    w = fine.imu[GYRO_COLS].to_numpy()
    a = fine.imu[ACCEL_COLS].to_numpy()
    t = np.asarray(fine.imu.index, float)
    tr = fine.truth.iloc[::FINE]
    still = tr.stationary.to_numpy() > 0.5
    site = (tr.lat.iloc[0], tr.lon.iloc[0], tr.height.iloc[0])
    _, _, u = geodetic_to_enu(tr.lat.values, tr.lon.values, tr.height.values, *site)
    rows = []

    def add(name, af):
        imu = rates_table(t[::FINE], w[::FINE], af[::FINE])
        res = run_foot_ins(imu, cfg, still=still, lat=site[0], lon=site[1], height=site[2])
        rows.append({"effect": name, "dh": float(res.trajectory.up.iloc[-1] - u[-1]),
                     **stride_phases(res, imu, u)})

    add("none", a)
    for ms in (-5.0, -2.0, 2.0, 5.0):
        add(f"accel delayed {ms:+.0f} ms", _accel_advanced(t, a, -1e-3 * ms))
    for axis in range(3):
        for deg in (0.5, 2.0):
            add(f"accel triad rotated {deg} deg about {'xyz'[axis]}", a @ _rotation(axis, deg).T)
    wdot = np.gradient(w, t, axis=0)
    add("size effect: y accel 3 mm up", _size_effect(w, wdot, a, 1, (0, 0, 3e-3)))
    add("size effect: z accel 3 mm up", _size_effect(w, wdot, a, 2, (0, 0, 3e-3)))
    return rows


def skew_real(cfg: FootConfig) -> list[dict]:
    """An accelerometer lag compensated over :data:`SKEW_MS` on the real walks (the preset's
    own stance windows, held fixed): end height error, ``J`` and its vertical part at stance
    entry, the mean stance-to-stance height change, and on PyShoe the phase split (Vicon).
    On fold A (the first six walks of 2017-11-22) also the forward accelerometer's size effect
    compensated over :data:`SIZE_MM` (rows with ``y_accel_up_mm`` instead of ``skew_ms``)."""
    from insgnss.detect import imu_rates, stance_entry_rms
    from insgnss.imu import rates_table

    tracks = []
    for mat in sorted((DATA / "pyshoe-vicon").glob("2017-11-2[27]-*.mat")):
        imu, truth = convert.to_insgnss(mat)
        tracks.append((mat.stem, imu, SITES["pyshoe"], truth["z"].to_numpy() - truth["z"].iloc[0]))
    tracks += [(f"xio {n.split('_')[0]}", read_xio(n), SITES["xio"], None)
               for n in ("short_walk", "long_walk")]
    tracks += [(f"ucr {s}", read_ucr(s), SITES["ucr"], None) for s in ("left", "right")]
    fold_a = [n for n, *_ in tracks if n.startswith("2017-11-22")][:6]
    rows = []
    for name, imu, site, tz in tracks:
        t, w, a = imu_rates(imu)
        still = run_foot_ins(imu, cfg, lat=site[0], lon=site[1],
                             height=site[2]).stillness.still.to_numpy(bool)
        starts = np.array([s for s, _ in _runs(still)[1:]])
        for ms in SKEW_MS:
            im = rates_table(t, w, _accel_advanced(t, a, 1e-3 * ms))
            res = run_foot_ins(im, cfg, still=still, lat=site[0], lon=site[1], height=site[2])
            nu = res.innovations[["zupt_e", "zupt_n", "zupt_u"]].to_numpy()
            up = res.forward.up.to_numpy()
            row = {"track": name, "skew_ms": ms,
                   "dh": float(res.trajectory.up.iloc[-1] - (0.0 if tz is None else tz[-1])),
                   "J_mm_s": 1e3 * stance_entry_rms(nu, still),
                   "J_up_mm_s": 1e3 * float(np.sqrt(np.nanmean(nu[starts, 2] ** 2))),
                   "stride_dh_mm": 1e3 * float(np.mean(np.diff(up[starts])))}
            if tz is not None:
                row.update(stride_phases(res, im, tz))
            rows.append(row)
        if name in fold_a:  # the forward accelerometer's size effect compensated
            wdot = np.gradient(w, t, axis=0)
            for mm in SIZE_MM:
                im = rates_table(t, w, _size_effect(w, wdot, a, 1, (0.0, 0.0, -1e-3 * mm)))
                res = run_foot_ins(im, cfg, still=still, lat=site[0], lon=site[1],
                                   height=site[2])
                nu = res.innovations[["zupt_e", "zupt_n", "zupt_u"]].to_numpy()
                rows.append({"track": name, "y_accel_up_mm": mm,
                             "dh": float(res.trajectory.up.iloc[-1] - tz[-1]),
                             "J_mm_s": 1e3 * stance_entry_rms(nu, still),
                             **stride_phases(res, im, tz)})
    return rows


def print_skew(sim: list[dict], real: list[dict]) -> None:
    print("simulated level walk, 200 Hz, truth stances; per stride [mm]: release->heel strike, "
          "heel strike->stance, stance")
    for r in sim:
        print(f"  {r['effect']:40s} dh {r['dh']:+7.3f} m  {1e3 * r['swing_to_heel_strike']:+6.1f} "
              f"{1e3 * r['heel_strike_to_stance']:+6.1f} {1e3 * r['stance']:+6.1f}")
    print("real walks, accelerometer lag compensated [ms]: end height [m], J, J_up [mm/s], "
          "mean stance-to-stance dh [mm], phases [mm per stride] (PyShoe)")
    for r in real:
        if "y_accel_up_mm" in r:
            print(f"  {r['track']:22s} y accel {r['y_accel_up_mm']:+4.0f} mm above, compensated: "
                  f"dh {r['dh']:+7.3f}  J {r['J_mm_s']:6.1f}  {1e3 * r['swing_to_heel_strike']:+6.1f} "
                  f"{1e3 * r['heel_strike_to_stance']:+6.1f} {1e3 * r['stance']:+6.1f}")
            continue
        ph = (f"  {1e3 * r['swing_to_heel_strike']:+6.1f} {1e3 * r['heel_strike_to_stance']:+6.1f} "
              f"{1e3 * r['stance']:+6.1f}" if "stance" in r else "")
        print(f"  {r['track']:22s} {r['skew_ms']:+5.1f}  dh {r['dh']:+7.3f}  J {r['J_mm_s']:6.1f}  "
              f"J_up {r['J_up_mm_s']:6.1f}  {r['stride_dh_mm']:+6.1f}{ph}")


def run_all(cfg: FootConfig, forward: bool = False) -> list[dict]:
    return run_xio(cfg, forward) + run_ucr(cfg, forward) + run_pyshoe(cfg, forward)


def print_table(rows: list[dict]) -> None:
    print(f"{'track':30s} {'metric':13s} {'horiz [m]':>9s} {'dh end [m]':>10s} "
          f"{'len raw':>8s} {'len stance':>10s}")
    for r in rows:
        print(f"{r['track']:30s} {r['metric']:13s} {r['horizontal']:9.3f} {r['height_err']:10.3f} "
              f"{r['length_raw']:8.2f} {r['length_stance']:10.2f}")
    ps = [r for r in rows if r["track"].startswith("pyshoe")]
    if ps:
        dh = np.abs([r["height_err"] for r in ps])
        print(f"PyShoe {len(ps)} trials: mean ARMSE {np.mean([r['horizontal'] for r in ps]):.4f} m,"
              f" |dh end| mean {dh.mean():.3f} max {dh.max():.3f} m, "
              f"{int(np.sum(dh > 0.15))} above 0.15 m")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", type=Path, default=None, help="TOML with a [foot] table")
    p.add_argument("--forward", action="store_true", help="the causal filter, not smoothed")
    p.add_argument("--json", action="store_true")
    p.add_argument("--only", choices=["xio", "ucr", "pyshoe", "sim", "level_floor", "sensor",
                                      "phases", "skew", "loading"],
                   default=None)
    a = p.parse_args(argv)
    cfg = load_config(a.config)
    t0 = time.perf_counter()
    studies = {"sensor": (sensor_effects_sim, sensor_effects_real, print_sensor),
               "skew": (skew_sim, skew_real, print_skew)}
    if a.only == "loading":
        from foot_loading import loading_real, loading_sim, print_loading

        studies["loading"] = (loading_sim, loading_real, print_loading)
    if a.only in studies:
        on_sim, on_real, show = studies[a.only]
        sim, real = on_sim(cfg), on_real(cfg)
        if a.json:
            print(json.dumps({"simulation": sim, "real": real}, indent=1))
        else:
            show(sim, real)
        return 0
    if a.only == "sim":
        rows = sim_effects(cfg)
        print(json.dumps(rows, indent=1)) if a.json else print_sim(rows)
        return 0
    if a.only == "phases":
        rows = run_phases(cfg)
        print(json.dumps(rows, indent=1)) if a.json else print_phases(rows)
        return 0
    if a.only == "level_floor":
        rows = run_level_floor(cfg, a.forward)
        print(json.dumps(rows, indent=1)) if a.json else print_level_floor(rows)
        return 0
    if a.only:
        rows = {"xio": run_xio, "ucr": run_ucr, "pyshoe": run_pyshoe}[a.only](cfg, a.forward)
    else:
        rows = run_all(cfg, a.forward)
    if a.json:
        print(json.dumps(rows, indent=1))
    else:
        print_table(rows)
        print(f"({time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
