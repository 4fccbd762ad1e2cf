"""Figures a user would put in a report or a paper (matplotlib, no global state, Agg-safe).

Every figure function returns a :class:`matplotlib.figure.Figure`; saving is the caller's
business (:func:`save_figure` writes atomically, PNG/PDF/SVG from the extension). Positions are
ENU metres about an origin that the figure names, angles in degrees, time in seconds since the
first sample of the run (the offset is in the axis label).

The report figures are built in two steps: a ``*_spec`` function turns a
:class:`insgnss.report_data.ReportData` into a :class:`FigureSpec` (panels of named series, the
data decimated for display), and :func:`render` draws it with matplotlib; the interactive page
(:mod:`insgnss.report_interactive`) draws the same specs with plotly, so both show the same
thing. Figures of the report (``REPORT_FIGURES``): position / velocity / attitude errors
against the filter's +-3 sigma (or, without a reference for the quantity, the sigmas and the
forward-minus-smoothed difference), heading and its sigma, estimated sensor errors, drift inside
outages, innovations, NIS, NEES and the track.

Decimation for display (:func:`minmax_indices`): each series is cut into buckets of equal
sample count and the minimum and maximum of every bucket are kept (plus the end points), so
spikes survive and a 720k-sample series becomes a few thousand points (``DISPLAY_POINTS``)
that look the same on a screen or a page.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from .earth import geodetic_to_enu
from .io.native import atomic_write
from .report_data import time_origin

if TYPE_CHECKING:
    from matplotlib.figure import Figure

DISPLAY_POINTS = 4000  #: points kept per series for display (min/max of DISPLAY_POINTS/2 buckets)
SOLUTION_COLORS = {"forward": "#1f77b4", "smoothed": "#d62728", "reference": "#444444"}
AXIS_COLORS = ("#1f77b4", "#2ca02c", "#9467bd")
FLAG_COLOR = "#ff7f0e"
REJECT_COLOR = "#d62728"
SIGMA_COLOR = "#7f7f7f"
OUTAGE_COLOR = "#e377c2"
#: matplotlib's qualitative colour maps "tab10" and "tab20" (one colour per outage window; the
#: specs are built without matplotlib, which only the drawing imports)
TAB10 = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
         "#7f7f7f", "#bcbd22", "#17becf")
TAB20 = ("#1f77b4", "#aec7e8", "#ff7f0e", "#ffbb78", "#2ca02c", "#98df8a", "#d62728",
         "#ff9896", "#9467bd", "#c5b0d5", "#8c564b", "#c49c94", "#e377c2", "#f7b6d2",
         "#7f7f7f", "#c7c7c7", "#bcbd22", "#dbdb8d", "#17becf", "#9edae5")
#: paper style: 9 pt text, thin lines, light grid (applied while a figure is drawn)
STYLE = {"font.size": 8.5, "axes.titlesize": 9, "axes.labelsize": 8.5, "legend.fontsize": 7.5,
         "xtick.labelsize": 8, "ytick.labelsize": 8, "axes.grid": True, "grid.alpha": 0.3,
         "grid.linewidth": 0.5, "lines.linewidth": 1.0, "axes.linewidth": 0.6,
         "legend.frameon": True, "legend.framealpha": 0.85}
WIDTH = 7.16  #: figure width [in] (two-column paper page)


# --- decimation -----------------------------------------------------------------------------
def minmax_indices(*ys: np.ndarray, n: int = DISPLAY_POINTS) -> np.ndarray:
    """Sorted indices keeping the minimum and maximum of every series in ``ys`` (same length)
    in each of ``n // (2 len(ys))`` equal buckets, and the first and last sample: at most
    ``n + 2`` indices; all indices when the series are no longer than ``n``. NaN never wins a
    bucket unless the bucket is all NaN."""
    m = len(ys[0]) if ys else 0
    if m <= n:
        return np.arange(m)
    nb = max(n // (2 * len(ys)), 1)
    size = int(np.ceil(m / nb))
    pad = nb * size - m
    keep = [np.array([0, m - 1])]
    starts = np.arange(nb) * size
    for y in ys:
        y = np.asarray(y, float)
        lo = np.concatenate([np.where(np.isnan(y), np.inf, y), np.full(pad, np.inf)])
        hi = np.concatenate([np.where(np.isnan(y), -np.inf, y), np.full(pad, -np.inf)])
        keep.append(starts + np.argmin(lo.reshape(nb, size), axis=1))
        keep.append(starts + np.argmax(hi.reshape(nb, size), axis=1))
    idx = np.unique(np.concatenate(keep))
    return idx[idx < m]


def decimate(x: np.ndarray, *ys: np.ndarray, n: int = DISPLAY_POINTS) -> tuple:
    """``(x[i], y1[i], ...)`` with the min/max-preserving indices of :func:`minmax_indices`."""
    i = minmax_indices(*ys, n=n) if ys else np.arange(len(x))
    return (np.asarray(x)[i],) + tuple(np.asarray(y)[i] for y in ys)


# --- figure description -------------------------------------------------------------------
@dataclass
class Trace:
    """One drawn element of a panel.

    ``kind``: ``line``, ``points``, ``band`` (between ``lo`` and ``hi``), ``hline`` (at ``value``),
    ``colorline`` (``x, y`` coloured by ``c``) or ``marker`` (a few labelled points).
    """

    kind: str
    x: np.ndarray | None = None
    y: np.ndarray | None = None
    lo: np.ndarray | None = None
    hi: np.ndarray | None = None
    c: np.ndarray | None = None
    value: float = 0.0
    label: str | None = None
    color: str | None = None
    width: float = 1.0
    dash: str = "solid"  # solid | dashed | dotted | dashdot
    marker: str = "o"
    size: float = 3.0
    alpha: float = 1.0


@dataclass
class Panel:
    """One axes: traces, labels, shaded outage windows, optional log scale or equal aspect."""

    traces: list = field(default_factory=list)
    title: str = ""
    xlabel: str = ""
    ylabel: str = ""
    logy: bool = False
    shade: list = field(default_factory=list)  #: (x0, x1) spans shaded as outages
    equal: bool = False
    colorbar: str | None = None  #: label of the colour scale of a ``colorline``
    scalebar: bool = False
    note: str = ""  #: text in the lower left corner (panel statistics)
    ylim: tuple | None = None
    legend: str = "figure"  #: figure (one legend for the figure) | right (beside the panel)


@dataclass
class FigureSpec:
    """A figure: ``rows x cols`` panels (row-major), a title and a caption for the report."""

    key: str
    title: str
    caption: str
    panels: list
    rows: int
    cols: int = 1
    sharex: bool = True
    row_height: float = 1.9


# --- helpers -------------------------------------------------------------------------------
def local_enu(traj: pd.DataFrame, origin: tuple[float, float, float] | None = None) -> np.ndarray:
    """(N, 3) ENU coordinates [m] of a trajectory about ``origin`` (default: first sample)."""
    lat, lon, h = (traj[c].to_numpy(float) for c in ("lat", "lon", "height"))
    o = origin if origin is not None else (lat[0], lon[0], h[0])
    return np.column_stack(geodetic_to_enu(lat, lon, h, *o))


def _tlabel(t0: float) -> str:
    return f"time - {t0:.2f} s [s]" if abs(t0) > 1e-9 else "time [s]"


def _shade(data, t0):
    return [(a - t0, b - t0) for a, b in data.windows]


# --- report figure specs ----------------------------------------------------------------------
def error_spec(data, quantity: str) -> FigureSpec | None:
    """Errors of ``quantity`` (position, velocity, attitude) against the filter's +-3 sigma,
    forward and smoothed, outages shaded, epochs outside 3 sigma flagged."""
    from .report_data import LABELS, QUANTITIES, excursions

    cols, stds, unit, scale = QUANTITIES[quantity]
    sols = [s for s in data.solutions.values()
            if s.errors is not None and all(c in s.errors.columns for c in cols)]
    if not sols:
        return None
    t0 = time_origin(data)
    panels = []
    for c, sc in zip(cols, stds, strict=True):
        for s in sols:
            e = s.errors
            t = e.index.to_numpy(float) - t0
            y = e[c].to_numpy(float) * scale
            p = Panel(title=s.name if c == cols[0] else "",
                      ylabel=f"{LABELS[c]} error [{unit}]", shade=_shade(data, t0))
            if sc in e.columns:
                sd = e[sc].to_numpy(float) * scale
                td, _, lo, hi = decimate(t, y, -3 * sd, 3 * sd)
                p.traces.append(Trace("band", x=td, lo=lo, hi=hi, color=SIGMA_COLOR, alpha=0.3,
                                      label="filter +-3 sigma"))
            td, yd = decimate(t, y)
            p.traces.append(Trace("line", x=td, y=yd, color=SOLUTION_COLORS[s.name],
                                  label=f"{s.name} error"))
            if sc in e.columns:
                x = excursions(e, c, sc)
                p.note = f"outside 3 sigma: {x['n']} epochs ({100 * x['fraction']:.1f} %)"
                if x["n"]:
                    tf, yf = decimate(t[x["mask"]], y[x["mask"]])
                    p.traces.append(Trace("points", x=tf, y=yf, color=FLAG_COLOR, marker="o",
                                          size=3, label="outside 3 sigma"))
            panels.append(p)
    for p in panels[-len(sols):]:
        p.xlabel = _tlabel(t0)
    return FigureSpec(f"{quantity}_errors", f"{quantity.capitalize()} errors",
                      f"{quantity.capitalize()} error (estimate minus reference) of each "
                      "solution with the filter's +-3 sigma band; outages shaded; orange dots "
                      "mark epochs where the error leaves the 3-sigma band.",
                      panels, rows=3, cols=len(sols))


def sigma_spec(data, quantity: str) -> FigureSpec | None:
    """The filter's 3 sigma of ``quantity`` over time, forward and smoothed (no reference)."""
    from .report_data import LABELS, QUANTITIES

    cols, stds, unit, scale = QUANTITIES[quantity]
    t0 = time_origin(data)
    panels = []
    for c, sc in zip(cols, stds, strict=True):
        p = Panel(ylabel=f"3 sigma {LABELS[c]} [{unit}]", shade=_shade(data, t0),
                  title=f"{quantity}: filter 3 sigma" if c == cols[0] else "")
        for s in data.solutions.values():
            if sc in s.table.columns:
                t = s.table.index.to_numpy(float) - t0
                td, yd = decimate(t, 3 * s.table[sc].to_numpy(float) * scale)
                p.traces.append(Trace("line", x=td, y=yd, color=SOLUTION_COLORS[s.name],
                                      label=s.name))
        if p.traces:
            panels.append(p)
    if not panels:
        return None
    panels[-1].xlabel = _tlabel(t0)
    return FigureSpec(f"{quantity}_sigma", f"{quantity.capitalize()}: filter 3 sigma",
                      f"No reference for {quantity}: the filter's 3-sigma of each component, "
                      "forward and smoothed; outages shaded.", panels, rows=len(panels))


