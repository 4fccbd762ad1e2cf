"""Interactive report page: the summary of the static report and the same figures
(:class:`insgnss.plots.FigureSpec`) as zoomable plotly charts.

The page opens offline: plotly.js (from the ``plotly`` Python package) is embedded once in the
page, and every figure is a plain plotly.js description (``Plotly.newPlot``) with its arrays as
base64 typed arrays (``{"dtype", "bdata"}``, plotly.js >= 2.28), the series already decimated
to what a screen shows (:func:`insgnss.plots.minmax_indices`). Time-series panels of one figure
share their time axis (zooming one zooms all). The track panel keeps equal axes; a button draws
the track on OpenStreetMap tiles (MapLibre, plotly ``scattermap``) when the viewer is online:
nothing is requested from the network until that button is pressed.
"""

from __future__ import annotations

import base64
import html
import io
import json
import shutil
from importlib import resources
from typing import TextIO

import numpy as np

from .plots import OUTAGE_COLOR, FigureSpec, minmax_indices
from .report_data import ReportData

PX_PER_INCH = 120
_DASH = {"solid": "solid", "dashed": "dash", "dotted": "dot", "dashdot": "dashdot"}
_SYMBOL = {"o": "circle", ".": "circle", "x": "x-thin-open", "s": "square"}


def plotly_js():
    """The plotly.js bundle shipped with the ``plotly`` package (embedded once per page), as
    a resource to open."""
    return resources.files("plotly") / "package_data" / "plotly.min.js"


def _b64(a, dtype: str = "f4") -> dict:
    a = np.ascontiguousarray(np.asarray(a, float).astype("<" + dtype))
    return {"dtype": dtype, "bdata": base64.b64encode(a.tobytes()).decode("ascii")}


def _ax(k: int) -> str:
    return "" if k == 1 else str(k)


