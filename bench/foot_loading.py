"""Fifth round of the foot INS height study (docs/zupt.md section 6): the loading phase.

On the PyShoe walks the forward filter gains +4.8 mm of height per stride between the heel
strike and the first detected stance sample (third round). Three mechanisms are tested here,
each on the real data (per-stride statistics against the Vicon height of the IMU point) and in
simulation with the effect alone (:mod:`insgnss.simulate.gait`, the 100.8 m level walk of the
other rounds, 4 kHz fine grid point-sampled at 200 Hz, truth stances):

1. **Vibration rectification** (g^2-sensitivity) of the accelerometer under the heel-strike
   shock: a DC shift ``k * <f_hp,i^2>`` on each axis ``i`` (``f_hp`` the specific force above
   20 Hz). The height it makes in the loading phase is ``k g X`` with
   ``X = sum_i integral C_up,i(t) (f_hp,i / g)^2 (t_stance - t) dt`` [s^2]; the per-stride climb
   is regressed on ``X`` and on the shock energy ``integral |f_hp / g|^2 dt`` [g^2 s].
2. **Gyro g-sensitivity and scale factor** at heel-pitch rates: compensated on the real walks
   (the preset's stance windows held fixed) over a range of sizes, and applied in simulation.
3. **Vertical velocity at the detected stance onset**: the Vicon-differentiated vertical
   velocity of the IMU point at the first ZUPT sample of each stance, the height the IMU point
   still loses after that sample (a zero-velocity update there holds the INS while the foot
   sinks), and the height the stance ZUPT adds to the forward solution.

Also printed: the INS-minus-truth vertical velocity just before and after the heel strike (the
velocity error the shock leaves) and the tilt a loading-phase attitude error would need.

Usage: ``PYTHONPATH=. python bench/bench_foot_height.py --only loading``.
"""

from __future__ import annotations

import numpy as np

G0 = 9.80665
HP_HZ = (20.0, 50.0)  # high-pass corners of the shock energy [Hz]
VEL_WINDOW = 9  # samples of the Savitzky-Golay derivative of the Vicon height (45 ms at 200 Hz)


def imu_point_truth(res, truth_z: np.ndarray) -> dict:
    """Vicon height of the IMU point and the forward solution's stride structure.

    The marker sits at a body offset ``r`` from the IMU, fitted by least squares over the
    swings (as :func:`bench_foot_height.stride_phases`); returns times, the forward height,
    vertical velocity and up row of ``C_b^l``, the truth height ``z`` of the IMU point, the
    still runs and the swings (last still sample, first still sample of the next stance).
    """
    from bench_foot_height import _runs

    from insgnss.attitude import euler_to_dcm

    sol = res.forward
    t = sol.index.to_numpy()
    up = sol["up"].to_numpy()
    C = np.array([euler_to_dcm(r, p, h) for r, p, h in
                  sol[["roll", "pitch", "heading"]].to_numpy()])
    up_row = C[:, 2]
    runs = _runs(res.stillness.still.to_numpy(bool))
    swings = [(b0 - 1, a1) for (_, b0), (a1, _) in zip(runs[:-1], runs[1:], strict=True)
              if t[a1] - t[b0 - 1] > 0.25]  # detector splits inside one stance are no swing
    A = np.concatenate([up_row[a:b + 1] - up_row[a] for a, b in swings])
    y = np.concatenate([(truth_z[a:b + 1] - truth_z[a]) - (up[a:b + 1] - up[a])
                        for a, b in swings])
    r = np.linalg.lstsq(A, y, rcond=None)[0]
    return {"t": t, "up": up, "vel_u": sol["vel_u"].to_numpy(), "up_row": up_row, "C": C,
            "z": truth_z - up_row @ r, "runs": runs, "swings": swings, "r": r}


