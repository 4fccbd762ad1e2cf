"""Report (issue 18): every figure for the demo, the real drive and a foot job; summary tables in
both forms of the measurement counts; the INCOMPLETE banner; figure files; decimation."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pandas as pd
import pytest
from report_helpers import EXPECTED, REPO, figure_keys, set_outputs

from insgnss.config import load_job, load_job_dict
from insgnss.errors import ConfigError
from insgnss.pipeline import load_inputs, run_job, write_outputs
from insgnss.plots import (
    DISPLAY_POINTS,
    REPORT_FIGURES,
    decimate,
    innovation_spec,
    minmax_indices,
    nis_spec,
    track_spec,
)
from insgnss.report import fmt, measurement_counts
from insgnss.report_data import (
    COMPONENTS,
    FIGURE_KEYS,
    INTERACTIVE_NAME,
    build_report_data,
    figure_file,
    time_origin,
)


# --- shared runs ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    from insgnss.commands.demo import demo_job_path

    job = set_outputs(load_job(demo_job_path()), figures=["png", "pdf", "svg"])
    res = run_job(job, progress=False)
    out = tmp_path_factory.mktemp("demo")
    return res, out, write_outputs(res, out)


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    from conftest import shared_data

    shared_data("gnss-imu-rtklibexplorer", "drive_0708")
    job = set_outputs(load_job(REPO / "scenarios" / "drive_0708.toml"), figures=["svg"])
    job.settings["filter"]["autotune"] = False  # the report's figures, not the self-tuning
    res = run_job(job, progress=False)
    out = tmp_path_factory.mktemp("drive")
    return res, out, write_outputs(res, out)


@pytest.fixture(scope="module")
def foot(tmp_path_factory):
    from conftest import shared_data

    trial = shared_data("pyshoe-vicon", "2017-11-22-11-22-03.mat")
    spec = importlib.util.spec_from_file_location("pyshoe_convert",
                                                  REPO / "scenarios" / "pyshoe" / "convert.py")
    convert = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(convert)
    d = tmp_path_factory.mktemp("foot")
    imu_csv, _ = convert.write_trial(trial, d)
    (d / "foot.toml").write_text((REPO / "scenarios" / "foot_mounted.toml").read_text()
                                 + f'\n[inputs.imu]\nformat = "native"\npath = "{imu_csv.name}"\n'
                                 '\n[outputs]\ndir = "out"\nformats = ["csv"]\n')
    job = load_job(d / "foot.toml")
    res = run_job(job, progress=False)
    return res, d / "out", write_outputs(res, d / "out")


def _check_pages(out, expected: set[str]):
    static = (out / "report.html").read_text()
    inter = (out / INTERACTIVE_NAME).read_text()
    assert figure_keys(static) == expected
    assert figure_keys(inter) == expected
    assert "<script" not in static  # the static page opens without scripts
    assert static.count("data:image/png;base64,") == len(expected)
    for key in expected:
        assert f"id='plot-{key}'" in inter
    # plotly.js embedded once, the page needs no network
    assert inter.count("plotly.js v") == 1 and "<script src" not in inter
    # readable summary: no raw Python dicts, no NaN cells
    assert "{'" not in static and ">nan<" not in static.lower()
    assert "<th>offered</th>" in static.replace("<th class=''>", "<th>")
    return static, inter


def test_demo_report_has_every_figure(demo):
    res, out, paths = demo
    static, inter = _check_pages(out, EXPECTED["demo"])
    assert "INCOMPLETE" not in static
    # figure files beside the report in every requested format, listed in the output set
    for key in EXPECTED["demo"]:
        assert (out / figure_file(key, "pdf")).read_bytes()[:4] == b"%PDF"
        assert b"<svg" in (out / figure_file(key, "svg")).read_bytes()[:2000]
        assert (out / figure_file(key, "png")).read_bytes()[:4] == b"\x89PNG"
        assert figure_file(key, "svg") in paths
    summary = json.loads((out / "summary.json").read_text())
    assert "report_interactive.html" in summary["files"] and "fig_nees.pdf" in summary["files"]
    # named innovation components in the interactive figures (not "component 0")
    for name in ("east", "north", "up", "x (right)", "right"):
        assert f'"name":"{name}"' in inter
    assert "component 0" not in inter
    assert "insgnss version" in static and "Resolved job" in static


def test_drive_report_position_reference_only(drive):
    res, out, _ = drive
    static, _ = _check_pages(out, EXPECTED["drive"])
    # RTK positions and velocities at the antenna, no attitude: velocity errors would need the
    # lever-arm velocity (body rate), so velocity and attitude come as sigmas and differences
    assert "The reference has no attitude" in static
    assert "The reference measures the antenna" in static
    assert (out / figure_file("nees", "svg")).exists()
    assert not (out / figure_file("nees", "pdf")).exists()
    data = build_report_data(res)
    assert data.reference_kinds == ("position",)
    # NEES only where the reference has the quantity
    assert list(data.solutions["forward"].nees.columns) == ["position"]


def test_foot_report_without_reference(foot):
    res, out, _ = foot
    static, _ = _check_pages(out, EXPECTED["foot"])
    assert "No reference" in static
    # the foot filter's innovations are named (zupt east/north/up, zaru x/y/z)
    spec = innovation_spec(build_report_data(res))
    names = {t.label for p in spec.panels for t in p.traces if t.label}
    assert {"zupt east", "zupt north", "zupt up", "zaru x"} <= names


def test_incomplete_run_shows_the_banner(tmp_path):
    """A run stopped by the filter health check (NaN in the IMU, as in
    test_robustness_health.py) writes both pages with the banner and the stop reason on top."""
    from robustness_helpers import small_job

    job = small_job()
    set_outputs(job, report=True)
    inputs = load_inputs(job)
    imu = inputs.imu.copy()
    imu.iloc[int(np.searchsorted(imu.index, imu.index[0] + 50.0)), 0] = np.nan
    inputs.imu = imu
    res = run_job(job, inputs=inputs, progress=False)
    assert not res.summary["complete"]
    write_outputs(res, tmp_path)
    for name in ("report.html", INTERACTIVE_NAME):
        page = (tmp_path / name).read_text()
        body = page[page.index("<body>"):]
        assert body.index("id='incomplete'") < body.index("id='summary'")
        assert "INCOMPLETE" in body and "non-finite" in body
        assert f"t = {fmt(res.summary['stopped_at'])} s" in body
    assert (tmp_path / "INCOMPLETE").exists()


# --- pieces -----------------------------------------------------------------------------------
def test_measurement_counts_old_and_new_forms():
    old = {"measurements": {"gnss_pos": 10, "zupt": 5}, "rejected": {"gnss_pos": 2}}
    inn = pd.DataFrame({"type": ["gnss_pos"] * 10 + ["zupt"] * 5,
                        "accepted": [True] * 8 + [False] * 2 + [True] * 5,
                        "recovered": [False] * 9 + [True] + [False] * 5})
    t = measurement_counts(old, inn).set_index("measurement")
    assert t.loc["gnss_pos"].tolist() == [10, 8, 2, 1] and t.loc["zupt"].tolist() == [5, 5, 0, 0]
    new = {"measurements": {"gnss_pos": {"offered": 10, "applied": 7, "rejected": 3,
                                         "recovered": 1}}}
    t = measurement_counts(new).set_index("measurement")
    assert t.loc["gnss_pos"].tolist() == [10, 7, 3, 1]
    new["measurements"]["gnss_pos"]["unusable"] = 2
    t = measurement_counts(new).set_index("measurement")
    assert t.loc["gnss_pos", "unusable"] == 2
    assert fmt(float("nan")) == "-" and fmt({"a": 1.23456}) == "a: 1.235" and fmt(None) == "-"


def test_summary_shows_version_resolved_job_and_autotune(demo):
    from insgnss.report import render_report

    res, _, _ = demo
    s = dict(res.summary)
    res.summary = {**s, "version": "9.9.9", "job_resolved": {"filter": {"smoother": True}},
                   "autotune": {"gyro_arw_deg_sqrt_h": 0.31, "converged": True}}
    try:
        page = render_report(res)
    finally:
        res.summary = s
    assert "9.9.9" in page and "Autotuned parameters" in page and "gyro_arw_deg_sqrt_h" in page
    assert "&quot;smoother&quot;: true" in page


def test_rejected_points_drawn_at_their_nis_and_normalised_innovation(demo):
    res, _, _ = demo
    data = build_report_data(res)
    inn = data.innovations
    rej = inn[~inn["accepted"].astype(bool)]
    assert len(rej) >= 1
    t0 = time_origin(data)
    spec = nis_spec(data)
    crosses = [t for p in spec.panels for t in p.traces if t.label == "rejected"]
    got = np.sort(np.concatenate([t.y for t in crosses]))
    assert np.allclose(got, np.sort(rej["nis"].to_numpy(float)))
    assert np.all(got > 0)  # not at y = 0 (issue 18)
    spec = innovation_spec(data)
    ty = rej["type"].iloc[0]
    panel = next(p for p in spec.panels if p.title.startswith(f"{ty}:"))
    xs = [t for t in panel.traces if t.color == "#d62728" and t.kind == "points"]
    want = rej[rej["type"] == ty]
    assert np.allclose(xs[0].y, want["innov_0"] / want["innov_std_0"])
    assert np.allclose(xs[0].x, want["time"] - t0)
    names = [t.label for t in panel.traces if t.kind == "points" and t.color != "#d62728"]
    assert names == list(COMPONENTS[ty][0])


def test_minmax_decimation_keeps_extremes():
    rng = np.random.default_rng(0)
    n = 720_000  # 1 h at 200 Hz
    y = rng.normal(size=n)
    y[123_457] = 50.0
    y[654_321] = -60.0
    i = minmax_indices(y)
    assert i.size <= DISPLAY_POINTS + 2 and i[0] == 0 and i[-1] == n - 1
    assert 123_457 in i and 654_321 in i and np.all(np.diff(i) > 0)
    x, yd = decimate(np.arange(n), y)
    assert yd.max() == 50.0 and yd.min() == -60.0
    # every bucket's min and max survive
    b = n // (DISPLAY_POINTS // 2) + 1
    assert np.isclose(yd.max(), y[: b * (DISPLAY_POINTS // 2)].max())
    assert minmax_indices(np.arange(10.0)).tolist() == list(range(10))


def test_track_of_a_long_log_is_decimated(demo):
    """A 1 h / 200 Hz track is drawn with a few thousand points, not 720k."""
    from insgnss.report_data import ReportData, SolutionData

    res, _, _ = demo
    n = 720_000
    t = np.arange(n) / 200.0
    lat0, lon0 = np.radians(51.0), np.radians(-114.0)
    tab = pd.DataFrame({"lat": lat0 + 1e-6 * np.sin(t / 300), "lon": lon0 + 1e-6 * t / 36,
                        "height": np.zeros(n), "east_std": np.ones(n), "north_std": np.ones(n)},
                       index=pd.Index(t, name="time"))
    data = ReportData("long", {}, [], {"forward": SolutionData("forward", tab)},
                      (lat0, lon0, 0.0))
    sizes = [len(tr.x) for p in track_spec(data).panels for tr in p.traces]
    assert max(sizes) <= DISPLAY_POINTS + 2


def test_figure_keys_and_config():
    assert tuple(k for k, _, _ in REPORT_FIGURES) == FIGURE_KEYS
    job = load_job_dict({"outputs": {"figures": ["png", "pdf"]}})
    assert job["outputs"]["figures"] == ["png", "pdf"]
    assert load_job_dict({})["outputs"]["figures"] == []
    with pytest.raises(ConfigError, match="outputs.figures"):
        load_job_dict({"outputs": {"figures": ["jpg"]}})


def test_single_run_nees_uses_the_epoch_covariance(demo):
    """NEES of the report = e' P(e|e)^-1 e with the forward filter's covariance at the same
    epoch and the position error at that reference epoch (catches any epoch misalignment)."""
    res, _, _ = demo
    data = build_report_data(res)
    f = res.filter
    nees = data.solutions["forward"].nees
    err = data.solutions["forward"].errors
    ep = np.asarray(f.epoch_times, float)
    for t in nees.index[[5, 100, 500, -1]]:
        k = int(np.argmin(np.abs(ep - t)))
        assert abs(ep[k] - t) < 1e-6
        e = err.loc[t, ["east", "north", "up"]].to_numpy(float)
        want = e @ np.linalg.solve(f.P_filtered[k][:3, :3], e)
        assert nees.loc[t, "position"] == pytest.approx(want, rel=1e-9)
        e = err.loc[t, ["vel_e", "vel_n", "vel_u"]].to_numpy(float)
        assert nees.loc[t, "velocity"] == pytest.approx(
            e @ np.linalg.solve(f.P_filtered[k][3:6, 3:6], e), rel=1e-9)


def test_report_data_at_output_rate(demo):
    """The report draws the run at its trajectory output rate (10 Hz by default, plus the
    samples around every GNSS epoch), the errors at the thinned reference epochs; ``"imu"``
    keeps every sample and every reference epoch."""
    import copy

    res = demo[0]
    full = res.filter.forward
    data = build_report_data(res)
    tab = data.solutions["forward"].table
    t = tab.index.to_numpy(float)
    assert len(tab) < len(full) / 3  # the demo IMU runs well above 10 Hz
    assert np.isin(t, full.index.to_numpy(float)).all()  # rows of the solution, not resampled
    assert np.median(np.diff(t)) == pytest.approx(0.1, rel=0.2)
    tg = res.inputs.gnss.index.to_numpy(float)
    tg = tg[(tg >= t[0]) & (tg <= t[-1])]
    gap = np.abs(t[np.clip(np.searchsorted(t, tg), 0, len(t) - 1)] - tg)
    assert gap.max() < np.median(np.diff(full.index.to_numpy(float))) * 1.01
    n_err = len(res.evaluation["forward"]["errors"])

    def at_rate(rate):
        other = copy.copy(res)
        other.job = copy.deepcopy(res.job)
        other.job["outputs"]["rate_hz"] = rate
        return build_report_data(other)

    # the demo reference is at 10 Hz: at 0.2 Hz its epochs are thinned too (the errors with it)
    slow = at_rate(0.2)
    err = slow.solutions["forward"].errors
    assert len(err) < n_err / 2
    assert np.isin(err.index.to_numpy(float), slow.reference.index.to_numpy(float)).all()
    assert np.isin(err.index.to_numpy(float),
                   res.evaluation["forward"]["errors"].index.to_numpy(float)).all()
    every = at_rate("imu")
    assert len(every.solutions["forward"].table) == len(full)
    assert len(every.solutions["forward"].errors) == n_err


def test_outage_shading_one_collection():
    """Outage windows: one polygon per window in a single collection (matplotlib) and a single
    filled trace on a hidden 0-1 axis of its own (plotly), spanning the panel's height."""
    from matplotlib.collections import PolyCollection

    from insgnss.plots import FigureSpec, Panel, Trace, render
    from insgnss.report_interactive import figure_json

    x = np.linspace(0.0, 100.0, 201)
    windows = [(10.0, 20.0), (40.0, 45.0), (70.0, 90.0)]
    panels = [Panel(traces=[Trace("line", x, np.sin(x))], shade=windows if k else [])
              for k in range(3)]
    spec = FigureSpec("t", "t", "", panels, rows=3)
    fig = render(spec)
    colls = [c for c in fig.axes[1].collections if isinstance(c, PolyCollection)]
    assert len(colls) == 1
    xy = [p.vertices for p in colls[0].get_paths()]
    assert [(v[:, 0].min(), v[:, 0].max()) for v in xy] == windows
    assert all(v[:, 1].min() == 0.0 and v[:, 1].max() == 1.0 for v in xy)  # axes fraction
    assert fig.axes[1].get_xlim()[1] <= 105.0  # the shading does not change the limits
    assert not any(isinstance(c, PolyCollection) for c in fig.axes[0].collections)

    fj = figure_json(spec)
    fills = [d for d in fj["data"] if d.get("fill") == "toself"]
    assert len(fills) == 2  # one per shaded panel
    for d, k in zip(fills, (2, 3), strict=True):
        assert d["xaxis"] == f"x{k}"
        hidden = fj["layout"]["yaxis" + d["yaxis"][1:]]
        assert hidden["overlaying"] == f"y{k}" and hidden["range"] == [0, 1]
        assert not hidden["visible"]
        assert d["yaxis"] not in ("y", "y2", "y3")  # no panel's own axis
        xs = np.array(d["x"], float)
        assert np.nanmin(xs) == 10.0 and np.nanmax(xs) == 90.0
        assert np.isnan(xs).sum() == len(windows)