def difference_spec(data, quantity: str) -> FigureSpec | None:
    """Forward minus smoothed ``quantity`` with ``+-3 sqrt(sigma_f^2 - sigma_s^2)`` (the
    covariance of the RTS difference is ``P_f - P_s``)."""
    from .report_data import LABELS, QUANTITIES, forward_minus_smoothed, sample_at

    if not {"forward", "smoothed"} <= set(data.solutions):
        return None
    cols, stds, unit, scale = QUANTITIES[quantity]
    d = forward_minus_smoothed(data)
    if not all(c in d.columns for c in cols):
        return None
    f = data.solutions["forward"].table
    s = sample_at(data.solutions["smoothed"].table, d.index.to_numpy(float))
    f = f.loc[s.index] if len(f) != len(s) else f
    t0 = time_origin(data)
    t = d.index.to_numpy(float) - t0
    panels = []
    for c, sc in zip(cols, stds, strict=True):
        p = Panel(ylabel=f"{LABELS[c]} [{unit}]", shade=_shade(data, t0),
                  title=f"{quantity}: forward minus smoothed" if c == cols[0] else "")
        y = d[c].to_numpy(float) * scale
        if sc in f.columns and sc in s.columns:
            sd = np.sqrt(np.maximum(f[sc].to_numpy(float) ** 2 - s[sc].to_numpy(float) ** 2,
                                    0.0)) * scale
            td, lo, hi = decimate(t, -3 * sd, 3 * sd)
            p.traces.append(Trace("band", x=td, lo=lo, hi=hi, color=SIGMA_COLOR, alpha=0.3,
                                  label="+-3 sqrt(sigma_f^2 - sigma_s^2)"))
        td, yd = decimate(t, y)
        p.traces.append(Trace("line", x=td, y=yd, color="k", label="forward - smoothed"))
        panels.append(p)
    panels[-1].xlabel = _tlabel(t0)
    return FigureSpec(f"{quantity}_difference", f"{quantity.capitalize()}: forward minus "
                      "smoothed", f"Forward minus smoothed {quantity} with the +-3-sigma band "
                      "of the difference (covariance P_forward - P_smoothed); outages shaded.",
                      panels, rows=3)