def loading_strides(res, imu, truth_z: np.ndarray, truth_xy: np.ndarray | None = None
                    ) -> list[dict]:
    """Per-stride quantities of the loading phase (heel strike -> first stance sample).

    ``load``: height error gained there [m]; ``X20``, ``X50``: the rectification regressor
    [s^2] at the two high-pass corners; ``E20``, ``E50``: shock energy [g^2 s]; ``v_onset``:
    truth vertical velocity of the IMU point at the first ZUPT sample [m/s]; ``sink``: the
    truth height the IMU point still loses after it (to its lowest point in the stance) [m];
    ``stance``: height error gained over the stance [m]; ``settle``: the part of it gained
    until the IMU point's lowest point; ``dv_pre``, ``dv_post``: mean
    INS-minus-truth vertical velocity 20-100 ms before and 50-150 ms after the heel strike,
    relative to the release [m/s]; ``dvh``: horizontal velocity change over the loading phase
    [m/s]; ``dpitch``: rotation angle over it [rad]. With ``truth_xy`` (the Vicon horizontal
    position, rotated onto the INS east/north by a 2-D rigid fit of the IMU point) also the
    forward (along the stride) velocity error before and after the heel strike (``dvf_pre``,
    ``dvf_post``) and, for the swing (release + 50 ms -> heel strike - 50 ms) and the loading
    phase, the sums ``sum v_ins v_truth`` and ``sum v_ins^2`` of the forward and vertical
    velocities relative to the release (``{sw,ld}_{f,u}_{it,ii}``): their ratio is the slope
    of the truth on the INS velocity.
    """
    from bench_foot_height import HEEL_STRIKE_SEARCH
    from scipy.signal import butter, savgol_filter, sosfiltfilt

    p = imu_point_truth(res, truth_z)
    t, up, vu, C3, z = p["t"], p["up"], p["vel_u"], p["up_row"], p["z"]
    dt = float(np.median(np.diff(t)))
    vt = savgol_filter(z, VEL_WINDOW, 3, deriv=1, delta=dt)
    err, ev = up - z, vu - vt
    f = imu[["accel_x", "accel_y", "accel_z"]].to_numpy()
    w = imu[["gyro_x", "gyro_y", "gyro_z"]].to_numpy()
    fn = np.linalg.norm(f, axis=1)
    fhp = {fc: sosfiltfilt(butter(2, fc, "highpass", fs=1 / dt, output="sos"), f, axis=0) / G0
           for fc in HP_HZ}
    sol = res.forward
    vh = sol[["vel_e", "vel_n"]].to_numpy()
    k20, k100, k50, k150 = (int(round(s / dt)) for s in (0.02, 0.1, 0.05, 0.15))
    if truth_xy is not None:
        from foot_data import rigid_fit_2d

        xy = truth_xy - p["C"][:, :2, :] @ p["r"]
        Rf, cf = rigid_fit_2d(xy, sol[["east", "north"]].to_numpy())
        xy = xy @ Rf.T + cf
        vxy_t = savgol_filter(xy, VEL_WINDOW, 3, deriv=1, delta=dt, axis=0)
    out = []
    for (a, b), (a2, _) in zip(p["swings"][:-1], p["swings"][1:], strict=True):
        lo = max(a, b - int(round(HEEL_STRIKE_SEARCH / dt)))
        hs = lo + int(np.argmax(fn[lo:b + 1]))
        seg = slice(hs, b + 1)
        lever = t[b] - t[seg]
        row = {"load": err[b] - err[hs], "stance": err[a2] - err[b], "T": t[b] - t[hs],
               "v_onset": vt[b], "sink": z[b] - z[b:a2 + 1].min(),
               "settle": err[b + int(np.argmin(z[b:a2 + 1]))] - err[b],
               "truth_descent": z[hs] - z[b], "ins_descent": up[hs] - up[b],
               "dvh": float(np.linalg.norm(vh[b] - vh[hs])),
               "dpitch": float(np.sum(np.linalg.norm(w[seg], axis=1)) * dt),
               "peak_g": fn[hs] / G0}
        for fc, x in fhp.items():
            row[f"X{fc:.0f}"] = float(np.sum(np.sum(C3[seg] * x[seg] ** 2, axis=1) * lever) * dt)
            row[f"E{fc:.0f}"] = float(np.sum(x[seg] ** 2) * dt)
        if hs - k100 > a and hs + k150 < len(t):
            row["dv_pre"] = float(np.mean(ev[hs - k100:hs - k20]) - ev[a])
            row["dv_post"] = float(np.mean(ev[hs + k50:hs + k150]) - ev[a])
            row["dv_step"] = row["dv_post"] - row["dv_pre"]
            row["v_impact"] = float(np.mean(vt[hs - k100:hs - k20]))
        if truth_xy is not None and hs - k100 > a and hs + k150 < len(t):
            d = xy[a2] - xy[a]
            d = d / np.linalg.norm(d)
            fi, ft = vh @ d - vh[a] @ d, vxy_t @ d - vxy_t[a] @ d
            ef = fi - ft
            row["dvf_pre"] = float(np.mean(ef[hs - k100:hs - k20]))
            row["dvf_post"] = float(np.mean(ef[hs + k50:hs + k150]))
            row["vf_truth_pre"] = float(np.mean(ft[hs - k100:hs - k20]))
            row["vf_truth_post"] = float(np.mean(ft[hs + k50:hs + k150]))
            row["vu_truth_post"] = float(np.mean(vt[hs + k50:hs + k150]))
            ui, ut = vu - vu[a], vt - vt[a]
            for ph, sl in (("sw", slice(a + k50, hs - k50)), ("ld", slice(hs + 2, b))):
                for c, (x_i, x_t) in (("f", (fi, ft)), ("u", (ui, ut))):
                    row[f"{ph}_{c}_it"] = float(np.sum(x_i[sl] * x_t[sl]))
                    row[f"{ph}_{c}_ii"] = float(np.sum(x_i[sl] ** 2))
        out.append(row)
    return out