@pytest.mark.parametrize("workers", [0, 1, 2])
def test_figures_shared_queue_largest_first(monkeypatch, workers):
    """Every figure is drawn exactly once, by whichever process takes it next from the shared
    queue (largest first), and the PNG bytes come back in the order of the specs."""
    import multiprocessing
    import os
    import time
    from types import SimpleNamespace

    import insgnss.report as rep

    if workers and "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("figure workers need fork")
    sizes = [1, 12, 2, 5, 3, 3, 4]  # panels per figure, two traces each
    specs = [SimpleNamespace(panels=[SimpleNamespace(traces=[0, 0])] * n) for n in sizes]
    assert [rep.figure_cost(s) for s in specs] == [4, 54, 9, 22, 13, 13, 18]
    track = SimpleNamespace(panels=[SimpleNamespace(traces=[SimpleNamespace(kind="colorline")]
                                                    + [SimpleNamespace(kind="line")] * 7)])
    assert rep.figure_cost(track) == 4 + 2 + 16  # the colour bar and the segments

    def fake_figure(i):  # forked workers inherit the patch
        start = time.perf_counter()
        time.sleep(0.005 * sizes[i])
        return f"{i} {os.getpid()} {start!r}".encode()

    monkeypatch.setattr(rep, "_figure", fake_figure)
    monkeypatch.setattr(rep, "figure_workers", lambda n: workers)
    seen = []
    pngs = rep._draw_figures(specs, [[] for _ in specs], lambda: seen.append("interactive"))
    assert seen == ["interactive"] and rep._WORK is None
    rows = [p.decode().split() for p in pngs]
    assert [int(r[0]) for r in rows] == list(range(len(specs)))
    pids = {int(r[1]) for r in rows}
    assert len(pids) <= workers + 1
    if workers == 0:  # one process: strictly largest first, ties in the order of the specs
        assert pids == {os.getpid()}
        starts = [float(r[2]) for r in rows]
        assert sorted(range(len(specs)), key=starts.__getitem__) == [1, 3, 6, 4, 5, 2, 0]


