"""Self-tuning of a job's noise parameters (``[filter] autotune = true``): which parameters a
job can estimate, how a value of each reaches the filter, and the maximum-likelihood search
(:func:`insgnss.autotune.tune`) over filter runs of the job.

=========================  ===========================================  ====================
parameter                  what it sets                                 informed by
=========================  ===========================================  ====================
``imu_time_offset``        added to the IMU time stamps [s]             GNSS
``gnss_pos_scale_q<Q>``    ``aiding.q_scale[Q]``: the std multiplier    GNSS position
                           of the GNSS epochs with quality flag Q
``gnss_vel_scale``         ``aiding.gnss_velocity_std_scale``           GNSS velocity
``accel_vrw``              accelerometer white noise [m/s/sqrt(s)]      every aiding
``gyro_arw``               gyro white noise [rad/sqrt(s)]               every aiding
``accel_bias_instability`` accelerometer bias instability [m/s^2]       every aiding
``gyro_bias_instability``  gyro bias instability [rad/s]                every aiding
``nhc_std``                ``aiding.nhc_std`` (lateral; the vertical    NHC
                           keeps its ratio) [m/s]; only when
                           ``autotune_parameters`` names it
``zupt_std``               ``aiding.zupt_std`` [m/s]                    ZUPT
=========================  ===========================================  ====================

A parameter is offered only when the job has the measurements that inform it (a Q flag with
at least :data:`MIN_EPOCHS` usable epochs, NHC or ZUPT switched on). The filter runs use only
what the run itself may use: the same aiding, with the outage windows withheld
(:func:`insgnss.job.aiding.build_aiding`), and no smoother (the likelihood is the forward
filter's). ``[filter] autotune_parameters`` restricts the list.
"""

from __future__ import annotations

import copy
import logging
import time
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from ..attitude import euler_to_dcm
from ..autotune import COAST_SUFFIX, Parameter, TuneResult, tune
from ..config import Job
from ..earth import ecef_to_enu_vectors, geodetic_to_ecef
from ..errors import ConfigError, InsgnssError
from ..executors import ForkedHelpers
from ..imu import ImuErrorModel
from ..preprocess import shift_time
from .context import RunContext
from .inputs import Inputs
from .windows import outside_windows

_log = logging.getLogger("insgnss.autotune")

#: measurement types of the one-step view (stage 1 of the self-tuning)
ONE_STEP = ("gnss_pos", "gnss_vel", "zupt", "zaru", "nhc", "odometer", "cupt", "heading")

#: parameters tuned only when ``[filter] autotune_parameters`` names them: the NHC sigma. The
#: constraint's violations (side slip, suspension heave) are correlated over seconds, far longer
#: than its 0.25 s update interval, and a filter with a white model absorbs their slow part into
#: its velocity and attitude: the one-step likelihood then prefers a sigma well below the true
#: one (on simulated cars with a 0.1 m/s, 2 s slip: 0.05 m/s), and that sigma lets the
#: constraint steer the dead reckoning in an outage (``bench/bench_nhc_sigma.py``). The
#: platform profile's sigma holds instead (docs/filter.md, "Self-tuning").
EXPLICIT_ONLY = ("nhc_std",)
#: fewest usable GNSS epochs of one quality flag for its sigma scale to be tuned
MIN_EPOCHS = 20
#: search range of the IMU time offset [s] (the logging delays seen are 0.05-0.15 s)
TIME_OFFSET_RANGE = 0.3
#: search range of noise scales: a factor either way of the prior
NOISE_RANGE = 30.0


#: coast horizon [s] of the tuning windows of a job without outage windows (a typical GNSS
#: outage under a bridge or in an urban canyon)
DEFAULT_HORIZON = 15.0
#: GNSS time [s] left to the filter after its first epoch before a tuning window may start
TUNING_SETTLE = 30.0


@dataclass
class Tuned:
    """A job with a parameter set applied: the job (aiding keys changed), its inputs (IMU time
    shifted), the filter's IMU model and the GNSS outage windows of the run (the job's, plus
    the tuning windows in a self-tuning run)."""

    job: Job
    inputs: Inputs
    model: ImuErrorModel
    windows: list