def stride_climb_vs_shock(res, imu) -> dict:
    """Truth-free form of test 1 for any level walk: the forward solution's height change
    from the start of one stance to the start of the next (on a level floor, the INS error of
    that stride) against the shock energy of its loading phase (high-pass at 20 Hz, or at a
    quarter of the rate below 80 Hz). Returns the correlation, the number of strides, the mean
    climb [m] and the mean energy [g^2 s]."""
    from bench_foot_height import HEEL_STRIKE_SEARCH, _runs
    from scipy.signal import butter, sosfiltfilt

    t = res.forward.index.to_numpy()
    up = res.forward["up"].to_numpy()
    dt = float(np.median(np.diff(t)))
    fc = min(20.0, 0.25 / dt)
    f = imu[["accel_x", "accel_y", "accel_z"]].to_numpy()
    fn = np.linalg.norm(f, axis=1)
    fhp = sosfiltfilt(butter(2, fc, "highpass", fs=1 / dt, output="sos"), f, axis=0) / G0
    runs = [(s0, e0) for s0, e0 in _runs(res.stillness.still.to_numpy(bool))]
    starts = [s0 for (s0, _), (_, e_prev) in zip(runs[1:], runs[:-1], strict=True)
              if t[s0] - t[e_prev - 1] > 0.25]
    dh, en = [], []
    for b0, b1 in zip(starts[:-1], starts[1:], strict=True):
        lo = max(b0, b1 - int(round(HEEL_STRIKE_SEARCH / dt)))
        hs = lo + int(np.argmax(fn[lo:b1 + 1]))
        dh.append(up[b1] - up[b0])
        en.append(float(np.sum(fhp[hs:b1 + 1] ** 2) * dt))
    dh, en = np.array(dh), np.array(en)
    return {"r": float(np.corrcoef(dh, en)[0, 1]), "strides": len(dh), "hp_hz": fc,
            "climb_mm": 1e3 * float(dh.mean()), "E_g2s": float(en.mean())}


def _corr(x, y, groups) -> tuple[float, float, float]:
    """Pooled, within-trial (trial means removed) and across-trial (trial means) correlation."""
    x, y, g = np.asarray(x, float), np.asarray(y, float), np.asarray(groups)
    xw, yw = x.copy(), y.copy()
    xm, ym = [], []
    for k in np.unique(g):
        m = g == k
        xw[m] -= x[m].mean()
        yw[m] -= y[m].mean()
        xm.append(x[m].mean())
        ym.append(y[m].mean())
    return (float(np.corrcoef(x, y)[0, 1]), float(np.corrcoef(xw, yw)[0, 1]),
            float(np.corrcoef(xm, ym)[0, 1]))