# --- the figure server of insgnss process (issue 15) -------------------------------------------
def _small_specs():
    from insgnss.plots import FigureSpec, Panel, Trace

    t = np.linspace(0.0, 10.0, 50)
    return [FigureSpec(f"fig{k}", f"figure {k}", "",
                       [Panel(title="p", traces=[Trace("line", x=t, y=np.sin(t + k))])], 1)
            for k in range(5)]


def test_figure_server_draws_the_same_figures(tmp_path):
    """Figures drawn by the server forked ahead of the run are byte-identical to those drawn
    in the run's own process, their files are written, the interactive page is written once
    meanwhile, and the server is gone afterwards."""
    import multiprocessing

    import insgnss.report as rep

    if "fork" not in multiprocessing.get_all_start_methods() or rep._cores() < 2:
        pytest.skip("the figure server needs fork and two cores")
    specs = _small_specs()
    own = rep._draw_figures(specs, [[] for _ in specs])
    assert rep.start_figure_workers() and rep.start_figure_workers()  # once
    proc = rep._SERVER[0]
    seen = []
    files = [[("png", tmp_path / f"{s.key}.png")] for s in specs]
    served = rep._draw_figures(specs, files, lambda: seen.append(proc.is_alive()))
    assert seen == [True] and rep._SERVER is None and not proc.is_alive()
    assert served == own
    assert [(tmp_path / f"{s.key}.png").read_bytes() for s in specs] == own