def tuning_windows(windows, gnss, horizon: float | None = None) -> list[tuple[float, float]]:
    """Tuning windows of the coast view: in every stretch of usable GNSS (between the job's
    outage windows, from :data:`TUNING_SETTLE` after the first epoch to the last) at least 1.5
    horizons long, one window of ``horizon`` seconds in its middle. ``horizon``: the mean
    length of the job's outage windows, else :data:`DEFAULT_HORIZON`. The GNSS inside them is
    withheld from the self-tuning's filter runs and predicted by their dead reckoning."""
    if gnss is None or len(gnss) < 2:
        return []
    if horizon is None:
        horizon = float(np.mean([b - a for a, b in windows])) if windows else DEFAULT_HORIZON
    t0, t1 = float(gnss.index[0]) + TUNING_SETTLE, float(gnss.index[-1])
    spans, prev = [], t0
    for a, b in sorted(windows):
        spans.append((prev, a))
        prev = max(prev, b)
    spans.append((prev, t1))
    out = []
    for a, b in spans:
        if b - a >= 1.5 * horizon:
            c = 0.5 * (a + b)
            out.append((c - 0.5 * horizon, c + 0.5 * horizon))
    return out


def coast_rows(forward: pd.DataFrame, gposition, tuning: list) -> pd.DataFrame:
    """The coast view's rows: every GNSS position the job would use (``gposition``, the
    :class:`~insgnss.filter.measurements.GnssPosition` model of the production aiding) inside a
    tuning window, against the forward solution there (antenna point, ENU residuals), with
    ``innov_std_k = sqrt(P_k + R_k)`` from the forward sigmas and the GNSS sigmas: the
    innovation log format (type ``gnss_pos_coast``)."""
    if gposition is None or not tuning or not len(forward):
        return pd.DataFrame()
    t = np.asarray(gposition.times, float)
    sel = np.zeros(t.size, bool)
    for a, b in tuning:
        sel |= (t >= a) & (t < b)
    sel &= np.asarray(gposition.valid, bool)
    tf = forward.index.to_numpy(float)
    sel &= (t >= tf[0]) & (t <= tf[-1])
    idx = np.flatnonzero(sel)
    if not idx.size:
        return pd.DataFrame()
    k = np.clip(np.searchsorted(tf, t[idx]), 1, tf.size - 1)
    k = np.where(np.abs(tf[k - 1] - t[idx]) < np.abs(tf[k] - t[idx]), k - 1, k)
    f = forward.iloc[k]
    C = euler_to_dcm(f["roll"].to_numpy(), f["pitch"].to_numpy(), f["heading"].to_numpy())
    arm = C @ np.asarray(gposition.lever_arm, float)
    g = gposition.pos[idx]
    lat, lon = f["lat"].to_numpy(), f["lon"].to_numpy()
    d = np.column_stack(geodetic_to_ecef(g[:, 0], g[:, 1], g[:, 2])) - \
        np.column_stack(geodetic_to_ecef(lat, lon, f["height"].to_numpy()))
    resid = arm - ecef_to_enu_vectors(d, lat, lon)  # predicted antenna minus measured, ENU
    P = f[["east_std", "north_std", "up_std"]].to_numpy(float)
    S = np.sqrt(P ** 2 + gposition.std[idx] ** 2)
    rows = {"time": t[idx], "type": "gnss_pos" + COAST_SUFFIX, "dof": 3,
            "nis": np.sum((resid / S) ** 2, axis=1), "threshold": np.inf, "accepted": False,
            "recovered": False}
    for j in range(3):
        rows[f"innov_{j}"] = resid[:, j]
    for j in range(3):
        rows[f"innov_std_{j}"] = S[:, j]
    return pd.DataFrame(rows)