def summarize(trials: dict[str, list[dict]]) -> dict:
    """Pooled statistics of :func:`loading_strides` over the trials (module docstring)."""
    rows = [r for v in trials.values() for r in v]
    g = [k for k, v in trials.items() for _ in v]
    col = {k: np.array([r.get(k, np.nan) for r in rows]) for k in rows[0]}
    y = col["load"]
    out = {"trials": len(trials), "strides": len(rows), "load_mm": 1e3 * float(y.mean()),
           "stance_mm": 1e3 * float(col["stance"].mean()), "T_ms": 1e3 * float(col["T"].mean())}
    for k in ("E20", "E50", "X20", "X50", "peak_g", "dpitch", "truth_descent", "v_onset"):
        out[f"r_{k}"] = _corr(col[k], y, g)
    for fc in HP_HZ:
        x = col[f"X{fc:.0f}"]
        k = float(np.sum(x * y) / np.sum(x * x)) / G0  # load = k g X, through zero [1/g]
        out[f"vre_needed_mg_per_g2_{fc:.0f}Hz"] = 1e3 * k
        out[f"vre_r2_{fc:.0f}Hz"] = 1.0 - float(np.sum((y - k * G0 * x) ** 2) /
                                               np.sum((y - y.mean()) ** 2))
        out[f"E{fc:.0f}_g2s"] = float(np.mean(col[f"E{fc:.0f}"]))
    v = col["v_onset"]
    out["v_onset_mm_s"] = [1e3 * float(np.percentile(v, q)) for q in (10, 50, 90)]
    out["sink_mm"] = [1e3 * float(np.percentile(col["sink"], q)) for q in (10, 50, 90)]
    out["sink_mean_mm"] = 1e3 * float(col["sink"].mean())
    out["r_sink_load"] = _corr(col["sink"], y, g)
    out["settle_mm"] = 1e3 * float(col["settle"].mean())
    ok = np.isfinite(col["dv_pre"])
    out["dv_pre_mm_s"] = 1e3 * float(np.mean(col["dv_pre"][ok]))
    out["dv_post_mm_s"] = 1e3 * float(np.mean(col["dv_post"][ok]))
    gk = np.asarray(g)[ok]
    out["r_dv_step_load"] = _corr(col["dv_step"][ok], y[ok], gk)
    out["r_dv_step_v_impact"] = _corr(col["dv_step"][ok], col["v_impact"][ok], gk)
    out["v_impact_mm_s"] = 1e3 * float(np.mean(col["v_impact"][ok]))
    if "dvf_pre" in col:
        okf = np.isfinite(col["dvf_pre"])
        out["dvf_pre_mm_s"] = 1e3 * float(np.mean(col["dvf_pre"][okf]))
        out["dvf_post_mm_s"] = 1e3 * float(np.mean(col["dvf_post"][okf]))
        dF = float(np.mean(col["vf_truth_post"][okf] - col["vf_truth_pre"][okf]))
        dU = float(np.mean(col["vu_truth_post"][okf] - col["v_impact"][okf]))
        eps = (out["dv_post_mm_s"] - out["dv_pre_mm_s"]) * 1e-3 / dF  # tilt for the up step
        out["impact_dv_truth_m_s"] = (dF, dU)
        out["tilt_for_up_step_deg"] = float(np.degrees(eps))
        out["tilt_forward_step_mm_s"] = -1e3 * eps * dU
        for ph in ("sw", "ld"):
            for c in ("f", "u"):
                out[f"slope_{ph}_{c}"] = float(np.nansum(col[f"{ph}_{c}_it"]) /
                                               np.nansum(col[f"{ph}_{c}_ii"]))
    # a tilt error eps during the loading phase gives about eps * dvh * T / 2 of height
    out["tilt_needed_deg"] = float(np.degrees(np.mean(y) / np.mean(col["dvh"] * col["T"] / 2)))
    out["dvh_m_s"] = float(col["dvh"].mean())
    out["dpitch_deg"] = float(np.degrees(col["dpitch"].mean()))
    out["descent_mm"] = (1e3 * float(col["truth_descent"].mean()),
                         1e3 * float(col["ins_descent"].mean()))
    return out