def heading_spec(data) -> FigureSpec | None:
    """Heading (0-360 deg, clockwise from north) and its 3 sigma over time."""
    t0 = time_origin(data)
    top = Panel(title="heading", ylabel="heading [deg]", shade=_shade(data, t0), ylim=(0, 360))
    bot = Panel(ylabel="3 sigma heading [deg]", xlabel=_tlabel(t0), shade=_shade(data, t0))
    ref = data.reference
    if ref is not None and "heading" in ref.columns and "attitude" in data.reference_kinds:
        t = ref.index.to_numpy(float) - t0
        td, yd = decimate(t, np.degrees(ref["heading"].to_numpy(float)) % 360.0)
        top.traces.append(Trace("points", x=td, y=yd, color=SOLUTION_COLORS["reference"],
                                size=1.5, label="reference"))
    for s in data.solutions.values():
        t = s.table.index.to_numpy(float) - t0
        td, yd = decimate(t, np.degrees(s.table["heading"].to_numpy(float)) % 360.0)
        top.traces.append(Trace("points", x=td, y=yd, color=SOLUTION_COLORS[s.name], size=1.5,
                                label=s.name))
        if "heading_std" in s.table.columns:
            td, yd = decimate(t, 3 * np.degrees(s.table["heading_std"].to_numpy(float)))
            bot.traces.append(Trace("line", x=td, y=yd, color=SOLUTION_COLORS[s.name],
                                    label=s.name))
    panels = [top] + ([bot] if bot.traces else [])
    return FigureSpec("heading", "Heading", "Heading of each solution (clockwise from north, "
                      "points so that the 0/360 deg wrap draws no vertical lines) and the "
                      "filter's 3-sigma heading; outages shaded.", panels, rows=len(panels))


def sensor_spec(data) -> FigureSpec | None:
    """Estimated IMU biases (and scale factors) per axis with +-3 sigma, forward and smoothed,
    and the simulated truth."""
    from .report_data import SENSOR_BLOCKS

    def has(sol, cols):
        return all(c in sol.table.columns for c in cols)

    blocks = [(k, v) for k, v in SENSOR_BLOCKS.items()
              if any(has(s, v[0]) for s in data.solutions.values())]
    if not blocks:
        return None
    # the solution whose band is drawn: the smoothed one unless only the forward has the states
    main = data.best if has(data.best, blocks[0][1][0]) else data.solutions["forward"]
    t0 = time_origin(data)
    panels = []
    truth = data.sensor_truth
    for key, (cols, unit, scale) in blocks:
        for c in cols:
            p = Panel(title=f"{key.replace('_', ' ')} {c[-1]}", ylabel=f"[{unit}]",
                      shade=_shade(data, t0))
            for s in data.solutions.values():
                tab = s.table
                if c not in tab.columns:
                    continue
                t = tab.index.to_numpy(float) - t0
                y = tab[c].to_numpy(float) * scale
                if s is main and f"{c}_std" in tab.columns:
                    sd = tab[f"{c}_std"].to_numpy(float) * scale
                    td, lo, hi = decimate(t, y - 3 * sd, y + 3 * sd)
                    p.traces.append(Trace("band", x=td, lo=lo, hi=hi,
                                          color=SOLUTION_COLORS[s.name], alpha=0.2,
                                          label=f"{s.name} +-3 sigma"))
                td, yd = decimate(t, y)
                p.traces.append(Trace("line", x=td, y=yd, color=SOLUTION_COLORS[s.name],
                                      width=1.2 if s is main else 0.7,
                                      dash="solid" if s is main else "dashed",
                                      label=s.name))
            span = [v for tr in p.traces if tr.kind == "band" for v in (tr.lo, tr.hi)]
            if truth is not None and c in truth.columns:
                tt = truth.index.to_numpy(float) - t0
                td, yd = decimate(tt, truth[c].to_numpy(float) * scale)
                p.traces.append(Trace("line", x=td, y=yd, color="k", dash="dotted", width=1.2,
                                      label="truth (simulation)"))
                span.append(yd)
            if span:  # the band and the truth, not the forward filter's start-up transient
                v = np.concatenate(span)
                v = v[np.isfinite(v)]
                if v.size:
                    lo, hi = np.percentile(v, [0.5, 99.5])
                    pad = 0.15 * (hi - lo) + 1e-12
                    p.ylim = (lo - pad, hi + pad)
            panels.append(p)
    for p in panels[-3:]:
        p.xlabel = _tlabel(t0)
    names = ", ".join(k.replace("_", " ") for k, _ in blocks)
    return FigureSpec("sensor_errors", "Estimated IMU biases and scale factors",
                      f"Estimated {names} per body axis (x right, y forward, z up): "
                      f"{main.name} solution with its +-3 sigma band, the other solution "
                      "dashed" + (", the simulated truth dotted" if truth is not None else "")
                      + "; outages shaded.", panels, rows=len(blocks), cols=3, row_height=1.7)


