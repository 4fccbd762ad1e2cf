"""Drift comparison on one data set: free inertial, ZUPT, ZUPT+ZARU, ZUPT+CUPT and GNSS-aided
runs, one error table and the drift figures (docs/zupt.md).

JOB is either
  - a TOML job / scenario file (vehicle data or a simulation; read with the job loader), or
  - a folder with ``imu.csv`` (native IMU table, body RFU) and ``truth.csv`` (``x y z`` local
    positions, or a full ``lat lon height ...`` trajectory): a foot-mounted comparison with the
    pedestrian preset (e.g. a PyShoe trial converted by scenarios/pyshoe/convert.py).

Still samples of a vehicle job: the job's declared ``aiding.static_intervals``, else its
``aiding.detector`` settings, else (simulations) the stops of the simulated truth, else the
default vehicle detector. Control points: ``inputs.control_points``, else (simulations)
surveyed points simulated at the truth stops (2 cm).

Examples:
  insgnss compare scenarios/car_town_mems.toml -o out/compare_car
  insgnss compare out/pyshoe_trial -o out/compare_foot --foot-config scenarios/foot_mounted.toml
"""

from __future__ import annotations

import argparse
import json
import tomllib
from pathlib import Path

from ._outputs import add_wait_argument, output_folder

NAME = "compare"
HELP = ("drift comparison: free inertial, ZUPT, ZUPT+ZARU, ZUPT+CUPT, GNSS, the job's own "
        "aided solutions and RISS")

#: default vehicle stop detector: specific-force spread over 0.5 s (engine-off or idling car)
VEHICLE_DETECTOR = {"method": "amv", "window": 0.5, "threshold": 0.05, "min_stance": 1.0,
                    "margin": 0.3}


def register(p: argparse.ArgumentParser) -> None:
    p.add_argument("job", type=Path, help="TOML job/scenario file, or a folder with imu.csv "
                   "and truth.csv (foot-mounted)")
    p.add_argument("-o", "--output", type=Path, default=Path("compare_out"),
                   help="output folder (table, figures)")
    p.add_argument("--only", default=None, metavar="RUN,...",
                   help="compare only these runs: comma-separated subset of free,zupt,"
                   "zupt_zaru,zupt_cupt,gnss,job,job_smoothed,riss,riss_smoothed")
    # --runs was this option's name; in `insgnss montecarlo` --runs is a number of runs
    p.add_argument("--runs", dest="runs_deprecated", default=None, help=argparse.SUPPRESS)
    p.add_argument("--solution", choices=["forward", "smoothed"], default="forward",
                   help="compare the forward (causal) or the smoothed solutions")
    p.add_argument("--fit-window", nargs=2, type=float, default=None, metavar=("T0", "T1"),
                   help="growth-exponent fit window [s since start] (default 10 300; foot 1 30)")
    p.add_argument("--seed", type=int, default=None, help="simulation seed")
    p.add_argument("--foot-config", type=Path, default=None,
                   help="TOML with a [foot] table (foot-mounted folder jobs)")
    p.add_argument("--no-figures", action="store_true")
    add_wait_argument(p)
    p.set_defaults(func=run)


def _settings(args, foot: bool):
    from ..compare import CompareSettings

    kw = {"solution": args.solution}
    if args.fit_window:
        kw["fit_window"] = tuple(args.fit_window)
    elif foot:
        kw["fit_window"] = (1.0, 30.0)
    return CompareSettings(**kw)


def _runs(args):
    only = args.only
    if args.runs_deprecated is not None:
        import warnings

        warnings.warn("insgnss compare --runs is deprecated: use --only (in insgnss montecarlo "
                      "--runs is the number of runs)", FutureWarning, stacklevel=2)
        only = only or args.runs_deprecated
    return None if not only else [r.strip() for r in only.split(",") if r.strip()]


def _foot(args):
    from ..compare import compare_foot_runs
    from ..errors import InputFormatError
    from ..foot import FootConfig
    from ..io.native import read_table

    d = args.job
    if not (d / "imu.csv").exists():
        raise InputFormatError("no imu.csv in the job folder", file=d)
    imu = read_table(d / "imu.csv")
    if not (d / "truth.csv").exists():
        raise InputFormatError("no truth.csv in the job folder (needed for the errors)", file=d)
    truth = read_table(d / "truth.csv")
    cfg = FootConfig()
    if args.foot_config is not None:
        with open(args.foot_config, "rb") as fh:
            cfg = FootConfig.from_dict(tomllib.load(fh).get("foot", {}))
    res = compare_foot_runs(imu, truth, cfg, runs=_runs(args), settings=_settings(args, True))
    return res, f"foot-mounted: {d.name}"