def loading_real(cfg) -> dict:
    """The 12 PyShoe walking trials of 2017-11-22: per-stride statistics (:func:`summarize`);
    on fold A (the first six) the gyro effects compensated with the preset's stances held."""
    from bench_foot_height import SITES, convert, read_ucr, read_xio, stride_phases
    from foot_data import DATA

    from insgnss.detect import imu_rates, stance_entry_rms
    from insgnss.foot import run_foot_ins
    from insgnss.imu import rates_table

    lat, lon, h = SITES["pyshoe"]
    trials, comp = {}, []
    mats = sorted((DATA / "pyshoe-vicon").glob("2017-11-22-*.mat"))
    for i, mat in enumerate(mats):
        imu, truth = convert.to_insgnss(mat)
        tz = truth["z"].to_numpy() - truth["z"].iloc[0]
        res = run_foot_ins(imu, cfg, lat=lat, lon=lon, height=h)
        trials[mat.stem] = loading_strides(res, imu, tz, truth[["x", "y"]].to_numpy())
        if i >= 6:
            continue
        t, w, a = imu_rates(imu)
        still = res.stillness.still.to_numpy(bool)
        for name, size, wc in [("none", 0.0, w), *gyro_variants(w, a, compensate=True)]:
            r2 = run_foot_ins(rates_table(t, wc, a), cfg, still=still, lat=lat, lon=lon,
                              height=h)
            nu = r2.innovations[["zupt_e", "zupt_n", "zupt_u"]].to_numpy()
            ph = stride_phases(r2, imu, tz)
            comp.append({"track": mat.stem, "effect": name, "size": size,
                         "dh": float(r2.trajectory.up.iloc[-1] - tz[-1]),
                         "load_mm": 1e3 * ph["heel_strike_to_stance"],
                         "J_mm_s": 1e3 * stance_entry_rms(nu, still)})
    shock = {}
    for i, mat in enumerate(mats):
        imu, _ = convert.to_insgnss(mat)
        res = run_foot_ins(imu, cfg, lat=lat, lon=lon, height=h)
        shock[f"pyshoe fold {'AB'[i // 6]} {mat.stem[-8:]}"] = stride_climb_vs_shock(res, imu)
    for name, imu, site in ([(f"xio {n.split('_')[0]}", read_xio(n), SITES["xio"])
                             for n in ("short_walk", "long_walk")] +
                            [(f"ucr {s}", read_ucr(s), SITES["ucr"]) for s in ("left", "right")]):
        res = run_foot_ins(imu, cfg, lat=site[0], lon=site[1], height=site[2])
        shock[name] = stride_climb_vs_shock(res, imu)
    return {"summary": summarize(trials), "gyro": comp, "shock_truth_free": shock,
            "per_trial": {k: {"load_mm": 1e3 * float(np.mean([r["load"] for r in v])),
                              "E20": float(np.mean([r["E20"] for r in v])),
                              "v_onset_mm_s": 1e3 * float(np.median([r["v_onset"] for r in v])),
                              "sink_mm": 1e3 * float(np.mean([r["sink"] for r in v]))}
                          for k, v in trials.items()}}


GSENS = np.radians(1.0) / G0  # 1 deg/s/g [rad/s per m/s^2], ten times an MPU-6000-class value
GYRO_SCALE = 0.01  # 1 %


def gyro_variants(w: np.ndarray, a: np.ndarray, compensate: bool = False):
    """``(name, size, rates)``: the heel-pitch (x, right) gyro with a g-sensitivity to the
    forward or vertical specific force, ``w_x + b f_j`` (b = +-1 deg/s/g), or a scale factor
    ``(1 + s) w_x`` (s = +-1 %); every axis's scale factor. ``compensate`` removes the effect
    from measured rates instead of adding it."""
    sgn = -1.0 if compensate else 1.0
    for j, lab in ((1, "forward"), (2, "vertical")):
        for s in (1.0, -1.0):
            wc = w.copy()
            wc[:, 0] += sgn * s * GSENS * a[:, j]
            yield f"pitch gyro g-sensitivity to {lab} f [deg/s/g]", s, wc
    for s in (GYRO_SCALE, -GYRO_SCALE):
        wc = w.copy()
        wc[:, 0] *= (1 + s) ** sgn
        yield "pitch gyro scale factor", s, wc
        yield "all gyro scale factors", s, w * (1 + s) ** sgn