def drift_spec(data) -> FigureSpec | None:
    """Horizontal drift inside each outage with the predicted 3 sigma, and as % of the distance
    travelled since the outage start."""
    d = data.drift
    if d is None or not len(d):
        return None
    sols = list(dict.fromkeys(d["solution"]))
    panels = []
    cmap = TAB10 if len(data.windows) <= 10 else TAB20
    for row in ("horizontal", "percent"):
        for name in sols:
            ds = d[d["solution"] == name]
            kind = ds["kind"].iloc[0]
            p = Panel(title=f"{name}: {'horizontal ' + kind if row == 'horizontal' else kind} "
                      "inside outages" if row == "horizontal" else "",
                      ylabel="horizontal [m]" if row == "horizontal" else "drift [% of distance]",
                      xlabel="time since outage start [s]" if row == "percent" else "",
                      legend="right" if name == sols[-1] else "none")
            for w, g in ds.groupby("outage"):
                col = cmap[int(w) % len(cmap)]
                t = g["t_rel"].to_numpy(float)
                dist = float(np.nanmax(g["distance"].to_numpy(float)))
                if row == "horizontal":
                    p.traces.append(Trace("line", x=t, y=g["horizontal"].to_numpy(float),
                                          color=col, width=1.2,
                                          label=f"outage {int(w) + 1} ({dist:.0f} m)"))
                    p.traces.append(Trace("line", x=t, y=g["sigma3"].to_numpy(float), color=col,
                                          dash="dashed", width=0.8,
                                          label="3 sigma, predicted"
                                          if w == ds["outage"].min() else None))
                else:
                    p.traces.append(Trace("line", x=t, y=g["percent"].to_numpy(float),
                                          color=col, width=1.2))
            panels.append(p)
    return FigureSpec("outage_drift", "Drift inside outages",
                      "Top: horizontal error (or, without a reference, forward minus smoothed) "
                      "inside each GNSS outage against time since the outage start, with the "
                      "filter's predicted 3 sqrt(sigma_E^2 + sigma_N^2) dashed; the legend gives "
                      "the distance travelled in each outage. Bottom: drift (growth of the "
                      "horizontal error since the outage start) as a percentage of the distance "
                      "travelled since the outage start (from 5 m on).",
                      panels, rows=2, cols=len(sols), sharex=False, row_height=2.4)


def innovation_spec(data) -> FigureSpec | None:
    """Normalised innovations (innovation / predicted sigma) per measurement type and named
    component; rejected measurements as crosses at their normalised value."""
    from .report_data import innovation_groups

    inn = data.innovations
    if inn is None:
        return None
    t0 = time_origin(data)
    panels = []
    for ty in dict.fromkeys(inn["type"]):
        d = inn[inn["type"] == ty]
        t = d["time"].to_numpy(float) - t0
        acc = d["accepted"].to_numpy(bool) if "accepted" in d.columns else np.ones(len(d), bool)
        for title, unit, scale, comps in innovation_groups(d, ty):
            normalised = all(s is not None for _, _, s in comps)
            p = Panel(title=f"{title}: " + ("innovation / predicted sigma" if normalised else
                                            "innovation"),
                      ylabel="normalised" if normalised else f"[{unit}]" if unit else "",
                      shade=_shade(data, t0), legend="right")
            if normalised:
                p.traces += [Trace("hline", value=v, color="k", dash="dashed", width=0.6,
                                   label="+-3" if v > 0 else None) for v in (3.0, -3.0)]
            for j, (col, name, std) in enumerate(comps):
                v = d[col].to_numpy(float)
                v = v / d[std].to_numpy(float) if std else v * scale
                td, yd = decimate(t[acc], v[acc])
                p.traces.append(Trace("points", x=td, y=yd, color=AXIS_COLORS[j % 3], size=2,
                                      label=name))
                if np.any(~acc):
                    p.traces.append(Trace("points", x=t[~acc], y=v[~acc], color=REJECT_COLOR,
                                          marker="x", size=5,
                                          label=f"rejected ({int((~acc).sum())})" if j == 0
                                          else None))
            p.note = f"{len(d)} evaluated, {int((~acc).sum())} rejected"
            panels.append(p)
    if not panels:
        return None
    panels[-1].xlabel = _tlabel(t0)
    return FigureSpec("innovations", "Innovations",
                      "Innovations of every measurement type by component (east/north/up in "
                      "the navigation frame, x/y/z or right/forward/up in the body frame), "
                      "divided by their predicted sigma where the log has it; red crosses: "
                      "measurements the gate rejected, at their value.", panels,
                      rows=len(panels), row_height=1.7)


def break_gaps(t: np.ndarray, *ys: np.ndarray, factor: float = 10.0) -> tuple:
    """Insert a NaN row where ``t`` jumps by more than ``factor`` times its median step, so a
    line is not drawn across a gap (e.g. between stops)."""
    t = np.asarray(t, float)
    if t.size < 3:
        return (t,) + tuple(np.asarray(y, float) for y in ys)
    dt = np.diff(t)
    k = np.flatnonzero(dt > factor * np.median(dt)) + 1
    if not k.size:
        return (t,) + tuple(np.asarray(y, float) for y in ys)
    return (np.insert(t, k, np.nan),) + tuple(np.insert(np.asarray(y, float), k, np.nan)
                                              for y in ys)


