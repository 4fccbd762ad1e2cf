"""HTML report of a processing run: a static page and an interactive page.

``report.html`` is self-contained and static (figures embedded as PNG, no scripts): it opens
offline in any browser, prints, and is what goes into an e-mail or an appendix.
``report_interactive.html`` (:mod:`insgnss.report_interactive`) holds the same summary and the
same figures as zoomable plotly charts (plotly.js embedded once, offline; map tiles only on
request when online). The static page links to it.

Page: an ``INCOMPLETE`` banner with the stop reason when the filter stopped early; the run
(job, source, insgnss version, process, IMU model, outages), the initialization, the
measurements offered / applied / rejected / recovered per type, timing, preprocessing and
autotuned parameters when present; accuracy against the reference, per-outage tables,
consistency (epochs outside 3 sigma, mean NEES / NIS); what is not shown and why; the figures of
:mod:`insgnss.plots` (``REPORT_FIGURES``) with captions; the resolved job.

``[outputs] figures = ["png", "pdf", "svg"]`` also writes every figure as ``fig_<key>.<ext>``
beside the report (vector PDF/SVG for papers).
"""

from __future__ import annotations

import base64
import html
import io
import json
import os
from pathlib import Path

import numpy as np
import pandas as pd

from .executors import fork_map, fork_workers
from .executors import usable_cores as _cores
from .io.native import atomic_write, atomic_write_text
from .report_data import (
    FIGURE_FORMATS,
    INTERACTIVE_NAME,
    NEES_NAMES,
    ReportData,
    build_report_data,
    excursion_table,
    figure_file,
    time_origin,
)

PNG_DPI = 150

STYLE = (
    "body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;max-width:1180px;"
    "margin:1.5em auto;padding:0 1em;color:#222;line-height:1.4}"
    "h1{font-size:1.5em;margin-bottom:0.2em}h2{font-size:1.2em;margin-top:1.6em;"
    "border-bottom:1px solid #ccc}h3{font-size:1.0em}"
    "table{border-collapse:collapse;margin:0.4em 0 1em 0;font-size:0.9em}"
    "td,th{padding:2px 9px;border-bottom:1px solid #e3e3e3;text-align:right;"
    "vertical-align:top}th{background:#f4f4f4}td.l,th.l{text-align:left}"
    "table.kv th{text-align:left;background:none;font-weight:600}table.kv td{text-align:left}"
    ".banner{background:#b00020;color:#fff;padding:0.8em 1em;font-size:1.1em;border-radius:4px}"
    ".banner b{font-size:1.2em}.note{color:#555;font-size:0.9em}"
    "figure{margin:1em 0 2em 0}figure img{max-width:100%;height:auto;border:1px solid #eee}"
    "figcaption{font-size:0.9em;color:#444;max-width:900px}"
    "pre{background:#f7f7f7;padding:0.6em;overflow-x:auto;font-size:0.85em}"
    "nav a{margin-right:0.8em}"
)


# --- formatting ---------------------------------------------------------------------------------
def fmt(v) -> str:
    """A value for a table cell: 4 significant digits, '-' for None/NaN, lists and dicts
    compact (never a raw Python repr)."""
    if v is None:
        return "-"
    if isinstance(v, bool | np.bool_):
        return "yes" if v else "no"
    if isinstance(v, int | np.integer):
        return f"{int(v):d}"
    if isinstance(v, float | np.floating):
        if not np.isfinite(v):
            return "-"
        a = abs(float(v))
        if 1e6 <= a < 1e15:  # time stamps (GPS seconds), sample counts: all digits
            return f"{v:.3f}".rstrip("0").rstrip(".")
        return f"{v:.4g}" if a == 0 or 1e-3 <= a < 1e6 else f"{v:.3e}"
    if isinstance(v, dict):
        return ", ".join(f"{k}: {fmt(x)}" for k, x in v.items()) or "-"
    if isinstance(v, list | tuple | np.ndarray):
        items = [fmt(x) for x in v]
        if len(items) > 8:
            items = items[:8] + [f"... ({len(v)} in all)"]
        return "[" + ", ".join(items) + "]" if items else "-"
    return str(v)


def _kv(rows: list[tuple[str, object]]) -> str:
    body = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(fmt(v))}</td></tr>"
                   for k, v in rows if v is not None)
    return f"<table class='kv'>{body}</table>"