def loading_sim(cfg) -> list[dict]:
    """The simulated level walk with one effect at a time on the 4 kHz grid (truth stances):
    accelerometer vibration rectification ``f_i + k LP(f_hp,i^2)`` (20 Hz high-pass, the
    rectified power low-passed at 50 Hz), the pitch gyro's g-sensitivity and scale factor;
    end height and the forward filter's phase split."""
    from bench_foot_height import FINE, _lowpass, _sim, stride_phases
    from scipy.signal import butter, sosfiltfilt

    from insgnss.earth import geodetic_to_enu
    from insgnss.foot import run_foot_ins
    from insgnss.imu import ACCEL_COLS, GYRO_COLS, rates_table

    rate = 200.0
    fine = _sim(rate=rate * FINE, oversample=1, output="rates")
    w = fine.imu[GYRO_COLS].to_numpy()
    a = fine.imu[ACCEL_COLS].to_numpy()
    t = np.asarray(fine.imu.index, float)
    fs = rate * FINE
    tr = fine.truth.iloc[::FINE]
    still = tr.stationary.to_numpy() > 0.5
    site = (tr.lat.iloc[0], tr.lon.iloc[0], tr.height.iloc[0])
    _, _, u = geodetic_to_enu(tr.lat.values, tr.lon.values, tr.height.values, *site)
    rows = []

    def add(name, size, wf, af):
        imu = rates_table(t[::FINE], wf[::FINE], af[::FINE])
        res = run_foot_ins(imu, cfg, still=still, lat=site[0], lon=site[1], height=site[2])
        rows.append({"effect": name, "size": size,
                     "dh": float(res.trajectory.up.iloc[-1] - u[-1]),
                     **stride_phases(res, imu, u)})

    add("none", 0.0, w, a)
    hp = sosfiltfilt(butter(2, 20.0, "highpass", fs=fs, output="sos"), a, axis=0) / G0
    power = np.maximum(_lowpass(hp ** 2, 50.0, fs), 0.0)  # rectified shock power [g^2]
    fine_peak = float(np.linalg.norm(a, axis=1).max() / G0)
    for k in (1.0, 10.0, 50.0):  # mg/g^2
        add(f"accel vibration rectification [mg/g^2] (shock peak {fine_peak:.1f} g)", k, w,
            a + 1e-3 * k * G0 * power)
    for name, size, wc in gyro_variants(w, a):
        add(name, size, wc, a)
    return rows