def _moving_mean(y: np.ndarray, w: int) -> np.ndarray:
    y = np.asarray(y, float)
    ok = np.isfinite(y)
    c = np.concatenate([[0.0], np.cumsum(np.where(ok, y, 0.0))])
    n = np.concatenate([[0], np.cumsum(ok)])
    out = np.full(y.size, np.nan)
    if y.size >= w:
        cnt = n[w:] - n[:-w]
        out[w - 1:] = np.where(cnt > 0, (c[w:] - c[:-w]) / np.maximum(cnt, 1), np.nan)
    return out


def _chi2_panel(p: Panel, t, v, dof: float, window: int, accepted=None, color="#1f77b4"):
    """NEES/NIS points, the 95 % bounds of one sample and of the moving mean, the mean."""
    from .consistency import chi2_bounds
    from .report_data import CONFIDENCE

    lo1, hi1 = chi2_bounds(np.array([dof]), np.array([1]), CONFIDENCE)
    low, hiw = chi2_bounds(np.array([dof]), np.array([window]), CONFIDENCE)
    inside = np.isfinite(v) & (v >= lo1[0]) & (v <= hi1[0])
    frac = 100.0 * inside.sum() / max(np.isfinite(v).sum(), 1)
    acc = np.ones(len(v), bool) if accepted is None else accepted
    td, yd = decimate(t[acc], v[acc])
    p.traces.append(Trace("points", x=td, y=yd, color=color, size=2, label="single epoch"))
    p.note = (p.note + "; " if p.note else "") + f"{frac:.0f} % inside the 95 % bounds"
    mm = _moving_mean(v, window)
    td, yd = break_gaps(*decimate(t, mm))
    p.traces.append(Trace("line", x=td, y=yd, color="k", width=1.0,
                          label=f"moving mean of {window}"))
    p.traces.append(Trace("hline", value=float(lo1[0]), color=SIGMA_COLOR, dash="dashed", width=0.8,
                          label="95 % bounds, one epoch"))
    p.traces.append(Trace("hline", value=float(hi1[0]), color=SIGMA_COLOR, dash="dashed", width=0.8))
    p.traces.append(Trace("hline", value=float(low[0]), color="k", dash="dotted", width=0.7,
                          label=f"95 % bounds of the mean of {window}"))
    p.traces.append(Trace("hline", value=float(hiw[0]), color="k", dash="dotted", width=0.7))
    p.traces.append(Trace("hline", value=float(dof), color="k", dash="solid", width=0.4))
    p.logy = True


def nis_spec(data) -> FigureSpec | None:
    """Single-run NIS per measurement type against its chi-square bounds; the gate threshold;
    rejected measurements at their NIS."""
    from .report_data import NEES_WINDOW

    inn = data.innovations
    if inn is None or "nis" not in inn.columns:
        return None
    t0 = time_origin(data)
    panels = []
    for ty in dict.fromkeys(inn["type"]):
        d = inn[inn["type"] == ty]
        v = d["nis"].to_numpy(float)
        if not np.isfinite(v).any():
            continue
        dof = float(np.nanmedian(d["dof"].to_numpy(float)))
        t = d["time"].to_numpy(float) - t0
        acc = d["accepted"].to_numpy(bool)
        p = Panel(title=f"{ty}: NIS ({dof:g} dof)", ylabel="NIS", shade=_shade(data, t0))
        _chi2_panel(p, t, v, dof, NEES_WINDOW, acc)
        if "threshold" in d.columns and np.isfinite(d["threshold"].to_numpy(float)).any():
            p.traces.append(Trace("hline", value=float(np.nanmax(d["threshold"])),
                                  color=REJECT_COLOR, width=0.8, label="gate"))
        if np.any(~acc):
            p.traces.append(Trace("points", x=t[~acc], y=v[~acc], color=REJECT_COLOR,
                                  marker="x", size=5, label="rejected"))
            p.note += f"; {int((~acc).sum())} rejected"
        panels.append(p)
    if not panels:
        return None
    panels[-1].xlabel = _tlabel(t0)
    return FigureSpec("nis", "NIS", "Normalised innovation squared of every measurement type "
                      "(forward filter) with the two-sided 95 % chi-square bounds of one epoch "
                      "(dashed) and of the moving mean (dotted); the gate threshold in red, "
                      "rejected measurements as red crosses at their NIS.", panels,
                      rows=len(panels), row_height=1.8)


def nees_spec(data) -> FigureSpec | None:
    """Single-run NEES of the position, velocity and attitude blocks against chi-square(3)."""
    from .report_data import NEES_NAMES, NEES_WINDOW

    sols = [s for s in data.solutions.values() if s.nees is not None and len(s.nees)]
    if not sols:
        return None
    names = [q for q in NEES_NAMES if any(q in s.nees.columns for s in sols)]
    t0 = time_origin(data)
    panels = []
    for q in names:
        for s in sols:
            p = Panel(title=f"{s.name}: {q} NEES (3 dof)", ylabel="NEES", shade=_shade(data, t0),
                      note=s.nees_note if q == names[0] else "")
            if q in s.nees.columns:
                _chi2_panel(p, s.nees.index.to_numpy(float) - t0, s.nees[q].to_numpy(float), 3.0,
                            NEES_WINDOW, color=SOLUTION_COLORS[s.name])
            panels.append(p)
    for p in panels[-len(sols):]:
        p.xlabel = _tlabel(t0)
    return FigureSpec("nees", "NEES", "Normalised estimation error squared e' P^-1 e of the "
                      "position, velocity and attitude blocks at the filter epochs that have a "
                      "reference, with the 95 % chi-square(3) bounds of one epoch (dashed) and "
                      "of the moving mean (dotted). A consistent filter keeps 95 % of the "
                      "points and the mean inside.", panels, rows=len(names), cols=len(sols),
                      row_height=1.9)