def table_html(df: pd.DataFrame, left: tuple = ()) -> str:
    """A DataFrame as an HTML table with :func:`fmt` cells; all-NaN columns dropped."""
    if df is None or not len(df):
        return ""
    keep = [c for c in df.columns if not (df[c].dtype.kind in "fc" and df[c].isna().all())]
    df = df[keep]
    head = "".join(f"<th class='{'l' if c in left else ''}'>{html.escape(str(c))}</th>"
                   for c in df.columns)
    rows = []
    for _, r in df.iterrows():
        rows.append("".join(f"<td class='{'l' if c in left else ''}'>{html.escape(fmt(r[c]))}"
                            "</td>" for c in df.columns))
    return "<table><tr>" + head + "</tr>" + "".join(f"<tr>{r}</tr>" for r in rows) + "</table>"


def _flatten(d: dict, prefix: str = "") -> list[tuple[str, object]]:
    out = []
    for k, v in d.items():
        if isinstance(v, dict) and v and all(not isinstance(x, dict | list) for x in v.values()) \
                and len(v) <= 4:
            out.append((f"{prefix}{k}", v))
        elif isinstance(v, dict):
            out.extend(_flatten(v, f"{prefix}{k}."))
        else:
            out.append((f"{prefix}{k}", v))
    return out


def measurement_counts(summary: dict, innovations: pd.DataFrame | None = None) -> pd.DataFrame:
    """Offered / applied / rejected / recovered per measurement type, from either form of
    ``summary["measurements"]``: per type ``{"offered", "applied", "rejected", "recovered"}``, or
    the older ``{type: count}`` with ``summary["rejected"] = {type: count}`` (then applied and
    recovered come from the innovation log when it has them)."""
    meas = summary.get("measurements") or {}
    rej = summary.get("rejected") or {}
    rows = []
    fields = ["offered", "applied", "rejected", "recovered"]
    if any(isinstance(v, dict) and "unusable" in v for v in meas.values()):
        fields.append("unusable")  # epochs a model could not use (e.g. no valid fix)
    for ty, v in meas.items():
        if isinstance(v, dict):
            row = {"measurement": ty, **{k: v.get(k) for k in fields}}
        else:
            row = {"measurement": ty, "offered": int(v), "applied": None,
                   "rejected": int(rej.get(ty, 0)), "recovered": None}
            if innovations is not None and "type" in innovations.columns:
                d = innovations[innovations["type"] == ty]
                if len(d) and "accepted" in d.columns:
                    row["applied"] = int(d["accepted"].astype(bool).sum())
                if len(d) and "recovered" in d.columns:
                    row["recovered"] = int(d["recovered"].astype(bool).sum())
        rows.append(row)
    return pd.DataFrame(rows, columns=["measurement", *fields])


ACCURACY_COLUMNS = {  # summary key -> readable header
    "rms_h_m": "horizontal RMS [m]", "max_h_m": "horizontal max [m]",
    "non_outage_rms_h_m": "outside outages, horizontal RMS [m]",
    "non_outage_rms_v_m": "outside outages, vertical RMS [m]",
    "end_h_err_m_mean": "outage end error, mean [m]",
    "end_h_err_m_max": "outage end error, max [m]",
    "rms_h_err_m_mean": "in-outage RMS, mean [m]",
    "max_h_err_m_mean": "in-outage max, mean [m]",
    "n_covered": "reference epochs",
}


OUTAGE_COLUMNS = {"start": "start [s]", "end": "end [s]", "n_epochs": "reference epochs",
                  "end_h_err_m": "horizontal error at end [m]",
                  "max_h_err_m": "max horizontal [m]", "rms_h_err_m": "RMS horizontal [m]",
                  "end_v_err_m": "vertical error at end [m]", "complete": "fully covered"}


def banner_html(summary: dict) -> str:
    """The INCOMPLETE banner of a run that stopped early ('' for a complete run)."""
    if summary.get("complete", True):
        return ""
    at = summary.get("stopped_at")
    return ("<div class='banner' id='incomplete'><b>INCOMPLETE</b>: the filter stopped early"
            + (f" at t = {fmt(at)} s" if at is not None else "") + ": "
            + html.escape(str(summary.get("error") or "unknown reason"))
            + ". The trajectories, logs and figures end there.</div>")