def test_figure_server_lost_or_unused(tmp_path):
    """A server that died is replaced by drawing here (the interactive page written once); one
    the run never uses exits when stopped."""
    import multiprocessing

    import insgnss.report as rep

    if "fork" not in multiprocessing.get_all_start_methods() or rep._cores() < 2:
        pytest.skip("the figure server needs fork and two cores")
    specs = _small_specs()[:2]
    rep.start_figure_workers()
    proc = rep._SERVER[0]
    proc.kill()
    proc.join()
    seen = []
    pngs = rep._draw_figures(specs, [[] for _ in specs], lambda: seen.append(1))
    assert seen == [1] and len(pngs) == 2 and pngs[0].startswith(b"\x89PNG")
    assert rep._SERVER is None
    rep.start_figure_workers()
    proc = rep._SERVER[0]
    rep.stop_figure_workers()  # exits on the closed connection, or terminated while warming
    assert not proc.is_alive() and proc.exitcode in (0, -15) and rep._SERVER is None



def test_error_while_the_server_draws_is_raised():
    """An error of the work done while the server draws (``insgnss process`` writes its
    trajectories then; an OSError of a full disk) is the run's error: raised, not taken for a
    dead server and swallowed; the server is stopped."""
    import multiprocessing

    import insgnss.report as rep

    if "fork" not in multiprocessing.get_all_start_methods() or rep._cores() < 2:
        pytest.skip("the figure server needs fork and two cores")
    specs = _small_specs()[:2]
    rep.start_figure_workers()
    proc = rep._SERVER[0]

    def write():
        raise OSError(28, "No space left on device")

    with pytest.raises(OSError, match="No space left"):
        rep._draw_figures(specs, [[] for _ in specs], write)
    proc.join(5.0)
    assert rep._SERVER is None and not proc.is_alive()

def test_figure_specs_need_no_matplotlib():
    """Building the report's specifications and its interactive page imports no matplotlib
    (the figure server draws); the outage colours are matplotlib's tab10 / tab20."""
    import subprocess
    import sys

    code = ("import sys, insgnss.report, insgnss.plots, insgnss.report_interactive as ri; "
            "c = [ri._rgba(x, 0.3) for x in ('#7f7f7f', 'k', '#abc')]; "
            "print('matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
    import matplotlib

    from insgnss.plots import TAB10, TAB20

    for name, ours in (("tab10", TAB10), ("tab20", TAB20)):
        cmap = matplotlib.colormaps[name]
        assert [matplotlib.colors.to_hex(cmap(i)) for i in range(cmap.N)] == list(ours)
    from insgnss.report_interactive import _rgb

    for c in ("#7f7f7f", "#1f77b4", "k", "black", "w", "#abc", "tab:red"):
        assert _rgb(c) == matplotlib.colors.to_rgb(c)
