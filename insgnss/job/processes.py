"""Process models of a job, as a table: each entry turns a prepared run (:class:`.RunContext`)
into a :class:`.JobResult` with the filter engine and a process model.

=============  ==============================================================================
process        what runs
=============  ==============================================================================
``strapdown``  LLF strapdown error-state filter + RTS smoother
               (:func:`insgnss.filter.engine.run_filter`) with the job's aiding;
               ``[filter] frame = "wander"``: the wander-azimuth process model
               (:func:`insgnss.filter.wander_model.run_wander_filter`, valid over the poles)
``riss``       the RISS process model (:func:`insgnss.filter.riss_model.run_riss_filter`):
               the same initialization, aiding, evaluation and summary, the odometer as the
               process input
``foot``       the foot-mounted pedestrian INS (:func:`insgnss.foot.run_foot_ins`): ZUPT/ZARU at
               every stance sample; heading unobservable, so it is given; ``[filter] coning``
               applies the engine's two-sample coning/sculling correction first
=============  ==============================================================================

Which one runs is data, not code: ``[process] preset`` names a process in :data:`PRESETS`
(``None`` leaves the choice to ``[filter] process_model``). A platform profile
(``[job] platform``) is a further row of such a table; a new process model is a function
added to :data:`PROCESSES`.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..config import Job
from ..errors import ConfigError, FilterHealthError, NoUsableAidingError
from ..filter.engine import FilterConfig, run_filter
from ..filter.heading_reinit import HeadingReinit
from ..filter.health import with_imu_note
from ..imu import ImuErrorModel, coning_sculling, increments, increments_table
from ..io.spill import SpillAllocator, release, release_frame, trim_heap
from ..policies import gap_noise, sample_rates
from ..preprocess import vibration_noise, with_static_noise
from ..validate import time_slice, warn
from .aiding import (
    Aiding,
    applied_check,
    build_aiding,
    check_aiding,
    course_track,
    measurement_counts,
)
from .context import RunContext
from .evaluation import evaluate_result
from .initialization import Initialization, initialize, standing_intervals
from .result import JobResult, PresetResult
from .summary import filter_summary, initialization_summary, job_name, platform_summary, status
from .tuning import Tuned, apply, autotune


def filter_config(job: Job, model: ImuErrorModel, init: Initialization,
                  spill_dir=None) -> FilterConfig:
    """The engine's :class:`~insgnss.filter.engine.FilterConfig` from ``[filter]`` and the
    initialization's sigmas; the smoother's node store beyond ``filter.store_memory_mb`` is
    memory-mapped in ``spill_dir`` (default: the system's temporary folder,
    :mod:`insgnss.io.spill`)."""
    f = job["filter"]
    return FilterConfig(
        store_allocate=SpillAllocator(f["store_memory_mb"] * 2.0**20, spill_dir),
        imu_model=model, bias_model=f["bias_model"], scale_factors=f["scale_factors"],
        propagation_interval=f["propagation_interval"], epoch_interval=f["epoch_interval"],
        epoch_grid=f["epoch_grid"],
        discretization=f["discretization"], kalman=f["kalman"],
        gate_probability=f["gate_probability"] or None,
        smoother=f["smoother"], initial_pos_std=init.pos_std, coning=f["coning"],
        initial_vel_std=job["initialization"]["velocity_std"] or init.vel_std,
        initial_att_std=tuple(np.radians(job["initialization"]["attitude_std_deg"]))
        if job["initialization"]["attitude_std_deg"] else init.att_std,
        levelling_correlation=init.levelled,
        gate_recovery=f["gate_recovery"] or None, nis_window=f["nis_window"] or None,
        nis_bound=f["nis_bound"],
        gyro_bias=None if init.gyro_bias is None else tuple(init.gyro_bias))


def heading_reinit(job: Job, aiding: Aiding, windows) -> HeadingReinit | None:
    """The heading re-initialisation of ``aiding.heading_reinit`` (LLF strapdown only: the
    wander-azimuth frame keeps its heading error in the ECEF frame) with the GNSS course of
    the epochs the run uses; None when off or without a course sample."""
    a = job["aiding"]
    if not a["heading_reinit"] or job["filter"]["frame"] == "wander":
        return None
    track = course_track(job, aiding.gnss_used, windows)
    if track is None:
        return None
    return HeadingReinit(track, angle=np.radians(a["heading_reinit_angle_deg"]),
                         duration=float(a["heading_reinit_duration"]),
                         min_speed=float(a["heading_reinit_min_speed"]))


def static_noise_model(ctx: RunContext, init: Initialization, model: ImuErrorModel
                       ) -> ImuErrorModel:
    """``filter.noise_from_static``: the IMU model with ARW/VRW raised to the noise measured in
    the truly still window the initialization found (:attr:`Initialization.noise_window`);
    without one, the model unchanged and a warning (noise measured on a moving hand would be
    its motion, not the sensor's noise)."""
    if not ctx.job["filter"]["noise_from_static"] or init.method != "static":
        return model
    if init.noise_window is None:
        note = ("filter.noise_from_static: no truly still window at the start; the IMU noise "
                f"model ({model.name}) is used as it is")
        ctx.preprocessing["static_noise"] = note
        warn(note, file=ctx.inputs.imu.attrs.get("source"), column="filter.noise_from_static")
        return model
    a, b = init.noise_window
    model = with_static_noise(model, time_slice(ctx.inputs.imu, a, b))
    ctx.preprocessing["gyro_arw_deg_sqrt_h"] = float(np.degrees(model.gyro_arw) * 60)
    ctx.preprocessing["accel_vrw_m_s_sqrt_h"] = float(model.accel_vrw * 60)
    ctx.preprocessing["static_noise_window"] = [float(a), float(b)]
    return model


def _filter_result(ctx: RunContext, init: Initialization, res, aiding: Aiding,
                   model: ImuErrorModel, n_imu: int, autotune: dict | None = None) -> JobResult:
    """Evaluate a finished filter run, check what it applied of each aiding source and build
    its :class:`JobResult` with the summary."""
    if isinstance(res.error, FilterHealthError) and res.final is not None:
        # name an IMU outlier that preceded the failure (insgnss.filter.health)
        imu = ctx.inputs.imu
        res.error = with_imu_note(res.error, imu.index.to_numpy(float),
                                  sample_rates(imu, "gyro")[1], sample_rates(imu, "accel")[1],
                                  float(res.final.time), ctx.job["filter"]["nis_window"] or 30.0)
    out = evaluate_result(JobResult(ctx.job, ctx.inputs, init, ctx.windows, res, model=model))
    counts = measurement_counts(aiding, res.innovations)
    out.failure, notes = applied_check(ctx.job, aiding, counts, res.innovations, res.complete)
    out.summary = filter_summary(out, counts, notes, model.name, n_imu, ctx.t_start,
                                 ctx.timing,
                                 {"imu": ctx.imu_report, "preprocessing": ctx.preprocessing,
                                  **({"autotune": autotune} if autotune else {})})
    return out


def _with_vibration_noise(ctx: RunContext, tuned: Tuned, imu, cfg: FilterConfig):
    """``filter.vibration_noise``: the extra process noise of the vibration measured in the
    quiet windows (:func:`insgnss.preprocess.vibration_noise`) merged into ``cfg.extra_noise``;
    the windows and densities go to ``summary.json`` ``preprocessing.vibration_noise``."""
    import pandas as pd

    from ..detect import find_static_windows

    ini = tuned.job["initialization"]
    bridged = [(g["start"], g["end"]) for g in ctx.imu_report["gaps"]
               if g.get("action") == "bridged"]
    quiet = find_static_windows(imu, max_accel_std=ini["static_max_accel_std"],
                                max_rate_std=np.radians(ini["static_max_rate_std_deg"]),
                                exclude=bridged).stationary
    # the IMU statistic cannot tell a steady drive from a stop: only where GNSS shows it stands
    stand = standing_intervals(tuned.inputs.gnss, tuned.windows)
    quiet = [(max(a, c), min(b, d)) for a, b in quiet for c, d in stand
             if min(b, d) > max(a, c)]
    xn = vibration_noise(imu, quiet, cfg.imu_model)
    n = 0 if xn is None else len(xn)
    ctx.preprocessing["vibration_noise"] = {
        "quiet_windows": len(quiet), "rows": n,
        "max_att_std_deg_per_step": 0.0 if not n else float(np.degrees(xn.att_std.max())),
        "max_vel_std_m_s_per_step": 0.0 if not n else float(xn.vel_std.max())}
    if xn is None:
        return cfg.extra_noise
    if cfg.extra_noise is None or not len(cfg.extra_noise):
        return xn
    return pd.concat([cfg.extra_noise, xn]).fillna(0.0).sort_index(kind="stable")


def _strapdown_filter(ctx: RunContext, tuned: Tuned, smoother: bool = True,
                      init: Initialization | None = None,
                      initial_parameters: dict | None = None):
    """Initialize (unless ``init``, the initialization of this job, inputs, model and windows,
    is given), build the aiding and run the strapdown filter for a (tuned) job:
    ``(filter result, initialization, aiding, IMU table)``. ``smoother=False`` is a run of the
    self-tuning: no smoother, no progress bar, no innovation gate and no runaway-NIS stop (a
    candidate noise model that fits badly is judged by its likelihood - robust to outliers,
    :mod:`insgnss.autotune` - not stopped or cut off by the gate, which would make the
    likelihood jump between nearby candidates). ``initial_parameters``: nominal start values
    of parameter states by label (:attr:`FilterConfig.initial_parameters`)."""
    job, inputs, model = tuned.job, tuned.inputs, tuned.model
    if init is None:
        init = initialize(job, inputs, model, tuned.windows)
    imu = time_slice(inputs.imu, init.state.time)
    aiding = build_aiding(job, inputs, tuned.windows, imu, _static_window(inputs, init))
    _record_still_threshold(ctx, aiding)
    aiding.require()
    cfg = filter_config(job, model, init, ctx.spill_dir)
    cfg.smoother = cfg.smoother and smoother
    cfg.initial_parameters = initial_parameters
    if not smoother:  # a self-tuning run: the likelihood judges the model, not the gate
        cfg.nis_window = None
        cfg.gate_probability = None
        cfg.gate_recovery = None
    if job["inputs"]["imu"]["gap_noise"]:
        cfg.extra_noise = gap_noise(imu, ctx.imu_report["gaps"])  # bridged IMU gaps
    if job["filter"]["vibration_noise"]:
        cfg.extra_noise = _with_vibration_noise(ctx, tuned, imu, cfg)
    cfg.heading_reinit = heading_reinit(job, aiding, tuned.windows)
    if job["filter"]["frame"] == "wander":
        from ..filter.wander_model import run_wander_filter

        res = run_wander_filter(imu, init.state, aiding.models, cfg)
    else:
        if ctx.progress and smoother:
            compile_before_progress(imu, init.state, aiding.models, cfg)
        res = run_filter(imu, init.state, aiding.models, cfg, progress=ctx.progress and smoother)
    if smoother:
        trim_heap()  # the increments, the smoother's temporaries (a long log: 100s of MiB)
        release_frame(inputs.imu)  # mapped IMU triads (job/inputs.py): their pages go back
        # and those of the node store's arrays the result keeps (the report reads a few rows)
        for name in ("P_filtered", "P_predicted", "Phi", "feedback", "P_smoothed"):
            a = getattr(res, name, None)
            if isinstance(a, np.ndarray):
                release(a)
    return res, init, aiding, imu


def relinearized_start(init: Initialization, smoothed) -> tuple[Initialization, dict]:
    """The start of a re-linearized pass (``[filter] smoother_passes`` = 2): the navigation
    state and parameter states (biases, scale factors, misalignment, pitch compliance, ...) of
    the smoothed table ``smoothed`` at its first row (the filter's start, ``init.state.time``),
    with the sigmas of ``init``. Returns ``(initialization, initial_parameters)``.

    The first pass's smoother already uses every epoch; the second pass integrates the same
    data about that estimate, so the errors the filter linearizes about (the heading before
    the GNSS course fixes it, the mounting before the misalignment states converge) are the
    small residuals of the first pass rather than the prior's: one Gauss-Newton step of an
    iterated smoother (Bell 1994), with the prior sigmas kept (the prior mean moves to the first
    pass's estimate, well inside those sigmas).
    """
    from ..mechanization import NavState
    from ..mechanization.core import NAV_COLS

    row = smoothed.iloc[0]
    st = init.state
    state = NavState.from_euler(float(row["lat"]), float(row["lon"]), float(row["height"]),
                                row[["vel_e", "vel_n", "vel_u"]].to_numpy(float),
                                float(row["roll"]), float(row["pitch"]), float(row["heading"]),
                                time=float(st.time))
    state.wander_angle = st.wander_angle
    skip = {*NAV_COLS, "time", "segment"}
    pars = {c: float(row[c]) for c in smoothed.columns
            if c not in skip and not c.endswith("_std") and np.isfinite(row[c])}
    gb = [pars.get(f"gyro_bias_{a}") for a in "xyz"]
    return replace(init, state=state,
                   gyro_bias=None if None in gb else np.array(gb, float)), pars


def _with_measured_violation(ctx: RunContext, tuned: Tuned, smoothed) -> Tuned:
    """``aiding.nhc_violation_from_data``: the NHC's violation measured in the first pass's
    smoothed solution (:func:`insgnss.nhc_violation.nhc_violation_estimate`) becomes the
    Gauss-Markov violation states of the next pass (``aiding.nhc_std`` its sigmas,
    ``aiding.nhc_correlation_time`` its correlation time; ``aiding.nhc_white_std`` stays the
    white part); recorded in ``summary.json`` ``preprocessing.nhc_violation``. A measurement
    without a correlation time or a finite sigma keeps the job's constraint (and warns)."""
    import copy

    from ..nhc_violation import nhc_violation_estimate

    est = nhc_violation_estimate(smoothed, tuned.windows)
    info = est.as_dict()
    ok = est.tau > 0 and all(np.isfinite(s) and s > 0 for s in est.std)
    info["applied"] = ok
    ctx.preprocessing["nhc_violation"] = info
    if not ok:
        warn(f"the NHC violation could not be measured ({est.samples} moving samples outside "
             f"the outages, correlation time {est.tau:.3g} s): the constraint of "
             f"aiding.nhc_std is kept", file=tuned.job.path, column="aiding.nhc_violation_from_data")
        return tuned
    settings = copy.deepcopy(tuned.job.settings)
    settings["aiding"]["nhc_std"] = [float(s) for s in est.std]
    settings["aiding"]["nhc_correlation_time"] = float(est.tau)
    return replace(tuned, job=replace(tuned.job, settings=settings))


def _static_window(inputs, init: Initialization):
    """The IMU samples of the static initialization window (None without one)."""
    if init.static_end is None:
        return None
    return time_slice(inputs.imu, init.state.time, init.static_end)


def _record_still_threshold(ctx: RunContext, aiding) -> None:
    if aiding.still_threshold is not None:
        ctx.preprocessing["zupt_detector_threshold_m_s2"] = aiding.still_threshold


def run_strapdown(ctx: RunContext) -> JobResult:
    """LLF strapdown error-state filter (+ smoother) with the job's aiding; with
    ``filter.autotune`` the noise parameters estimated first (:mod:`.tuning`)."""
    job, inputs, model = ctx.job, ctx.inputs, ctx.model
    check_aiding(job, inputs, ctx.windows)
    init = initialize(job, inputs, model, ctx.windows)
    first = model
    model = static_noise_model(ctx, init, model)
    tuned = Tuned(job, inputs, model, list(ctx.windows))
    tune_result = None
    if job["filter"]["autotune"]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the final run below warns about its own data
            theta, tune_result = autotune(
                ctx, model, lambda t: _strapdown_filter(ctx, t, False)[0],
                lambda t: build_aiding(t.job, t.inputs, t.windows, t.inputs.imu))
        tuned = apply(ctx, model, theta)
    # the same job, inputs, IMU model and windows: the same initialization (the static-window
    # search over the whole log is not repeated)
    same = tuned.job is job and tuned.inputs is inputs and tuned.model is first
    res, init, aiding, imu = _strapdown_filter(ctx, tuned, init=init if same else None)
    relin = job["filter"]["smoother_passes"] > 1
    from_data = bool(job["aiding"]["nhc"] and job["aiding"]["nhc_violation_from_data"])
    for k in range(max(job["filter"]["smoother_passes"] - 1, int(from_data))):
        if not (res.complete and res.smoothed is not None):
            break
        if from_data and k == 0:
            tuned = _with_measured_violation(ctx, tuned, res.smoothed)
        pars = None
        if relin:
            init, pars = relinearized_start(init, res.smoothed)
        res, init, aiding, imu = _strapdown_filter(ctx, tuned, init=init,
                                                   initial_parameters=pars)
    if tuned.job is not job and tune_result is None:
        ctx = replace(ctx, job=tuned.job)
    if tune_result is not None:
        ctx = replace(ctx, job=tuned.job, inputs=tuned.inputs)
    return _filter_result(ctx, init, res, aiding, tuned.model, len(imu),
                          None if tune_result is None else tune_result.as_dict())


#: IMU span [s] of the warm-up run of :func:`compile_before_progress`: a few filter epochs and
#: the first GNSS / constraint updates
WARM_SPAN = 3.0


def compile_before_progress(imu, state, models, cfg: FilterConfig) -> None:
    """Run the filter over the first :data:`WARM_SPAN` seconds without a progress bar, so that
    the compiled kernels (numba: compiled on the first call, or loaded from the cache) are
    ready before the progress bar starts and its ETA measures the filter, not the compiler.
    A warm-up that fails leaves the error to the real run."""
    from ..errors import InsgnssError

    part = time_slice(imu, None, float(imu.index[0]) + WARM_SPAN)
    if len(part) < 3:
        return
    try:
        run_filter(part, state, models, cfg, progress=False)
    except InsgnssError:
        pass


def run_riss(ctx: RunContext) -> JobResult:
    """``[filter] process_model = "riss"``: the same initialization, aiding, evaluation and
    summary as the strapdown job, with the RISS process model (:mod:`insgnss.filter.riss_model`);
    the job's odometer is the process input (``aiding.odometer`` would use it twice)."""
    from ..filter import riss_model

    job, inputs, model = ctx.job, ctx.inputs, ctx.model
    if inputs.odometer is None or not len(inputs.odometer):
        raise ConfigError("the RISS process model needs an odometer (inputs.odometer.path or a "
                          "simulated [odometer])", file=job.path, column="inputs.odometer.path")
    if job["aiding"]["odometer"]:
        raise ConfigError("with process_model = \"riss\" the odometer is the process input; "
                          "switch aiding.odometer off", file=job.path, column="aiding.odometer")
    check_aiding(job, inputs, ctx.windows)
    init = initialize(job, inputs, model, ctx.windows)
    odo = inputs.odometer
    t_odo = odo.index.to_numpy(float)
    imu = inputs.imu.loc[max(init.state.time, t_odo[0]):t_odo[-1]]
    if len(imu) < 2:
        raise ConfigError("the odometer does not overlap the IMU data", file=job.path,
                          column="inputs.odometer.path")
    if float(imu.index[0]) != init.state.time:
        init.state = init.state.copy()
        init.state.time = float(imu.index[0])
    aiding = build_aiding(job, inputs, ctx.windows, imu, _static_window(inputs, init))
    _record_still_threshold(ctx, aiding)
    aiding.require()
    cfg = filter_config(job, model, init, ctx.spill_dir)
    # aiding.odometer_std is the odometer speed noise; filter.scale_factors estimates the
    # vertical gyro scale factor
    rcfg = riss_model.RissConfig(odometer_speed_std=float(job["aiding"]["odometer_std"]),
                                 gyro_scale=bool(job["filter"]["scale_factors"]),
                                 **job["filter"]["riss"])
    res = riss_model.run_riss_filter(imu, odo, init.state, aiding.models, cfg, rcfg)
    return _filter_result(ctx, init, res, aiding, model, len(imu))


def run_foot(ctx: RunContext) -> JobResult:
    """Foot-mounted pedestrian INS (:mod:`insgnss.foot`): compiled ZUPT/ZARU filter and
    smoother; heading unobservable, so it is given (``[foot] heading``, default 0)."""
    from ..filter.height_aiding import BARO_COLUMNS
    from ..foot import FootConfig, run_foot_ins
    from ..strides import walk_distances

    job, inputs = ctx.job, ctx.inputs
    cfg = FootConfig.from_dict(job["foot"])
    ini = job["initialization"]
    # the given start; a simulated job starts where its truth does
    start = inputs.truth.iloc[0] if inputs.truth is not None else None
    lat = np.radians(ini["lat_deg"]) if ini["lat_deg"] is not None else \
        (float(start["lat"]) if start is not None else 0.0)
    lon = np.radians(ini["lon_deg"]) if ini["lon_deg"] is not None else \
        (float(start["lon"]) if start is not None else 0.0)
    h = ini["height"] if ini["height"] is not None else \
        (float(start["height"]) if start is not None else 0.0)
    c0 = time.perf_counter()
    imu = inputs.imu
    baro = [c for c in BARO_COLUMNS if c in imu.columns]
    baro = imu[baro[:1]] if baro else None  # barometer height (the IMU table's column)
    if job["filter"]["coning"]:
        # the same two-sample coning/sculling correction the engine applies (docs/zupt.md:
        # without it integrated increments make a 60 Hz foot INS climb 0.4 m per 100 m)
        t, dth, dv = increments(imu)
        imu = increments_table(t, *coning_sculling(dth, dv))
    fr = run_foot_ins(imu, cfg, lat=lat, lon=lon, height=h, baro=baro)
    run_s = time.perf_counter() - c0
    inn = fr.innovations.reset_index()
    inn = inn.rename(columns={inn.columns[0]: "time"})
    inn.insert(1, "type", "zupt")
    inn["accepted"] = True
    res = PresetResult(forward=fr.forward.join(fr.std).join(fr.biases),
                       smoothed=fr.trajectory if cfg.smooth else None, innovations=inn,
                       rejected=inn.iloc[:0], timing={"total": run_s})
    init = Initialization(fr.initial, "foot_levelling", "given")
    out = evaluate_result(JobResult(job, inputs, init, ctx.windows, res))
    still = int(fr.stillness.still.sum())
    if not fr.n_updates:
        out.failure = NoUsableAidingError(
            f"the foot-mounted INS rests on zero-velocity updates, but the stance detector "
            f"([foot.detector]) found {still} still sample(s) and the filter applied none",
            file=inputs.imu.attrs.get("source"), column="foot.detector")
    en = ["east", "north"]
    distance = walk_distances(fr.forward[en].to_numpy(), fr.stillness.still.to_numpy(bool),
                              fr.trajectory[en].to_numpy() if cfg.smooth else None)
    out.summary = {
        "job": job_name(job), "source": inputs.source, **status(out),
        "preset": "foot", "platform": platform_summary(job),
        "imu_samples": int(len(inputs.imu)), "zupt_updates": fr.n_updates,
        "initialization": initialization_summary(init),
        "measurements": {"zupt": {"offered": still, "applied": int(fr.n_updates),
                                  "rejected": 0, "recovered": 0, "unusable": 0}},
        "aiding_warnings": [],
        "distance": distance,
        "stance_threshold": None if fr.selection is None else {
            "selection": "innovation", "family": fr.selection.family,
            "log10": fr.selection.log10, "stance_entry_rms_m_s": fr.selection.criterion,
            "candidates": len(fr.selection.table)},
        "height_aiding": fr.height_aiding,
        "imu": ctx.imu_report, "preprocessing": ctx.preprocessing,
        "timing_s": {**ctx.timing, "total": run_s,
                     "job_total": time.perf_counter() - ctx.t_start},
        "evaluation": {k: v["summary"] for k, v in out.evaluation.items()},
    }
    return out


#: process name -> the function that runs it
PROCESSES: dict[str, Callable[[RunContext], JobResult]] = {
    "strapdown": run_strapdown,
    "riss": run_riss,
    "foot": run_foot,
}

#: ``[process] preset`` -> the process it selects (None: ``[filter] process_model`` decides)
PRESETS: dict[str, str | None] = {"standard": None, "foot": "foot"}


def process_name(job: Job) -> str:
    """The process a job runs (:data:`PRESETS`, then ``[filter] process_model``)."""
    return PRESETS[job["process"]["preset"]] or job["filter"]["process_model"]


def run_process(ctx: RunContext) -> JobResult:
    """Run the job's process (:func:`process_name`) on a prepared run."""
    return PROCESSES[process_name(ctx.job)](ctx)


__all__ = ["PRESETS", "PROCESSES", "compile_before_progress", "filter_config", "process_name",
           "run_foot", "run_process", "run_riss", "run_strapdown"]