def _version(summary: dict) -> str:
    if summary.get("version"):
        return str(summary["version"])
    from ._version import __version__

    return f"{__version__} (report writer)"


def _resolved_job(result) -> str:
    s = result.summary
    job = s.get("job_resolved")
    if job is None:
        job = {**result.job.settings, **({"simulation": result.job.simulation}
                                         if result.job.simulation else {})}
    from .io.native import jsonable

    return json.dumps(jsonable(job), indent=2, default=str)


def _outages_text(data: ReportData) -> str:
    if not data.windows:
        return "none"
    t0 = time_origin(data)
    spans = ", ".join(f"{fmt(a - t0)}-{fmt(b - t0)}" for a, b in data.windows)
    return f"{len(data.windows)}: {spans} s" + (f" (after t0 = {fmt(t0)} s)" if t0 else "")


def summary_html(result, data: ReportData) -> str:
    """Banner, summary tables, accuracy, outages, consistency and notes (shared by both
    pages)."""
    s = result.summary
    ini = s.get("initialization") or {}
    parts = [banner_html(s)]
    run = [("job", s.get("job")), ("source", s.get("source")), ("seed", s.get("seed")),
           ("platform", (s.get("platform") or {}).get("name")),
           ("insgnss version", _version(s)),
           ("process", s.get("preset") or s.get("process_model")),
           ("complete", s.get("complete")), ("IMU samples", s.get("imu_samples")),
           ("IMU model", s.get("imu_model")),
           ("GNSS outages", _outages_text(data)),
           ("reference", ", ".join(data.reference_kinds) if data.reference_kinds else "none")]
    parts.append("<h2 id='summary'>Summary</h2><h3>Run</h3>" + _kv(run))
    if s.get("input_files"):  # what reproduces the run (insgnss.job.summary.provenance)
        parts.append("<h3 id='input-files'>Input files</h3>" + table_html(pd.DataFrame(
            [{"file": f.get("path"), "bytes": f.get("bytes"), "sha256": f.get("sha256")}
             for f in s["input_files"]]), left=("file", "sha256")))
    if ini:
        parts.append("<h3>Initialization</h3>" + _kv([
            ("method", ini.get("method")), ("heading source", ini.get("heading_source")),
            ("time [s]", ini.get("time")), ("roll [deg]", ini.get("roll_deg")),
            ("pitch [deg]", ini.get("pitch_deg")), ("heading [deg]", ini.get("heading_deg"))]))
    counts = measurement_counts(s, data.innovations)
    if len(counts):
        parts.append("<h3>Measurements</h3>" + table_html(counts, left=("measurement",)))
    if s.get("heading_reinitialisations"):
        parts.append("<h3>Heading re-initialisations</h3>" + table_html(pd.DataFrame(
            [{"time [s]": ev.get("time"), "old heading [deg]": ev.get("old_heading_deg"),
              "new heading [deg]": ev.get("new_heading_deg"),
              "sigma [deg]": ev.get("heading_std_deg"), "reason": ev.get("reason")}
             for ev in s["heading_reinitialisations"]]), left=("reason",)))
    if s.get("aiding_warnings"):
        parts.append("<h3>Aiding warnings</h3>" + "".join(
            f"<p class='note'>{html.escape(str(w))}</p>" for w in s["aiding_warnings"]))
    timing = s.get("timing_s") or {}
    if timing:
        parts.append("<h3>Timing [s]</h3>" + table_html(pd.DataFrame(
            [{"stage": k, "seconds": v} for k, v in timing.items()]), left=("stage",)))
    if s.get("preprocessing"):
        parts.append("<h3>Preprocessing</h3>" + _kv(_flatten(s["preprocessing"])))
    at = s.get("autotune")
    if at and isinstance(at.get("parameters"), dict):
        ll = at.get("log_likelihood") or {}
        parts.append(
            "<h3>Self-tuned noise (maximum likelihood, docs/filter.md)</h3><p class='note'>"
            + html.escape(f"{at.get('sweeps')} sweeps, {at.get('evaluations')} filter runs; "
                          f"log-likelihood {fmt(ll.get('prior'))} with the priors, "
                          f"{fmt(ll.get('final'))} tuned. A parameter that is not observable "
                          "keeps its prior.") + "</p>"
            + table_html(pd.DataFrame([
                {"parameter": k, "value": v.get("value"), "prior": v.get("prior"),
                 "unit": v.get("unit", ""), "observable": v.get("observable"),
                 "log-lik. gain over prior": v.get("dll_prior")}
                for k, v in at["parameters"].items()]), left=("parameter", "unit")))
    elif at:
        parts.append("<h3>Autotuned parameters</h3>" + _kv(_flatten(at)))
    ev = s.get("evaluation") or {}
    if ev:
        rows = [{"solution": name, **{h: e.get(k) for k, h in ACCURACY_COLUMNS.items()}}
                for name, e in ev.items()]
        parts.append("<h2 id='accuracy'>Accuracy against the reference</h2>"
                     + table_html(pd.DataFrame(rows), left=("solution",)))
        for name, e in result.evaluation.items():
            if len(e["outages"]):
                o = e["outages"].copy()
                o["outage"] = o["outage"] + 1
                o = o.rename(columns=OUTAGE_COLUMNS)
                parts.append(f"<h3>Outages, {name}</h3>" + table_html(o))
    exc = excursion_table(data)
    if len(exc):
        parts.append("<h2 id='consistency'>Consistency</h2><p class='note'>Epochs where the "
                     "error leaves the filter's +-3 sigma (a consistent Gaussian filter: "
                     "0.27 %).</p>" + table_html(exc, left=("solution", "quantity", "component")))
    nees = [{"solution": sd.name, **{f"mean NEES {q} (3 dof)": float(np.nanmean(sd.nees[q]))
                                     for q in NEES_NAMES if q in sd.nees.columns}}
            for sd in data.solutions.values() if sd.nees is not None]
    if nees:
        parts.append("<h3>Mean NEES (expected 3)</h3>" + table_html(pd.DataFrame(nees),
                                                                     left=("solution",)))
    inn = data.innovations
    if inn is not None and "nis" in inn.columns:
        g = inn.groupby("type", sort=False)
        nis = pd.DataFrame({"measurement": list(g.groups), "dof": g["dof"].median().to_numpy(),
                            "mean NIS": g["nis"].mean().to_numpy()})
        parts.append("<h3>Mean NIS (expected: dof)</h3>" + table_html(nis,
                                                                     left=("measurement",)))
    if data.notes:
        parts.append("<h3>Not shown</h3>" + "".join(f"<p class='note'>{html.escape(n)}</p>"
                                                    for n in data.notes))
    return "\n".join(p for p in parts if p)