def _nice_length(span: float) -> float:
    """A 1-2-5 length of about a fifth of ``span``."""
    if not span > 0:
        return 1.0
    x = span / 5.0
    e = 10 ** np.floor(np.log10(x))
    return float(min((1, 2, 5, 10), key=lambda m: abs(m * e - x)) * e)


def track_spec(data) -> FigureSpec:
    """Horizontal track: solution coloured by horizontal error (with a reference) or sigma,
    reference, outages, start and end, scale bar, origin."""
    best = data.best
    tab = best.table
    enu = local_enu(tab, data.origin)
    t = tab.index.to_numpy(float)
    p = Panel(title=f"{best.name} track", xlabel="east [m]", ylabel="north [m]", equal=True,
              scalebar=True, legend="inside")
    ref = data.reference
    if ref is not None:
        re = local_enu(ref, data.origin)
        x, y = decimate(re[:, 0], re[:, 0], re[:, 1])[1:]
        p.traces.append(Trace("line", x=x, y=y, color="#aaaaaa", width=2.5, label="reference"))
    if best.errors is not None:
        e = best.errors
        c = np.interp(t, e.index.to_numpy(float), e["horizontal"].to_numpy(float))
        p.colorbar = f"{best.name} horizontal error [m]"
    else:
        c = np.hypot(tab["east_std"].to_numpy(float), tab["north_std"].to_numpy(float)) \
            if {"east_std", "north_std"} <= set(tab.columns) else np.zeros(len(tab))
        p.colorbar = f"{best.name} horizontal sigma [m]"
    if data.windows:
        from .outages import window_index

        k = window_index(t, data.windows)
        first = True
        for w in range(len(data.windows)):
            m = np.flatnonzero(k == w)
            if m.size:
                j = m[minmax_indices(enu[m, 0], enu[m, 1], n=400)]
                p.traces.append(Trace("line", x=enu[j, 0], y=enu[j, 1], color=OUTAGE_COLOR,
                                      width=5.0, alpha=0.45,
                                      label="GNSS outage" if first else None))
                first = False
    i = minmax_indices(enu[:, 0], enu[:, 1], c)
    p.traces.append(Trace("colorline", x=enu[i, 0], y=enu[i, 1], c=c[i], width=1.6,
                          label=best.name))
    p.traces.append(Trace("marker", x=enu[:1, 0], y=enu[:1, 1], color="#2ca02c", marker="o",
                          size=7, label="start"))
    p.traces.append(Trace("marker", x=enu[-1:, 0], y=enu[-1:, 1], color="k", marker="s",
                          size=7, label="end"))
    lat0, lon0, h0 = data.origin
    p.note = (f"origin {abs(np.degrees(lat0)):.6f} {'N' if lat0 >= 0 else 'S'}, "
              f"{abs(np.degrees(lon0)):.6f} {'E' if lon0 >= 0 else 'W'}, h {h0:.1f} m")
    return FigureSpec("track", "Track", "Horizontal track in ENU metres about the origin "
                      "(first sample): the solution coloured by its horizontal error against the "
                      "reference (or, without one, by the filter's horizontal sigma), the "
                      "reference in grey, GNSS outages highlighted, start (green) and end "
                      "(black square), a scale bar.", [p], rows=1, sharex=False, row_height=5.5)


#: report figures in page order: (key, spec function, arguments)
REPORT_FIGURES = (
    ("track", track_spec, ()),
    ("position_errors", error_spec, ("position",)),
    ("velocity_errors", error_spec, ("velocity",)),
    ("attitude_errors", error_spec, ("attitude",)),
    ("position_sigma", sigma_spec, ("position",)),
    ("velocity_sigma", sigma_spec, ("velocity",)),
    ("attitude_sigma", sigma_spec, ("attitude",)),
    ("position_difference", difference_spec, ("position",)),
    ("velocity_difference", difference_spec, ("velocity",)),
    ("attitude_difference", difference_spec, ("attitude",)),
    ("heading", heading_spec, ()),
    ("sensor_errors", sensor_spec, ()),
    ("outage_drift", drift_spec, ()),
    ("innovations", innovation_spec, ()),
    ("nis", nis_spec, ()),
    ("nees", nees_spec, ()),
)


def report_specs(data) -> list[FigureSpec]:
    """The figures of the report for ``data``: errors where a reference has the quantity, else
    the sigmas and the forward-minus-smoothed difference (see the module docstring)."""
    out = []
    for _key, fn, args in REPORT_FIGURES:
        q = args[0] if args else None
        if fn is error_spec and not data.has_reference(q):
            continue
        if fn in (sigma_spec, difference_spec) and data.has_reference(q):
            continue
        spec = fn(data, *args)
        if spec is not None:
            out.append(spec)
    return out


# --- matplotlib rendering ---------------------------------------------------------------------
_DASH = {"solid": "-", "dashed": "--", "dotted": ":", "dashdot": "-."}


