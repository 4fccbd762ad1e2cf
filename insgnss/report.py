"""Static HTML report of a processing run: one self-contained page (figures embedded as PNG),
readable offline in any browser, no server and no scripts.

Sections: summary, per-outage table, track map (solution, GNSS epochs used, outage spans),
position errors against the reference with the filter's 3-sigma envelopes, drift inside each
outage, estimated IMU biases with their sigmas, normalized innovations.
"""

from __future__ import annotations

import base64
import html
import io
import os

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from .io.native import atomic_write_text  # noqa: E402
from .outages import in_windows, window_index  # noqa: E402
from .plots import local_enu  # noqa: E402


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def track_figure(result):
    sol = result.filter.smoothed if result.filter.smoothed is not None else result.filter.forward
    gnss = result.inputs.gnss
    lat0, lon0, h0 = (float(sol[c].iloc[0]) for c in ("lat", "lon", "height"))
    enu = local_enu(sol, (lat0, lon0, h0))
    fig, ax = plt.subplots(figsize=(8, 7), layout="constrained")
    ax.plot(enu[:, 0], enu[:, 1], "-", color="tab:blue", lw=1.0, label="solution")
    t = sol.index.to_numpy(float)
    if result.windows:
        k = window_index(t, result.windows)
        for w in range(len(result.windows)):
            m = k == w
            if np.any(m):
                ax.plot(enu[m, 0], enu[m, 1], "-", color="tab:red", lw=2.0,
                        label="GNSS outage" if w == 0 else None)
    if gnss is not None and len(gnss):
        g = gnss[~in_windows(gnss.index.to_numpy(float), result.windows)]
        ge = local_enu(g, (lat0, lon0, h0))
        ax.plot(ge[:, 0], ge[:, 1], ".", color="k", ms=2, label="GNSS epochs used")
    ax.set(xlabel="east [m]", ylabel="north [m]", title="track")
    ax.axis("equal")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return fig


def error_figure(result):
    ev = result.evaluation
    if not ev:
        return None
    names = [n for n in ("forward", "smoothed") if n in ev]
    fig, axes = plt.subplots(3, len(names), figsize=(6 * len(names), 8), sharex=True,
                             squeeze=False, layout="constrained")
    for j, name in enumerate(names):
        err = ev[name]["errors"]
        t = err.index.to_numpy(float) - err.index[0]
        for i, (c, s) in enumerate((("east", "east_std"), ("north", "north_std"),
                                    ("up", "up_std"))):
            a = axes[i, j]
            a.plot(t, err[c], lw=0.8, color="tab:blue", label="error")
            if s in err.columns:
                a.fill_between(t, -3 * err[s], 3 * err[s], color="tab:orange", alpha=0.25,
                               label="filter 3-sigma")
            for w0, w1 in result.windows:
                a.axvspan(w0 - err.index[0], w1 - err.index[0], color="tab:red", alpha=0.08)
            a.set_ylabel(f"{c} error [m]")
            a.grid(True, alpha=0.3)
            if i == 0:
                a.set_title(f"{name} position error vs reference")
                a.legend(fontsize=8, loc="upper right")
        axes[-1, j].set_xlabel("time since first reference epoch [s]")
    return fig


def drift_figure(result):
    ev = result.evaluation
    if not ev or not result.windows:
        return None
    fig, ax = plt.subplots(1, len(ev), figsize=(6 * len(ev), 4), squeeze=False,
                           layout="constrained")
    for j, (name, e) in enumerate(ev.items()):
        err = e["errors"]
        t = err.index.to_numpy(float)
        k = window_index(t, result.windows)
        for w, (w0, _) in enumerate(result.windows):
            m = k == w
            if np.any(m):
                ax[0, j].plot(t[m] - w0, err["horizontal"].to_numpy()[m], lw=1.0)
        ax[0, j].set(xlabel="time since outage start [s]", ylabel="horizontal error [m]",
                     title=f"{name}: drift inside each outage")
        ax[0, j].grid(True, alpha=0.3)
    return fig