def _page(title: str, body: str, head_extra: str = "") -> str:
    return ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            f"<title>{html.escape(title)}</title><style>{STYLE}</style>{head_extra}</head>"
            f"<body>{body}</body></html>\n")


def render_report(result, data: ReportData | None = None, figures: list | None = None) -> str:
    """The static report as an HTML string (``figures``: ``(spec, png bytes)`` pairs; drawn
    here when not given)."""
    from .plots import render, report_specs

    data = build_report_data(result) if data is None else data
    if figures is None:
        figures = [(sp, _png_bytes(render(sp))) for sp in report_specs(data)]
    title = f"insgnss report: {data.title}"
    toc = " ".join(f"<a href='#{sp.key}'>{html.escape(sp.title)}</a>" for sp, _ in figures)
    body = [f"<h1>{html.escape(title)}</h1>",
            f"<nav><a href='{INTERACTIVE_NAME}'>interactive version (zoomable)</a> | "
            f"figures: {toc}</nav>", summary_html(result, data)]
    for sp, png in figures:
        b64 = base64.b64encode(png).decode("ascii")
        body.append(f"<h2 id='{sp.key}'>{html.escape(sp.title)}</h2><figure class='fig' "
                    f"data-key='{sp.key}'><img alt='{html.escape(sp.title)}' "
                    f"src='data:image/png;base64,{b64}'/><figcaption>{html.escape(sp.caption)}"
                    "</figcaption></figure>")
    body.append("<h2 id='job'>Resolved job</h2><details><summary>settings as run</summary><pre>"
                + html.escape(_resolved_job(result)) + "</pre></details>")
    return _page(title, "\n".join(body))


def _png_bytes(fig) -> bytes:
    buf = io.BytesIO()
    # zlib level 1: a third of the encoding time of the default (6) for 10 % larger files
    fig.savefig(buf, format="png", dpi=PNG_DPI, pil_kwargs={"compress_level": 1})
    return buf.getvalue()