def mpl():
    """matplotlib, imported on the first drawing with the Agg backend unless one was chosen
    (the specifications, which the interactive page draws too, need none of it: a run without
    static figures, or whose figures are drawn by worker processes, never imports it)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot  # noqa: F401  (matplotlib.pyplot below)

    return matplotlib


def _draw(ax, p: Panel, fig):
    matplotlib = mpl()
    from matplotlib.collections import LineCollection

    if p.shade:  # every outage window in one collection (one axvspan each costs 20 ms)
        from matplotlib.collections import PolyCollection

        ab = np.asarray(p.shade, float).reshape(-1, 2)
        verts = np.stack([np.column_stack([ab[:, 0], np.zeros(len(ab))]),
                          np.column_stack([ab[:, 0], np.ones(len(ab))]),
                          np.column_stack([ab[:, 1], np.ones(len(ab))]),
                          np.column_stack([ab[:, 1], np.zeros(len(ab))])], axis=1)
        ax.add_collection(PolyCollection(verts, transform=ax.get_xaxis_transform(),
                                         facecolors=OUTAGE_COLOR, alpha=0.12, linewidths=0,
                                         zorder=0.5), autolim=False)
    for tr in p.traces:
        ls = _DASH[tr.dash]
        if tr.kind == "line":
            ax.plot(tr.x, tr.y, ls=ls, color=tr.color, lw=tr.width, alpha=tr.alpha,
                    label=tr.label)
        elif tr.kind == "points":
            ax.plot(tr.x, tr.y, ls="none", marker=tr.marker if tr.marker != "o" else ".",
                    ms=tr.size, color=tr.color, alpha=tr.alpha, label=tr.label,
                    mew=1.0 if tr.marker == "x" else 0)
        elif tr.kind == "marker":
            ax.plot(tr.x, tr.y, ls="none", marker=tr.marker, ms=tr.size, color=tr.color,
                    mec="k", mew=0.6, label=tr.label, zorder=5)
        elif tr.kind == "band":
            ax.fill_between(tr.x, tr.lo, tr.hi, color=tr.color, alpha=tr.alpha, lw=0,
                            label=tr.label)
        elif tr.kind == "hline":
            ax.axhline(tr.value, ls=ls, color=tr.color, lw=tr.width, label=tr.label)
        elif tr.kind == "colorline":
            pts = np.column_stack([tr.x, tr.y])
            seg = np.stack([pts[:-1], pts[1:]], axis=1)
            c = np.asarray(tr.c, float)
            finite = c[np.isfinite(c)]
            vmax = float(np.nanpercentile(finite, 99)) if finite.size else 1.0
            lc = LineCollection(seg, cmap="viridis", linewidths=tr.width,
                                norm=matplotlib.colors.Normalize(0.0, vmax if vmax > 0 else 1.0))
            lc.set_array(0.5 * (c[:-1] + c[1:]))
            ax.add_collection(lc)
            ax.autoscale_view()
            cb = fig.colorbar(lc, ax=ax, shrink=0.8, pad=0.02, fraction=0.04, extend="max")
            cb.set_label(p.colorbar or "")
            ax.plot([], [], color=matplotlib.colormaps["viridis"](0.6), lw=tr.width,
                    label=tr.label)
    if p.logy:
        ax.set_yscale("log")
        # minor ticks at 2 and 5 of each decade: the default 2..9 doubles the ticks a log
        # panel creates and lays out (a third of the six-panel NEES figure's drawing time)
        ax.yaxis.set_minor_locator(matplotlib.ticker.LogLocator(base=10.0, subs=(2.0, 5.0)))
    if p.ylim is not None:
        ax.set_ylim(*p.ylim)
    # a fixed title position: matplotlib's automatic one measures every y tick label of the
    # panel at each draw (a third of a figure's drawing time); nothing sits above the axes
    # but a y offset/exponent, which goes to the right, away from the left title
    ax.set_title(p.title, loc="left", y=1.0)
    ax.yaxis.set_offset_position("right")
    ax.set_xlabel(p.xlabel)
    ax.set_ylabel(p.ylabel)
    if p.equal:
        ax.set_aspect("equal", adjustable="datalim")
    if p.scalebar:
        from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

        x0, x1 = ax.get_xlim()
        L = _nice_length(x1 - x0)
        ax.add_artist(AnchoredSizeBar(ax.transData, L, f"{L:g} m", "lower right", pad=0.5,
                                      sep=3, frameon=False, size_vertical=0))
    if p.note:
        ax.text(0.01, 0.02, p.note, transform=ax.transAxes, fontsize=6.5, color="#333333",
                va="bottom", ha="left", bbox={"fc": "white", "ec": "none", "alpha": 0.7})
    h, labels = ax.get_legend_handles_labels()
    if labels and p.legend == "inside":
        ax.legend(loc="best", ncol=2 if len(labels) > 4 else 1)
    elif labels and p.legend == "right":
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), markerscale=2.0,
                  borderaxespad=0.0)


def _margins(spec: FigureSpec, n_legend: int) -> dict:
    """Fixed margins in inches (constrained layout costs more than the drawing itself)."""
    titled = any(p.title for p in spec.panels[spec.cols:])
    right = 0.15 + (1.75 if any(p.legend == "right" for p in spec.panels) else 0.0) + \
        (0.75 if any(p.colorbar for p in spec.panels) else 0.0)
    top = 0.25 + (0.22 * int(np.ceil(n_legend / 4)) if n_legend else 0.0) + \
        (0.22 if any(p.title for p in spec.panels[:spec.cols]) else 0.0)
    return {"left": 0.7, "right": right, "top": top, "bottom": 0.5,
            "hspace": 0.5 if titled or not spec.sharex else 0.12,
            "wspace": 0.75}


def render(spec: FigureSpec) -> Figure:
    """Draw a :class:`FigureSpec` with matplotlib (paper style, :data:`STYLE`)."""
    from matplotlib.figure import Figure

    with mpl().pyplot.rc_context(STYLE):
        height = spec.row_height * spec.rows + 0.8
        fig = Figure(figsize=(WIDTH, height))
        axes = fig.subplots(spec.rows, spec.cols, squeeze=False,
                            sharex="col" if spec.sharex else False)
        for k, p in enumerate(spec.panels):
            _draw(axes[k // spec.cols, k % spec.cols], p, fig)
        for k in range(len(spec.panels), spec.rows * spec.cols):
            axes[k // spec.cols, k % spec.cols].set_visible(False)
        seen = {}
        for k, p in enumerate(spec.panels):
            if p.legend == "figure":
                for h, lab in zip(*axes[k // spec.cols, k % spec.cols]
                                  .get_legend_handles_labels(), strict=True):
                    seen.setdefault(lab, h)
        m = _margins(spec, len(seen))
        ax_h = (height - m["top"] - m["bottom"] - m["hspace"] * (spec.rows - 1)) / spec.rows
        ax_w = (WIDTH - m["left"] - m["right"] - m["wspace"] * (spec.cols - 1)) / spec.cols
        fig.subplots_adjust(left=m["left"] / WIDTH, right=1 - m["right"] / WIDTH,
                            bottom=m["bottom"] / height, top=1 - m["top"] / height,
                            hspace=m["hspace"] / max(ax_h, 0.1),
                            wspace=m["wspace"] / max(ax_w, 0.1))
        if seen:
            fig.legend(list(seen.values()), list(seen), loc="upper right",
                       bbox_to_anchor=(1 - 0.1 / WIDTH, 1 - 0.05 / height),
                       ncol=min(len(seen), 4), markerscale=2.0)
        fig.suptitle(spec.title, fontsize=10, x=0.1 / WIDTH, y=1 - 0.06 / height, ha="left",
                     va="top")
    return fig


def report_figures(data) -> list[tuple[FigureSpec, Figure]]:
    """Every report figure of ``data`` as ``(spec, matplotlib Figure)``."""
    return [(s, render(s)) for s in report_specs(data)]


# one public function per report figure ------------------------------------------------------
def track_figure(data) -> Figure:
    """Track coloured by horizontal error or sigma (:func:`track_spec`)."""
    return render(track_spec(data))


def error_figure(data, quantity: str = "position") -> Figure | None:
    """Position, velocity or attitude errors against +-3 sigma (:func:`error_spec`)."""
    s = error_spec(data, quantity)
    return None if s is None else render(s)


def sigma_figure(data, quantity: str = "position") -> Figure | None:
    """The filter's 3 sigma without a reference (:func:`sigma_spec`)."""
    s = sigma_spec(data, quantity)
    return None if s is None else render(s)