def bias_figure(result):
    sol = result.filter.smoothed if result.filter.smoothed is not None else result.filter.forward
    cols = ["gyro_bias_x", "gyro_bias_y", "gyro_bias_z", "accel_bias_x", "accel_bias_y",
            "accel_bias_z"]
    if not all(c in sol.columns for c in cols):
        return None
    t = sol.index.to_numpy(float) - sol.index[0]
    step = max(1, len(t) // 4000)
    fig, ax = plt.subplots(1, 2, figsize=(12, 4), layout="constrained")
    for c in cols[:3]:
        y = np.degrees(sol[c].to_numpy()[::step]) * 3600
        ax[0].plot(t[::step], y, lw=1.0, label=c[-1])
        if f"{c}_std" in sol.columns:
            s = np.degrees(sol[f"{c}_std"].to_numpy()[::step]) * 3600
            ax[0].fill_between(t[::step], y - s, y + s, alpha=0.15)
    for c in cols[3:]:
        y = sol[c].to_numpy()[::step] / 9.80665e-3
        ax[1].plot(t[::step], y, lw=1.0, label=c[-1])
        if f"{c}_std" in sol.columns:
            s = sol[f"{c}_std"].to_numpy()[::step] / 9.80665e-3
            ax[1].fill_between(t[::step], y - s, y + s, alpha=0.15)
    ax[0].set(xlabel="time [s]", ylabel="gyro bias [deg/h]", title="gyro bias (+-1 sigma)")
    ax[1].set(xlabel="time [s]", ylabel="accelerometer bias [mg]",
              title="accelerometer bias (+-1 sigma)")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    return fig


def innovation_figure(result):
    inn = result.filter.innovations
    if inn is None or not len(inn):
        return None
    types = list(dict.fromkeys(inn["type"]))
    fig, ax = plt.subplots(len(types), 1, figsize=(10, 2.4 * len(types)), squeeze=False,
                           sharex=True, layout="constrained")
    t0 = float(inn["time"].min())
    for i, ty in enumerate(types):
        d = inn[inn["type"] == ty]
        t = d["time"].to_numpy(float) - t0
        k = 0
        while f"innov_{k}" in d.columns and f"innov_std_{k}" in d.columns:
            v = d[f"innov_{k}"].to_numpy(float) / d[f"innov_std_{k}"].to_numpy(float)
            if np.isfinite(v).any():
                ax[i, 0].plot(t, v, ".", ms=1.5, label=f"component {k}")
            k += 1
        rej = d[~d["accepted"].astype(bool)]
        if len(rej):
            ax[i, 0].plot(rej["time"].to_numpy(float) - t0, np.zeros(len(rej)), "rx", ms=4,
                          label=f"rejected ({len(rej)})")
        ax[i, 0].set(ylabel="normalized", title=f"{ty} innovations / predicted sigma")
        ax[i, 0].axhline(3, color="k", lw=0.5, ls="--")
        ax[i, 0].axhline(-3, color="k", lw=0.5, ls="--")
        ax[i, 0].grid(True, alpha=0.3)
        if ax[i, 0].get_legend_handles_labels()[0]:
            ax[i, 0].legend(fontsize=7, loc="upper right", markerscale=3)
    ax[-1, 0].set_xlabel("time [s]")
    return fig


def _table(df: pd.DataFrame) -> str:
    return df.to_html(index=False, float_format=lambda v: f"{v:.3f}", border=0,
                      classes="tab")


def _summary_rows(summary: dict) -> str:
    rows = []
    for k in ("job", "source", "complete", "imu_samples", "imu_model"):
        rows.append(f"<tr><th>{k}</th><td>{html.escape(str(summary.get(k)))}</td></tr>")
    ini = summary.get("initialization", {})
    rows.append("<tr><th>initialization</th><td>" + html.escape(
        f"{ini.get('method')} ({ini.get('heading_source')}): roll "
        f"{ini.get('roll_deg', 0):.2f}, pitch {ini.get('pitch_deg', 0):.2f}, heading "
        f"{ini.get('heading_deg', 0):.2f} deg") + "</td></tr>")
    from .job.summary import measurement_rows

    rows.append("<tr><th>measurements</th><td>" + "<br>".join(
        html.escape(r) for r in measurement_rows(summary)) + "</td></tr>")
    timing = summary.get("timing_s", {})
    rows.append("<tr><th>timing [s]</th><td>" + html.escape(
        ", ".join(f"{k} {v:.2f}" for k, v in timing.items())) + "</td></tr>")
    return "\n".join(rows)


def render_report(result) -> str:
    """The report as an HTML string."""
    s = result.summary
    parts = [f"<h1>insgnss report: {html.escape(str(s.get('job')))}</h1>",
             "<h2>Summary</h2><table class='kv'>" + _summary_rows(s) + "</table>"]
    ev = s.get("evaluation", {})
    if ev:
        rows = []
        keys = ["rms_h_m", "max_h_m", "non_outage_rms_h_m", "end_h_err_m_mean",
                "max_h_err_m_mean", "rms_h_err_m_mean"]
        for name, e in ev.items():
            rows.append({"solution": name, **{k: e.get(k, np.nan) for k in keys}})
        parts.append("<h2>Accuracy against the reference [m]</h2>" + _table(pd.DataFrame(rows)))
        for name, e in result.evaluation.items():
            if len(e["outages"]):
                parts.append(f"<h3>Outages, {name}</h3>" + _table(e["outages"]))
    figs = [("Track", track_figure), ("Position errors", error_figure),
            ("Drift inside outages", drift_figure), ("IMU biases", bias_figure),
            ("Innovations", innovation_figure)]
    for title, fn in figs:
        fig = fn(result)
        if fig is None:
            continue
        parts.append(f"<h2>{title}</h2><figure><img alt='{title}' "
                     f"src='data:image/png;base64,{_png(fig)}'/></figure>")
    style = ("body{font-family:sans-serif;max-width:1300px;margin:2em auto;color:#222}"
             "table{border-collapse:collapse;margin:0.5em 0}td,th{padding:3px 8px;"
             "border-bottom:1px solid #ddd;text-align:left}img{max-width:100%}")
    return ("<!DOCTYPE html><html><head><meta charset='utf-8'><title>insgnss report</title>"
            f"<style>{style}</style></head><body>" + "\n".join(parts) + "</body></html>\n")


def write_report(result, path: str | os.PathLike):
    """Write the HTML report atomically."""
    return atomic_write_text(path, render_report(result))