#: what the figure workers draw: (specs, files), set before they are forked
_WORK: tuple | None = None


def _draw_figure(spec, files) -> bytes:
    """Draw one figure, write its files ``[(ext, path), ...]`` and return its PNG bytes."""
    from .plots import render

    fig = render(spec)
    png = _png_bytes(fig)
    fig.set_layout_engine(None)  # laid out once; further formats only draw
    for ext, path in files:
        if ext == "png":
            atomic_write(path, lambda p, b=png: Path(p).write_bytes(b))
        else:
            atomic_write(path, lambda p, e=ext: fig.savefig(p, format=e))
    return png


def _figure(i: int) -> bytes:
    """Draw figure ``i`` of :data:`_WORK` (:func:`_draw_figure`)."""
    specs, files = _WORK[:2]
    return _draw_figure(specs[i], files[i])


def figure_cost(spec) -> int:
    """Relative drawing cost of a figure: its axes (each with its ticks, labels and text,
    where matplotlib spends most of the time), its traces, and for a colour-coded line its
    colour bar (a further axes) and segment collection (the track costs as much as a
    six-panel figure)."""
    traces = [tr for p in spec.panels for tr in p.traces]
    colour = sum(getattr(tr, "kind", None) == "colorline" for tr in traces)
    return 4 * len(spec.panels) + len(traces) // 4 + 16 * colour