def figure_json(spec: FigureSpec) -> dict:
    """plotly.js ``{"data", "layout"}`` of a :class:`FigureSpec` (same panels, series, outage
    shading, log scales and equal aspect as the matplotlib figure)."""
    data, shapes, annotations = [], [], []
    height = int(PX_PER_INCH * (spec.row_height * spec.rows + 0.9))
    layout = {"height": height,
              "margin": {"l": 70, "r": 30, "t": 80, "b": 50}, "hovermode": "closest",
              "legend": {"orientation": "h", "y": 1.0 + 24.0 / height, "yanchor": "bottom",
                         "x": 1.0, "xanchor": "right"},
              "title": {"text": html.escape(spec.title), "x": 0.0, "font": {"size": 15}},
              "template": None, "plot_bgcolor": "white"}
    gap_x, gap_y = 0.07, 0.09 if any(p.title for p in spec.panels[spec.cols:]) else 0.04
    seen = set()
    time_axes = []
    for k0, p in enumerate(spec.panels):
        k = k0 + 1
        r, c = divmod(k0, spec.cols)
        x0 = c / spec.cols + (gap_x / 2 if c else 0)
        x1 = (c + 1) / spec.cols - (gap_x / 2 if c < spec.cols - 1 else 0)
        y1 = 1 - r / spec.rows - (gap_y / 2 if r else 0)
        y0 = 1 - (r + 1) / spec.rows + (gap_y / 2 if r < spec.rows - 1 else 0)
        xa = {"domain": [x0, x1], "anchor": f"y{_ax(k)}", "showgrid": True,
              "gridcolor": "#e5e5e5", "zeroline": False, "title": {"text": p.xlabel},
              "linecolor": "#444", "mirror": True}
        ya = {"domain": [y0, y1], "anchor": f"x{_ax(k)}", "showgrid": True,
              "gridcolor": "#e5e5e5", "zeroline": False, "title": {"text": p.ylabel},
              "linecolor": "#444", "mirror": True}
        if p.logy:
            ya["type"] = "log"
        if p.ylim is not None:
            ya["range"] = list(p.ylim)
        if p.equal:
            ya["scaleanchor"] = f"x{_ax(k)}"
            ya["scaleratio"] = 1
        elif spec.sharex:
            time_axes.append(k)
        layout[f"xaxis{_ax(k)}"] = xa
        layout[f"yaxis{_ax(k)}"] = ya
        if p.title:
            annotations.append({"text": f"<b>{html.escape(p.title)}</b>", "x": x0, "y": y1,
                                "xref": "paper", "yref": "paper", "xanchor": "left",
                                "yanchor": "bottom", "showarrow": False, "font": {"size": 12}})
        if p.note:
            annotations.append({"text": html.escape(p.note), "x": x0 + 0.005, "y": y0 + 0.005,
                                "xref": "paper", "yref": "paper", "xanchor": "left",
                                "yanchor": "bottom", "showarrow": False,
                                "font": {"size": 10, "color": "#444"},
                                "bgcolor": "rgba(255,255,255,0.7)"})
        if p.shade:  # all outage windows as one filled trace on a hidden 0-1 y axis
            # (one shape per window makes a page of thousands of windows unusable)
            ab = np.asarray(p.shade, float).reshape(-1, 2)
            n_ax = len(spec.panels) + k
            layout[f"yaxis{n_ax}"] = {"overlaying": f"y{_ax(k)}", "anchor": f"x{_ax(k)}",
                                      "range": [0, 1],
                                      "visible": False, "fixedrange": True}
            xs = np.column_stack([ab[:, 0], ab[:, 0], ab[:, 1], ab[:, 1],
                                  np.full(len(ab), np.nan)]).ravel()
            ys = np.tile([0.0, 1.0, 1.0, 0.0, np.nan], len(ab))
            data.append({"type": "scatter", "x": xs.tolist(), "y": ys.tolist(),
                         "mode": "lines", "fill": "toself", "line": {"width": 0},
                         "fillcolor": _rgba(OUTAGE_COLOR, 0.12), "hoverinfo": "skip",
                         "showlegend": False, "xaxis": f"x{_ax(k)}", "yaxis": f"y{n_ax}"})
        for tr in p.traces:
            axes = {"xaxis": f"x{_ax(k)}", "yaxis": f"y{_ax(k)}"}
            name = tr.label
            show = bool(name) and name not in seen
            if name:
                seen.add(name)
            common = {"name": name or "", "showlegend": show, "legendgroup": name or None,
                      **axes}
            if tr.kind == "hline":
                shapes.append({"type": "line", "xref": f"x{_ax(k)} domain", "yref": f"y{_ax(k)}",
                               "x0": 0, "x1": 1, "y0": tr.value, "y1": tr.value,
                               "line": {"color": tr.color, "width": tr.width,
                                        "dash": _DASH[tr.dash]}})
                if show:  # legend entry for the line
                    data.append({"type": "scatter", "x": [None], "y": [None], "mode": "lines",
                                 "line": {"color": tr.color, "dash": _DASH[tr.dash]}, **common})
                continue
            if tr.kind == "band":
                data.append({"type": "scatter", "x": _b64(tr.x), "y": _b64(tr.lo, "f4"),
                             "mode": "lines", "line": {"width": 0}, "hoverinfo": "skip",
                             **{**common, "showlegend": False}})
                data.append({"type": "scatter", "x": _b64(tr.x), "y": _b64(tr.hi, "f4"),
                             "mode": "lines", "line": {"width": 0}, "fill": "tonexty",
                             "fillcolor": _rgba(tr.color, tr.alpha), **common})
            elif tr.kind == "line":
                data.append({"type": "scatter", "x": _b64(tr.x), "y": _b64(tr.y, "f4"),
                             "mode": "lines", "opacity": tr.alpha,
                             "line": {"color": tr.color, "width": tr.width * 1.3,
                                      "dash": _DASH[tr.dash]}, **common})
            elif tr.kind in ("points", "marker"):
                data.append({"type": "scatter",
                             "x": _b64(tr.x), "y": _b64(tr.y, "f4"), "mode": "markers",
                             "marker": {"color": tr.color, "size": tr.size * 1.4,
                                        "symbol": _SYMBOL.get(tr.marker, "circle"),
                                        "line": {"width": 1 if tr.kind == "marker" else 0,
                                                 "color": "black"}}, **common})
            elif tr.kind == "colorline":
                c = np.asarray(tr.c, float)
                fin = c[np.isfinite(c)]
                vmax = float(np.percentile(fin, 99)) if fin.size else 1.0
                data.append({"type": "scatter", "x": _b64(tr.x), "y": _b64(tr.y, "f4"),
                             "mode": "lines", "line": {"color": "#bbbbbb", "width": 1},
                             "hoverinfo": "skip", **{**common, "showlegend": False}})
                data.append({"type": "scatter", "x": _b64(tr.x), "y": _b64(tr.y, "f4"),
                             "mode": "markers", "marker": {
                                 "color": _b64(c, "f4"), "colorscale": "Viridis", "cmin": 0.0,
                                 "cmax": vmax if vmax > 0 else 1.0, "size": 4,
                                 "colorbar": {"title": {"text": p.colorbar or "",
                                                        "side": "right"}, "len": 0.8}},
                             **common})
    if len(time_axes) > 1:  # one time axis for the whole figure
        for k in time_axes[1:]:
            layout[f"xaxis{_ax(k)}"]["matches"] = f"x{_ax(time_axes[0])}"
    layout["shapes"] = shapes
    layout["annotations"] = annotations
    return {"data": data, "layout": layout}