def parameters(ctx: RunContext, model: ImuErrorModel) -> list[Parameter]:
    """The parameters the job can tune (module docstring), priors from the job and ``model``."""
    job, inputs = ctx.job, ctx.inputs
    a = job["aiding"]
    out = []
    gnss = inputs.gnss
    if gnss is not None and len(gnss) and (a["gnss_position"] or a["gnss_velocity"]):
        out.append(Parameter("imu_time_offset", 0.0, -TIME_OFFSET_RANGE, TIME_OFFSET_RANGE,
                             step=0.02, log=False, unit="s",
                             doc="added to the IMU time stamps"))
    if gnss is not None and len(gnss) and a["gnss_position"]:
        g = outside_windows(gnss, ctx.windows)
        scale = {int(float(k)): float(v) for k, v in a["q_scale"].items()}
        if "q" in g.columns:
            q = g["q"].to_numpy()
            for flag in sorted(scale):
                if np.count_nonzero(q == flag) >= MIN_EPOCHS:
                    p = scale[flag]
                    out.append(Parameter(f"gnss_pos_scale_q{flag}", p, p / 5, p * NOISE_RANGE,
                                         doc=f"std multiplier of the Q={flag} GNSS positions"))
        else:
            p = a["gnss_std_scale"]
            out.append(Parameter("gnss_pos_scale", p, p / 5, p * NOISE_RANGE,
                                 doc="std multiplier of the GNSS positions"))
    if gnss is not None and len(gnss) and a["gnss_velocity"] and "vel_e" in gnss.columns:
        p = a["gnss_velocity_std_scale"]
        out.append(Parameter("gnss_vel_scale", p, p / 10, p * NOISE_RANGE,
                             doc="std multiplier of the GNSS velocities"))
    for name, unit, doc in (
            ("accel_vrw", "m/s/sqrt(s)", "accelerometer white noise (VRW)"),
            ("gyro_arw", "rad/sqrt(s)", "gyro white noise (ARW)"),
            ("accel_bias_instability", "m/s^2", "accelerometer bias instability"),
            ("gyro_bias_instability", "rad/s", "gyro bias instability")):
        p = float(getattr(model, name))
        if p > 0:
            out.append(Parameter(name, p, p / NOISE_RANGE, p * NOISE_RANGE, unit=unit, doc=doc))
    if a["nhc"]:
        p = float(a["nhc_std"][0])
        out.append(Parameter("nhc_std", p, p / 10, p * 10, unit="m/s",
                             doc="NHC lateral sigma (the vertical keeps its ratio)"))
    if a["zupt"]:
        p = float(a["zupt_std"])
        out.append(Parameter("zupt_std", p, p / 10, p * 10, unit="m/s", doc="ZUPT sigma"))
    wanted = job["filter"]["autotune_parameters"]
    if wanted is None:
        out = [p for p in out if p.name not in EXPLICIT_ONLY]
    else:
        names = {p.name for p in out}
        unknown = sorted(set(wanted) - names)
        if unknown:
            raise ConfigError("autotune parameter not available for this job", file=job.path,
                              column="filter.autotune_parameters",
                              expected=f"some of {sorted(names)}", found=unknown)
        out = [p for p in out if p.name in wanted]
    return out


def apply(ctx: RunContext, model: ImuErrorModel, theta: dict, shifted: dict | None = None
          ) -> Tuned:
    """The job, inputs and IMU model with the parameter values ``theta`` (module docstring).
    ``shifted``: a cache ``{imu_time_offset: inputs}`` of the time-shifted inputs, so that the
    runs of one offset share one IMU table."""
    job, inputs = ctx.job, ctx.inputs
    settings = copy.deepcopy(job.settings)
    a = settings["aiding"]
    changes = {}
    for name, v in theta.items():
        if name == "imu_time_offset":
            if v and shifted is not None and float(v) in shifted:
                inputs = shifted[float(v)]
            elif v:
                inputs = replace(inputs, imu=shift_time(inputs.imu, float(v)))
                if shifted is not None:
                    shifted[float(v)] = inputs
        elif name.startswith("gnss_pos_scale_q"):
            flag = name[len("gnss_pos_scale_q"):]
            key = next(k for k in a["q_scale"] if int(float(k)) == int(flag))
            a["q_scale"][key] = float(v)
        elif name == "gnss_pos_scale":
            a["gnss_std_scale"] = float(v)
        elif name == "gnss_vel_scale":
            a["gnss_velocity_std_scale"] = float(v)
        elif name == "nhc_std":
            lat, ver = a["nhc_std"]
            a["nhc_std"] = [float(v), float(v) * float(ver) / float(lat)]
        elif name == "zupt_std":
            a["zupt_std"] = float(v)
        else:
            changes[name] = float(v)
    if changes:
        model = model.scaled(**changes, name=f"{model.name}+autotune")
    return Tuned(replace(job, settings=settings), inputs, model, list(ctx.windows))