def figure_workers(n_figures: int) -> int:
    """Processes drawing figures besides the caller: one per further core available (at most
    3), none without ``fork`` (the workers inherit the figure descriptions, nothing is
    pickled but the PNG bytes coming back) or with fewer than 4 figures
    (:func:`insgnss.executors.fork_workers`)."""
    return fork_workers(n_figures, limit=min(3, n_figures // 2)) if n_figures >= 4 else 0


#: the figure server forked ahead of the report by :func:`start_figure_workers`:
#: ``(process, connection)``
_SERVER = None


def _warm() -> None:
    """Import matplotlib and lay out one text (font files and caches load on the first text
    drawn) and one mathtext label (a log axis's tick labels, ``10^-2``: the first one builds
    matplotlib's mathtext grammar, 0.2 s, once per process and inherited by the forked
    helpers), so that what follows only draws."""
    from matplotlib.figure import Figure

    from .plots import mpl

    mpl()
    fig = Figure(figsize=(1, 1))
    fig.text(0.5, 0.5, "0.5 m")
    fig.text(0.5, 0.2, r"$\mathdefault{10^{-2}}$")
    fig.canvas.draw()


def _figure_server(conn, parent_end) -> None:
    """The figure server: warm up, wait for ``(specs, files)`` and answer with their PNG bytes
    (:func:`_draw_figures`: this process and its forked helpers, which inherit the warm
    matplotlib); exit when the run closes the connection instead."""
    parent_end.close()
    try:
        _warm()
        specs, files = conn.recv()
    except (EOFError, OSError, KeyboardInterrupt):
        return
    try:
        conn.send(_draw_figures(specs, files))
    except (Exception, KeyboardInterrupt):  # noqa: BLE001 - the run draws the figures itself
        pass                                # and so reports the error; Ctrl-C ends the run
    finally:
        conn.close()


def start_figure_workers() -> bool:
    """Fork the process that will draw the report's figures now, before the run: it imports
    matplotlib (0.5-1 s) and loads its fonts on another core while this process reads the data
    and runs the filter. :func:`write_report` then sends it the figures (it forks its helpers
    then, warm: :func:`figure_workers`) and writes the interactive page meanwhile. None with a
    single core or without ``fork``; returns whether it started. :func:`stop_figure_workers`
    ends it (``insgnss process`` does, whatever happens)."""
    global _SERVER
    import multiprocessing

    if _SERVER is not None:
        return True
    if _cores() < 2 or "fork" not in multiprocessing.get_all_start_methods():
        return False
    ctx = multiprocessing.get_context("fork")
    here, there = ctx.Pipe()
    proc = ctx.Process(target=_figure_server, args=(there, here), name="insgnss-figures")
    proc.start()
    there.close()
    _SERVER = (proc, here)
    return True


def stop_figure_workers() -> None:
    """End the process of :func:`start_figure_workers`: a server that answered or waits for
    figures exits on the closed connection; one still warming up or drawing for a run that
    failed meanwhile is terminated after a second."""
    global _SERVER
    server, _SERVER = _SERVER, None
    if server is None:
        return
    proc, conn = server
    conn.close()
    proc.join(1.0)
    if proc.is_alive():
        proc.terminate()
        proc.join()


def _once(f):
    done = []

    def run():
        if not done:
            done.append(True)
            f()
    return run


def _draw_by_server(specs, files, while_drawing) -> list[bytes] | None:
    """The figures drawn by the process of :func:`start_figure_workers`, ``while_drawing()``
    run here meanwhile; ``None`` when no such process runs or it failed (the caller draws
    them itself, and so reports any error)."""
    if _SERVER is None:
        return None
    conn = _SERVER[1]
    try:
        conn.send((specs, files))
    except (OSError, ValueError):  # it died
        stop_figure_workers()
        return None
    try:
        if while_drawing is not None:
            while_drawing()  # its errors are the run's (an OSError here is no dead server)
        try:
            return conn.recv()
        except (EOFError, OSError):
            return None
    finally:
        stop_figure_workers()


def _draw_figures(specs, files, while_drawing=None) -> list[bytes]:
    """PNG bytes of every figure (``files[i]``: the ``(ext, path)`` to write of figure ``i``),
    drawn by this process and :func:`figure_workers` forked workers (matplotlib spends most of
    its time in Python, one figure at a time per process); ``while_drawing()`` runs here
    meanwhile. Every process takes the next figure from one shared queue, largest first
    (:func:`figure_cost`; :func:`insgnss.executors.fork_map`), so that none waits idle while
    another still has several figures to draw (a fixed split left the process with the
    sensor-error figure a second behind on the real drive). The paths are resolved here,
    before forking, so that an output set records every name in this process."""
    global _WORK

    if while_drawing is not None:
        while_drawing = _once(while_drawing)  # not again should the server fail
    pngs = _draw_by_server(specs, files, while_drawing)
    if pngs is not None:
        return pngs
    order = sorted(range(len(specs)), key=lambda i: -figure_cost(specs[i]))  # stable
    _WORK = (specs, files)
    try:
        return fork_map(lambda i: _figure(i), range(len(specs)), figure_workers(len(specs)),
                        order=order, meanwhile=while_drawing)
    finally:
        _WORK = None


def check_figure_formats(formats) -> list[str]:
    """Validated ``[outputs] figures`` list (lower case, each one of :data:`FIGURE_FORMATS`)."""
    from .errors import ConfigError

    out = []
    for f in formats or ():
        if not isinstance(f, str) or f.lower() not in FIGURE_FORMATS:
            raise ConfigError("unknown figure format", column="outputs.figures",
                              expected=f"some of {list(FIGURE_FORMATS)}", found=repr(f))
        out.append(f.lower())
    return list(dict.fromkeys(out))


def write_report(result, path: str | os.PathLike, *, dest=None, figures=(),
                 while_drawing=None) -> list[str]:
    """Write ``report.html`` at ``path``, the interactive page and, for each format in
    ``figures``, every figure as ``fig_<key>.<ext>``; ``dest(name)`` gives the path of another
    output (an :class:`~insgnss.io.outputset.OutputSet` staging path; default beside ``path``).
    ``while_drawing()`` runs in this process while other processes draw the figures (before
    the interactive page; :func:`_draw_figures`): ``insgnss process`` writes its trajectories
    then. Returns the names written besides ``path``."""
    from .plots import report_specs
    from .report_interactive import write_interactive

    formats = check_figure_formats(figures)
    path = Path(path)
    dest = dest or (lambda name: path.parent / name)
    data = build_report_data(result)
    specs = report_specs(data)

    names = [[(ext, figure_file(sp.key, ext)) for ext in formats] for sp in specs]
    files = [[(ext, dest(name)) for ext, name in row] for row in names]

    def interactive():
        summary = summary_html(result, data)

        def write(p):
            with open(p, "w", encoding="utf-8") as out:
                write_interactive(out, data, specs, summary, STYLE)

        atomic_write(dest(INTERACTIVE_NAME), write)

    def meanwhile():
        if while_drawing is not None:
            while_drawing()
        interactive()

    pngs = _draw_figures(specs, files, meanwhile)
    atomic_write_text(path, render_report(result, data, list(zip(specs, pngs, strict=True))))
    return [name for row in names for _, name in row] + [INTERACTIVE_NAME]