def _clean(x):
    """Non-finite floats to None (JSON null) in a figure description."""
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if isinstance(x, float | np.floating):
        return float(x) if np.isfinite(x) else None
    if isinstance(x, np.integer | np.bool_):
        return x.item()
    return x


#: the named colours of the figure specifications (matplotlib's single-letter names)
_NAMED = {"k": "#000000", "black": "#000000", "w": "#ffffff", "white": "#ffffff"}


def _rgb(color: str) -> tuple[float, float, float]:
    """``(r, g, b)`` in 0..1 of ``#rgb``, ``#rrggbb`` or a name of :data:`_NAMED` without
    importing matplotlib (the page is written while the figure server draws; another colour
    goes through ``matplotlib.colors.to_rgb``)."""
    c = _NAMED.get(color, color)
    if c.startswith("#") and len(c) in (4, 7):
        h = c[1:] if len(c) == 7 else "".join(ch * 2 for ch in c[1:])
        try:
            return tuple(int(h[i:i + 2], 16) / 255 for i in (0, 2, 4))
        except ValueError:
            pass
    from matplotlib.colors import to_rgb

    return to_rgb(color)


def _rgba(color: str | None, alpha: float) -> str:
    r, g, b = (int(255 * v) for v in _rgb(color or "#888888"))
    return f"rgba({r},{g},{b},{alpha})"


def _map_data(data: ReportData) -> dict:
    """Track in degrees (decimated) for the optional tile map."""
    tab = data.best.table
    lat, lon = np.degrees(tab["lat"].to_numpy(float)), np.degrees(tab["lon"].to_numpy(float))
    i = minmax_indices(lat, lon, n=3000)
    out = {"solution": {"lat": _b64(lat[i]), "lon": _b64(lon[i]), "name": data.best.name}}
    if data.reference is not None:
        rl = np.degrees(data.reference["lat"].to_numpy(float))
        ro = np.degrees(data.reference["lon"].to_numpy(float))
        j = minmax_indices(rl, ro, n=3000)
        out["reference"] = {"lat": _b64(rl[j]), "lon": _b64(ro[j]), "name": "reference"}
    out["center"] = {"lat": float(np.mean(lat)), "lon": float(np.mean(lon))}
    return out