def autotune(ctx: RunContext, model: ImuErrorModel, run_one, build_aiding
             ) -> tuple[dict, TuneResult]:
    """Estimate the job's parameters by maximum likelihood.

    ``run_one(tuned: Tuned) -> FilterResult`` runs the job's filter (forward only) with a
    parameter set applied (the process model's own setup); ``build_aiding(tuned) -> Aiding``
    builds the job's aiding for it. The runs withhold the GNSS of
    the tuning windows too (:func:`tuning_windows`); their likelihood is the one-step view
    (the innovation log) and the coast view (:func:`coast_rows`). Returns ``(theta, result)``:
    the values to use and the :class:`~insgnss.autotune.TuneResult`.

    Work done once, not per filter run: the time-shifted inputs per offset value and the
    production GNSS position model per set of GNSS scales and offset. The runs the search
    needs together (the two sides of a bracket) run at once on the further cores
    (:class:`insgnss.executors.ForkedHelpers`: helpers forked once for the whole search,
    deterministic runs, so the same result as one after the other). The result records the
    filter runs of each stage and the wall time (``seconds``).
    """
    params = parameters(ctx, model)
    if not params:
        raise ConfigError("filter.autotune: the job has no measurement that informs a noise "
                          "parameter", file=ctx.job.path, column="filter.autotune")
    tuning = tuning_windows(ctx.windows, ctx.inputs.gnss) \
        if ctx.job["aiding"]["gnss_position"] else []

    shifted: dict = {}  # imu_time_offset -> shifted inputs (one IMU table per offset)
    gpositions: dict = {}  # (GNSS scales, offset) -> the production GNSS position model

    def production_gpos(theta):
        """The GNSS positions the production run would use (its windows only): those inside
        the tuning windows are the coast view's measurements. They depend on the GNSS sigma
        scales and (through the IMU span) the time offset only: built once per such set."""
        k = tuple(sorted((n, v) for n, v in theta.items()
                         if n.startswith("gnss_pos_scale") or n == "imu_time_offset"))
        if k not in gpositions:
            prod = apply(ctx, model, theta, shifted)
            gpositions[k] = next((m for m in build_aiding(prod).models
                                  if m.name == "gnss_pos"), None)
        return gpositions[k]

    def run(theta):
        t = apply(ctx, model, theta, shifted)
        t.windows = sorted(list(ctx.windows) + tuning)
        try:
            res = run_one(t)
        except InsgnssError:
            return None
        if not res.complete:
            return None
        coast = coast_rows(res.forward, production_gpos(theta), tuning)
        return pd.concat([res.innovations, coast], ignore_index=True) if len(coast) else \
            res.innovations

    cache: dict = {}

    def key(theta):
        return tuple(sorted(theta.items()))

    def cached(theta):  # both stages run the same filter: reuse what the first one ran
        k = key(theta)
        if k not in cache:
            cache[k] = run(theta)
        return cache[k]

    def cached_many(thetas):  # independent new runs: on the further cores (forked helpers)
        keys = [key(th) for th in thetas]
        todo = {k: th for k, th in zip(keys, thetas, strict=True) if k not in cache}
        cache.update(zip(todo, helpers.map(list(todo.values())), strict=True))
        return [cache[k] for k in keys]

    with ForkedHelpers(run) as helpers:  # forked at the first pair, kept for the search
        return _search(ctx, params, tuning, cached, cached_many)


def _search(ctx: RunContext, params: list[Parameter], tuning: list, cached, cached_many):
    """The two stages of :func:`autotune` over the filter runs ``cached(theta)`` and
    ``cached_many(thetas)``: ``(theta, result)``."""
    t_start = time.perf_counter()
    sweeps = int(ctx.job["filter"]["autotune_sweeps"])
    log = lambda line: _log.info("autotune: %s", line)  # noqa: E731
    # stage 1: the one-step view only, from the priors (a model far off makes the dead
    # reckoning of the coast view diverge, and its likelihood surface rugged)
    first = tune(cached, params, sweeps=sweeps, types=ONE_STEP, progress=log,
                 run_many=cached_many)
    if not tuning:
        first.seconds = time.perf_counter() - t_start
        return first.values, first
    # stage 2: both views, from the one-step estimates
    start = [replace(p, prior=min(max(first.values[p.name], p.lower), p.upper)) for p in params]
    second = tune(cached, start, sweeps=sweeps, progress=log,
                  reference={p.name: p.prior for p in params}, run_many=cached_many)
    for name, row in second.parameters.items():
        row["one_step_estimate"] = first.parameters[name]["estimate"]
    second.log_likelihood["one_step_prior"] = first.log_likelihood["prior"]
    second.log_likelihood["one_step_final"] = first.log_likelihood["final"]
    second.evaluations += first.evaluations
    second.sweeps += first.sweeps
    second.tuning_windows = [list(w) for w in tuning]
    second.one_step_evaluations = first.evaluations
    second.seconds = time.perf_counter() - t_start
    values = second.values
    return values, second


__all__ = ["EXPLICIT_ONLY", "MIN_EPOCHS", "Tuned", "apply", "autotune", "parameters"]