def print_loading(sim: list[dict], real: dict) -> None:
    """The tables of docs/zupt.md section 6, fifth round."""
    print("simulated level walk, 200 Hz, truth stances; per stride [mm]: release->heel strike, "
          "heel strike->stance, stance")
    for r in sim:
        print(f"  {r['effect']:52s} {r['size']:+7.3g}  dh {r['dh']:+7.3f} m "
              f"{1e3 * r['swing_to_heel_strike']:+6.1f} {1e3 * r['heel_strike_to_stance']:+6.1f} "
              f"{1e3 * r['stance']:+6.1f}")
    s = real["summary"]
    print(f"PyShoe walking, {s['trials']} trials, {s['strides']} strides: loading phase "
          f"{s['load_mm']:+.2f} mm per stride ({s['T_ms']:.0f} ms), stance {s['stance_mm']:+.2f} mm")
    print("correlation with the loading-phase climb (pooled, within trials, across trial means):")
    for k in ("E20", "E50", "X20", "X50", "peak_g", "dpitch", "truth_descent", "v_onset"):
        print(f"  {k:14s} {s['r_' + k][0]:+.2f} {s['r_' + k][1]:+.2f} {s['r_' + k][2]:+.2f}")
    for fc in HP_HZ:
        print(f"  rectification needed ({fc:.0f} Hz): {s[f'vre_needed_mg_per_g2_{fc:.0f}Hz']:+.1f} "
              f"mg/g^2, R^2 {s[f'vre_r2_{fc:.0f}Hz']:+.3f}, shock energy {s[f'E{fc:.0f}_g2s']:.4f} g^2 s")
    print(f"  truth v_up at the first ZUPT sample [mm/s] p10/p50/p90: "
          f"{'/'.join(f'{v:+.0f}' for v in s['v_onset_mm_s'])}; the IMU point still sinks "
          f"{s['sink_mean_mm']:.1f} mm (p10/p50/p90 {'/'.join(f'{v:.1f}' for v in s['sink_mm'])}),"
          f" corr. with the climb {s['r_sink_load'][0]:+.2f}; the stance ZUPT gains "
          f"{s['settle_mm']:+.1f} mm to that point, {s['stance_mm'] - s['settle_mm']:+.1f} mm after")
    print(f"  INS-truth v_up relative to the release: {s['dv_pre_mm_s']:+.1f} mm/s before, "
          f"{s['dv_post_mm_s']:+.1f} mm/s after the heel strike (truth v_up before it "
          f"{s['v_impact_mm_s']:+.0f} mm/s); step vs climb r {s['r_dv_step_load'][0]:+.2f} "
          f"{s['r_dv_step_load'][1]:+.2f} {s['r_dv_step_load'][2]:+.2f}, step vs truth v_up "
          f"{s['r_dv_step_v_impact'][0]:+.2f} {s['r_dv_step_v_impact'][1]:+.2f} "
          f"{s['r_dv_step_v_impact'][2]:+.2f}")
    if "dvf_pre_mm_s" in s:
        print(f"  INS-truth forward velocity: {s['dvf_pre_mm_s']:+.1f} mm/s before, "
              f"{s['dvf_post_mm_s']:+.1f} mm/s after the heel strike; truth on INS velocity "
              f"slope, forward / vertical: swing {s['slope_sw_f']:.3f} / {s['slope_sw_u']:.3f}, "
              f"loading {s['slope_ld_f']:.3f} / {s['slope_ld_u']:.3f}")
        print(f"  truth velocity change between the windows, forward / up: "
              f"{s['impact_dv_truth_m_s'][0]:+.3f} / {s['impact_dv_truth_m_s'][1]:+.3f} m/s; the "
              f"tilt that gives the vertical step, {s['tilt_for_up_step_deg']:+.1f} deg, gives "
              f"{s['tilt_forward_step_mm_s']:+.1f} mm/s forward")
    print(f"  loading phase: truth / INS descent {s['descent_mm'][0]:.1f} / {s['descent_mm'][1]:.1f}"
          f" mm, |dv_h| {s['dvh_m_s']:.2f} m/s, rotation {s['dpitch_deg']:.1f} deg; tilt error "
          f"needed for the climb {s['tilt_needed_deg']:.2f} deg")
    pt = real["per_trial"].values()
    print("  across trials, mean sink vs mean loading climb r "
          f"{np.corrcoef([v['sink_mm'] for v in pt], [v['load_mm'] for v in pt])[0, 1]:+.2f}")
    for k, v in real["per_trial"].items():
        print(f"  {k}  load {v['load_mm']:+5.1f} mm  E20 {v['E20']:.4f}  v_onset "
              f"{v['v_onset_mm_s']:+5.0f} mm/s  sink {v['sink_mm']:.1f} mm")
    print("truth-free: stance-to-stance height change vs loading-phase shock energy, per stride")
    for k, v in real["shock_truth_free"].items():
        print(f"  {k:26s} r {v['r']:+.2f}  n {v['strides']:3d}  climb {v['climb_mm']:+5.1f} mm  "
              f"E {v['E_g2s']:.4f} g^2 s (> {v['hp_hz']:.0f} Hz)")
    print("fold A, gyro effects compensated (stances held): end height [m], loading [mm/stride], J")
    for r in real["gyro"]:
        print(f"  {r['track']:22s} {r['effect']:46s} {r['size']:+6.3g}  dh {r['dh']:+7.3f}  "
              f"load {r['load_mm']:+5.1f}  J {r['J_mm_s']:6.1f}")