def difference_figure(data, quantity: str = "position") -> Figure | None:
    """Forward minus smoothed (:func:`difference_spec`)."""
    s = difference_spec(data, quantity)
    return None if s is None else render(s)


def heading_figure(data) -> Figure | None:
    """Heading and its sigma (:func:`heading_spec`)."""
    s = heading_spec(data)
    return None if s is None else render(s)


def sensor_figure(data) -> Figure | None:
    """Estimated biases and scale factors (:func:`sensor_spec`)."""
    s = sensor_spec(data)
    return None if s is None else render(s)


def drift_figure(data) -> Figure | None:
    """Drift inside outages (:func:`drift_spec`)."""
    s = drift_spec(data)
    return None if s is None else render(s)


def innovation_figure(data) -> Figure | None:
    """Normalised innovations by named component (:func:`innovation_spec`)."""
    s = innovation_spec(data)
    return None if s is None else render(s)


def nis_figure(data) -> Figure | None:
    """NIS against chi-square bounds (:func:`nis_spec`)."""
    s = nis_spec(data)
    return None if s is None else render(s)


def nees_figure(data) -> Figure | None:
    """NEES against chi-square bounds (:func:`nees_spec`)."""
    s = nees_spec(data)
    return None if s is None else render(s)


# --- navigation overview (insgnss mechanize) ----------------------------------------------------
def navigation_figure(traj: pd.DataFrame, title: str = "") -> Figure:
    """Four panels: horizontal track, height, ENU velocity, roll/pitch/heading."""
    t = traj.index.to_numpy(float)
    enu = local_enu(traj)
    i = minmax_indices(enu[:, 0], enu[:, 1], traj["height"].to_numpy(float))
    t, enu, traj = t[i], enu[i], traj.iloc[i]
    fig, ax = mpl().pyplot.subplots(2, 2, figsize=(11, 7.5), layout="constrained")
    ax[0, 0].plot(enu[:, 0], enu[:, 1], lw=1.0)
    ax[0, 0].plot(enu[0, 0], enu[0, 1], "go", label="start")
    ax[0, 0].plot(enu[-1, 0], enu[-1, 1], "rs", label="end")
    ax[0, 0].set(xlabel="east [m]", ylabel="north [m]", title="horizontal track")
    ax[0, 0].axis("equal")
    ax[0, 0].legend(loc="best", fontsize=8)
    ax[0, 1].plot(t, traj["height"].to_numpy(float), lw=1.0)
    ax[0, 1].set(xlabel="time [s]", ylabel="ellipsoidal height [m]", title="height")
    for c, lab in zip(("vel_e", "vel_n", "vel_u"), ("east", "north", "up"), strict=True):
        ax[1, 0].plot(t, traj[c].to_numpy(float), lw=1.0, label=lab)
    ax[1, 0].set(xlabel="time [s]", ylabel="velocity [m/s]", title="ENU velocity")
    ax[1, 0].legend(fontsize=8)
    a2 = ax[1, 1].twinx()
    for c in ("roll", "pitch"):
        ax[1, 1].plot(t, np.degrees(traj[c].to_numpy(float)), lw=1.0, label=c)
    a2.plot(t, np.degrees(traj["heading"].to_numpy(float)), "k", lw=0.8, label="heading")
    ax[1, 1].set(xlabel="time [s]", ylabel="roll, pitch [deg]", title="attitude")
    a2.set_ylabel("heading [deg]")
    ax[1, 1].legend(loc="upper left", fontsize=8)
    a2.legend(loc="upper right", fontsize=8)
    for a in ax.flat:
        a.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    return fig


def save_figure(fig: Figure, path: str | os.PathLike, dpi: int = 150) -> None:
    """Save a figure atomically (format from the file extension) and close it."""
    fmt = os.path.splitext(str(path))[1].lstrip(".") or "png"
    atomic_write(path, lambda p: fig.savefig(p, dpi=dpi, format=fmt))
    mpl().pyplot.close(fig)