def _vehicle(args, job):
    import numpy as np

    from ..compare import compare_runs, control_points_at_stops
    from ..detect import DetectorConfig, detect_stillness
    from ..outages import in_windows
    from ..pipeline import filter_config, initialize, load_inputs, outage_windows, run_job
    from ..validate import time_slice

    inputs = load_inputs(job, args.seed)
    # the job's own processing (all its aiding, outages and preprocessing; this also applies
    # the preprocessing, e.g. an estimated IMU time offset, to the inputs the other runs use)
    jr = run_job(job, progress=False, inputs=inputs)
    job_solutions = {"job": jr.filter.forward, "job_smoothed": jr.filter.smoothed}
    job_rejected = {"job": jr.filter.rejected, "job_smoothed": jr.filter.rejected}
    if inputs.odometer is not None and len(inputs.odometer) and \
            job["filter"]["process_model"] != "riss":
        # the same job with the RISS process model (odometer as its input)
        import copy

        job_r = copy.deepcopy(job)
        job_r.settings["filter"]["process_model"] = "riss"
        job_r.settings["aiding"]["odometer"] = False
        job_r.settings["inputs"]["imu"]["estimate_time_offset"] = False  # already applied
        jr_r = run_job(job_r, progress=False, inputs=inputs)
        job_solutions.update(riss=jr_r.filter.forward, riss_smoothed=jr_r.filter.smoothed)
        job_rejected.update(riss=jr_r.filter.rejected, riss_smoothed=jr_r.filter.rejected)
    model = inputs.imu_model
    init = initialize(job, inputs, model)
    imu = time_slice(inputs.imu, init.state.time)
    t = imu.index.to_numpy(float)
    a = job["aiding"]
    note = ""
    if a["static_intervals"]:
        still = np.zeros(t.size, bool)
        for a0, a1 in a["static_intervals"]:
            still |= (t >= a0) & (t <= a1)
        note = "declared static intervals"
    elif a["detector"]:
        still = detect_stillness(imu, DetectorConfig.from_dict(a["detector"])).still.to_numpy()
        note = "job detector"
    elif inputs.truth is not None and "stationary" in inputs.truth.columns:
        from ..detect import shrink_runs

        st = np.interp(t, inputs.truth.index.to_numpy(float),
                       inputs.truth["stationary"].to_numpy(float)) > 0.5
        still = shrink_runs(st, max(1, int(round(0.3 / float(np.median(np.diff(t)))))))
        note = "stops of the simulated truth (a simulated IMU has no vibration to detect)"
    else:
        still = detect_stillness(imu, DetectorConfig.from_dict(VEHICLE_DETECTOR)).still.to_numpy()
        note = "default vehicle detector"
    cp = inputs.control_points
    if cp is None and inputs.truth is not None and "stationary" in inputs.truth.columns:
        cp = control_points_at_stops(time_slice(inputs.truth, init.state.time))
    gnss = inputs.gnss
    if gnss is not None and len(gnss):
        gnss = gnss[~in_windows(gnss.index.to_numpy(float), outage_windows(job, gnss))]
    truth = inputs.truth if inputs.truth is not None else inputs.reference
    if truth is None:
        from ..errors import ConfigError

        raise ConfigError("the comparison needs a truth or reference trajectory",
                          file=job.path, column="inputs.reference.path")
    cfg = filter_config(job, model, init)
    cfg.smoother = args.solution == "smoothed"
    settings = _settings(args, False)
    if a["zupt_max_speed"] and note == "job detector":
        settings.max_speed = float(a["zupt_max_speed"])
    res = compare_runs(imu, init.state, time_slice(truth, init.state.time), still=still,
                       control_points=cp, gnss=gnss, gnss_lever_arm=inputs.lever_arm,
                       runs=_runs(args), config=cfg, settings=settings,
                       job_solutions=job_solutions, job_rejected=job_rejected,
                       truth_lever_arm=inputs.lever_arm if inputs.truth is None and
                       inputs.reference_point == "antenna" else None)
    name = job.simulation.get("scenario", {}).get("name") or job["job"]["name"]
    return res, f"{name} (still samples: {note})"


def run(args: argparse.Namespace) -> int:
    foot = args.job.is_dir()
    if foot:
        job, protect = None, [args.job / "imu.csv", args.job / "truth.csv", args.foot_config]
    else:
        from ..config import load_job

        job = load_job(args.job)
        protect = job.input_paths()
    with output_folder(args, args.output, protect=protect, names=OUTPUT_NAMES):
        return _run(args, job)


#: the files insgnss compare writes
OUTPUT_NAMES = ("compare_table.csv", "compare_summary.json", "drift_loglog.png",
                "errors_vs_time.png")


def _run(args, job) -> int:
    from ..compare import format_table, plot_drift, plot_errors
    from ..io.native import atomic_write, atomic_write_text

    res, title = _foot(args) if job is None else _vehicle(args, job)
    out = args.output
    atomic_write(out / "compare_table.csv",
                 lambda p: res.table.to_csv(p, float_format="%.6g"))
    summary = {"title": title, "runs": res.runs, "solution": res.settings.solution,
               "fit_window_s": list(res.settings.fit_window),
               "table": json.loads(res.table.to_json(orient="index")),
               "cupt_times": [float(x) for x in res.cupt_times],
               "still_fraction": float(res.still.mean()) if res.still.size else 0.0}
    atomic_write_text(out / "compare_summary.json", json.dumps(summary, indent=1) + "\n")
    if not args.no_figures:
        plot_drift(res, out / "drift_loglog.png", title=f"Drift: {title}")
        plot_errors(res, out / "errors_vs_time.png", title=title)
    print(title)
    print(format_table(res.table))
    print(f"wrote {out}")
    return 0