SCRIPT = """
(function () {
  var figs = JSON.parse(document.getElementById('insgnss-figures').textContent);
  var config = {responsive: true, displaylogo: false, scrollZoom: true};
  Object.keys(figs).forEach(function (key) {
    var gd = document.getElementById('plot-' + key);
    Plotly.newPlot(gd, figs[key].data, figs[key].layout, config).then(function () {
      gd.setAttribute('data-rendered', '1');
    });
  });
  var btn = document.getElementById('map-tiles');
  if (btn) {
    btn.addEventListener('click', function () {
      var m = JSON.parse(document.getElementById('insgnss-map').textContent);
      var box = document.getElementById('map');
      box.style.display = 'block';
      var traces = [];
      ['reference', 'solution'].forEach(function (k) {
        if (!m[k]) { return; }
        traces.push({type: 'scattermap', mode: 'lines', lat: m[k].lat, lon: m[k].lon,
                     name: m[k].name, line: {width: k === 'reference' ? 5 : 2,
                     color: k === 'reference' ? '#999999' : '#d62728'}});
      });
      Plotly.newPlot(box, traces, {map: {style: 'open-street-map', center: m.center, zoom: 14},
                                   margin: {l: 0, r: 0, t: 0, b: 0}, height: 600}, config);
      btn.disabled = true;
    });
  }
})();
"""


def write_interactive(out: TextIO, data: ReportData, specs: list[FigureSpec], summary: str,
                      style: str = "") -> None:
    """Write the interactive page to the text stream ``out`` piece by piece: ``summary`` is the
    HTML of the summary section (:func:`insgnss.report.summary_html`, the same as on the static
    page), ``style`` its CSS. The figures' JSON is encoded in chunks and plotly.js copied from
    its file: the page of a long run is several MB, which as one string was held three to four
    times over while it was assembled."""
    title = f"insgnss interactive report: {data.title}"
    out.write("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
              f"<title>{html.escape(title)}</title><style>{style}</style></head><body>")
    body = [f"<h1>{html.escape(title)}</h1>",
            "<nav><a href='report.html'>static report</a> | "
            + " ".join(f"<a href='#{sp.key}'>{html.escape(sp.title)}</a>" for sp in specs)
            + "</nav>", "<p class='note'>Drag to zoom, double-click to reset, scroll to zoom; "
            "the time axes of one figure move together.</p>", summary]
    for sp in specs:
        extra = ""
        if sp.key == "track":
            extra = ("<p><button id='map-tiles' type='button'>Show on map tiles (needs an "
                     "internet connection)</button></p><div id='map' style='display:none'>"
                     "</div>")
        body.append(f"<h2 id='{sp.key}'>{html.escape(sp.title)}</h2><figure class='fig' "
                    f"data-key='{sp.key}'><div class='plot' id='plot-{sp.key}'></div>{extra}"
                    f"<figcaption>{html.escape(sp.caption)}</figcaption></figure>")
    out.write("\n".join(body))
    out.write("\n<script type='application/json' id='insgnss-figures'>")
    _write_json(out, {sp.key: figure_json(sp) for sp in specs})
    out.write("</script>\n<script type='application/json' id='insgnss-map'>")
    _write_json(out, _map_data(data))
    out.write("</script>\n<script>")
    with plotly_js().open("r", encoding="utf-8") as js:
        shutil.copyfileobj(js, out)
    out.write(f"</script><script>{SCRIPT}</script></body></html>\n")


def _write_json(out: TextIO, obj) -> None:
    """``obj`` as compact JSON with ``</`` escaped (safe inside a script element), in chunks;
    ``<`` occurs only inside strings, which the encoder yields whole."""
    enc = json.JSONEncoder(allow_nan=False, separators=(",", ":"))
    for chunk in enc.iterencode(_clean(obj)):
        out.write(chunk.replace("</", "<\\/"))


def render_interactive(data: ReportData, specs: list[FigureSpec], summary: str,
                       style: str = "") -> str:
    """The interactive page as an HTML string (:func:`write_interactive`)."""
    buf = io.StringIO()
    write_interactive(buf, data, specs, summary, style)
    return buf.getvalue()
