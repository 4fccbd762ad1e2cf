"""Monte Carlo studies of a simulated job: N runs with independent seeds, one statistics table.

A Monte Carlo job is a scenario file that both simulates and processes (``[scenario]
[trajectory] [imu] [gnss]`` ... plus the processing tables of docs/jobs.md) and may carry a
``[montecarlo]`` table (:class:`MonteCarloSettings`). Each run

1. simulates the scenario with its own seed (IMU errors, GNSS noise; the trajectory is the
   same in every run), runs the job's filter and smoother (:func:`insgnss.pipeline.run_job`);
2. samples the solutions on a common time grid (every ``grid_interval`` s of the job time base,
   at IMU samples) and returns only small arrays (:class:`RunRecord`): the errors (estimate
   minus truth) of position (ENU metres with the local radii, and horizontal), velocity (ENU)
   and roll/pitch/heading (wrapped), the filter's standard deviations of the same quantities,
   the NEES of the position, velocity and attitude blocks and the NIS of every measurement.

Seeds: the master seed feeds ``numpy.random.SeedSequence(master).spawn(N)``; run ``i`` gets the
63-bit integer ``child_i.generate_state(1, uint64) >> 1``, which the simulator's own
SeedSequence expands into its sensor streams. So a run depends only on (master seed, ``i``):
re-running reproduces every run bit for bit on any back-end, and a study with more runs
extends a smaller one (same first runs).

Aggregation per solution, quantity and epoch over the successful runs (:func:`aggregate`):
``mean`` (signed), ``rms``, percentiles of the *absolute* error (``p68 p95 p99`` by default),
``sigma`` = RMS over the runs of the filter's standard deviation. NEES (dof 3) and NIS (dof of
the measurement) are averaged over the ``n`` runs and compared with the two-sided chi-square
bounds ``chi2.ppf((1 -+ c) / 2, n dof) / n`` (Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4;
Groves 2013, sec. 17.4). Coverage check: at each epoch the filter's ``k sigma`` (k = 3) against
the ``q``-th percentile (q = 99) of the absolute error; the fraction of epochs where it covers.
For a Gaussian error that the filter describes, ``p99 = 2.58 sigma`` (one axis) and ``3.03
sigma`` for the horizontal error of a circular distribution, whose sigma here is
``hypot(east_std, north_std)`` (``sqrt 2`` times the per-axis sigma).

Outputs (:meth:`MonteCarloResult.write`, every file atomically): ``montecarlo.parquet`` (tidy:
one row per run, solution, quantity and epoch; Parquet via pyarrow, CSV without it),
``statistics.parquet`` (the per-epoch aggregates), ``summary.json`` (seeds, failures,
percentile table at the outage ends, NEES/NIS, coverage check, throughput) and the figures
``envelopes.png`` (error percentile envelopes vs 1 and 3 sigma) and ``consistency.png``.
"""

from __future__ import annotations

import copy
import json
import time as _time
import tomllib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .config import Job, load_job_dict
from .consistency import (  # noqa: F401  (re-exported: the Monte Carlo API names them)
    ANGLE_QUANTITIES,
    ERROR_QUANTITIES,
    NEES_BLOCKS,
    STD_OF,
    TIME_TOL,
    chi2_bounds,
    match_times,
    nees_blocks,
    solution_errors,
    wrap_angle,
)
from .errors import ConfigError, FilterHealthError
from .outages import in_windows

__all__ = ["ERROR_QUANTITIES", "NEES_BLOCKS", "MonteCarloResult", "MonteCarloSettings",
           "RunRecord", "aggregate", "draw_seeds", "envelope_figure", "percentile_table",
           "record_from_result", "run_montecarlo", "run_one"]

SOLUTIONS = ("forward", "smoothed")


# --- settings ---------------------------------------------------------------------------------
@dataclass
class MonteCarloSettings:
    """The ``[montecarlo]`` table of a job file (every key optional).

    Attributes
    ----------
    runs : int
        Number of runs (>= 1; the CLI's ``--runs`` overrides it).
    seed : int or None
        Master seed (>= 0; ``--seed`` overrides). ``None``: drawn from the OS entropy and
        recorded in the summary.
    grid_interval : float
        Common epoch grid [s]: job times that are multiples of it (within 1 us) at IMU samples.
    solutions : list of str
        ``forward`` and/or ``smoothed`` (a missing smoothed solution is skipped).
    percentiles : list of float
        Percentiles of the absolute error per epoch (0 < q < 100).
    confidence : float
        Two-sided probability of the NEES/NIS chi-square bounds.
    coverage_sigma, coverage_percentile, coverage_required : float
        Coverage check: ``coverage_sigma * sigma >= p(coverage_percentile)`` at a fraction
        ``>= coverage_required`` of the epochs (``coverage_percentile`` must be one of
        ``percentiles``).
    settle_time : float
        Epochs earlier than this after the first grid epoch are left out of the summary
        numbers (NEES/NIS fractions, coverage) [s]; the tables keep them.
    """

    runs: int = 100
    seed: int | None = None
    grid_interval: float = 1.0
    solutions: list = field(default_factory=lambda: list(SOLUTIONS))
    percentiles: list = field(default_factory=lambda: [68.0, 95.0, 99.0])
    confidence: float = 0.95
    coverage_sigma: float = 3.0
    coverage_percentile: float = 99.0
    coverage_required: float = 0.95
    settle_time: float = 0.0

    @classmethod
    def from_table(cls, table: dict | None, file=None) -> MonteCarloSettings:
        """Validate a ``[montecarlo]`` table; errors name ``montecarlo.<key>`` and the file."""
        table = {} if table is None else table
        if not isinstance(table, dict):
            raise ConfigError("must be a table", file=file, column="montecarlo",
                              found=type(table).__name__)
        names = [f for f in cls.__dataclass_fields__]
        s = cls()
        for key, v in table.items():
            col = f"montecarlo.{key}"

            def bad(msg, expected=None, v=v, col=col):
                return ConfigError(msg, file=file, column=col, expected=expected, found=repr(v))

            if key not in names:
                raise ConfigError("unknown key", file=file, column=col,
                                  expected=f"one of {sorted(names)}", found=repr(key))
            if key in ("runs", "seed"):
                if isinstance(v, bool) or not isinstance(v, int) or v < (1 if key == "runs"
                                                                         else 0):
                    raise bad("wrong value", "a positive integer" if key == "runs"
                              else "a non-negative integer")
            elif key == "solutions":
                if not isinstance(v, list) or not v or any(x not in SOLUTIONS for x in v):
                    raise bad("wrong value", f"a non-empty list of {list(SOLUTIONS)}")
                v = list(dict.fromkeys(v))
            elif key == "percentiles":
                if (not isinstance(v, list) or not v or any(
                        isinstance(x, bool) or not isinstance(x, int | float) or not 0 < x < 100
                        for x in v)):
                    raise bad("wrong value", "a non-empty list of numbers in (0, 100)")
                v = sorted({float(x) for x in v})
            else:
                if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
                    raise bad("wrong type", "a number")
                v = float(v)
                if key in ("grid_interval", "coverage_sigma") and v <= 0:
                    raise bad("must be positive")
                if key in ("confidence", "coverage_required") and not 0 < v < 1:
                    raise bad("must be in (0, 1)")
                if key == "coverage_percentile" and not 0 < v < 100:
                    raise bad("must be in (0, 100)")
                if key == "settle_time" and v < 0:
                    raise bad("must not be negative")
            setattr(s, key, v)
        if s.coverage_percentile not in s.percentiles:
            s.percentiles = sorted({*s.percentiles, s.coverage_percentile})
        return s

    def to_dict(self) -> dict:
        return asdict(self)


def pct_name(q: float) -> str:
    """Column name of a percentile: 68 -> ``p68``, 99.7 -> ``p99.7``."""
    return f"p{q:g}"


def draw_seeds(master: int, n: int) -> list[int]:
    """``n`` run seeds from one master seed (``SeedSequence(master).spawn(n)``, 63-bit each).

    Seed ``i`` depends only on ``master`` and ``i`` (so ``draw_seeds(m, 20)`` is the start of
    ``draw_seeds(m, 200)``).
    """
    if isinstance(master, bool) or not isinstance(master, int | np.integer) or master < 0:
        raise ConfigError("the master seed must be a non-negative integer", column="seed",
                          found=repr(master))
    children = np.random.SeedSequence(int(master)).spawn(int(n))
    return [int(c.generate_state(1, np.uint64)[0] >> np.uint64(1)) for c in children]


# --- one run ------------------------------------------------------------------------------------
@dataclass
class RunRecord:
    """The small result of one run (what a worker sends back).

    ``times`` (T,) common grid epochs; per solution ``errors[name]`` (T, Q) with the columns of
    :data:`ERROR_QUANTITIES`, ``sigmas[name]`` (T, Q) the filter's stds, ``nees[name]`` (T, 3)
    for :data:`NEES_BLOCKS` (NaN where no filter epoch falls on the grid); ``nis`` maps a
    measurement type to ``(times, nis, dof)`` arrays (forward filter, every evaluated
    measurement, gated or not); ``windows`` the outage windows; ``summary`` a few scalars.
    """

    seed: int
    times: np.ndarray
    errors: dict
    sigmas: dict
    nees: dict
    nis: dict
    windows: list
    summary: dict = field(default_factory=dict)


def grid_times(t: np.ndarray, interval: float) -> np.ndarray:
    """The times of ``t`` that are multiples of ``interval`` (within 1 us)."""
    k = np.round(t / interval)
    return t[np.abs(t - k * interval) <= TIME_TOL]


def record_from_result(res, settings: MonteCarloSettings, seed: int) -> RunRecord:
    """Reduce a :class:`~insgnss.pipeline.JobResult` with a simulated truth to a
    :class:`RunRecord`."""
    truth = res.inputs.truth
    if truth is None:
        raise ConfigError("Monte Carlo needs a simulated truth (a job with a scenario and no "
                          "IMU file)")
    f = res.filter
    t_sol = f.forward.index.to_numpy(float)
    t_truth = truth.index.to_numpy(float)
    times = grid_times(t_sol, settings.grid_interval)
    times = times[match_times(times, t_truth) >= 0]
    errors, sigmas, nees = {}, {}, {}
    ep = np.asarray(f.epoch_times, float)
    for name in settings.solutions:
        sol = f.forward if name == "forward" else f.smoothed
        P = f.P_filtered if name == "forward" else f.P_smoothed
        if sol is None or P is None:
            continue
        err, sig, x = solution_errors(sol, truth, times)
        k = match_times(times, ep)
        ne = np.full((times.size, len(NEES_BLOCKS)), np.nan)
        if np.any(k >= 0):
            ne[k >= 0] = nees_blocks(x[k >= 0], P[k[k >= 0]])
        errors[name], sigmas[name], nees[name] = err, sig, ne
    nis = {}
    inn = f.innovations
    if len(inn):
        for typ, g in inn.groupby("type", sort=True):
            nis[str(typ)] = (g["time"].to_numpy(float), g["nis"].to_numpy(float),
                             g["dof"].to_numpy(float))
    ev = res.summary.get("evaluation", {})
    keep = ("rms_h_m", "max_h_m", "end_h_err_m_mean", "end_h_err_m_max", "non_outage_rms_h_m")
    summary = {name: {k: ev[name][k] for k in keep if k in ev[name]} for name in ev}
    summary["heading_source"] = res.summary.get("initialization", {}).get("heading_source")
    return RunRecord(int(seed), times, errors, sigmas, nees, nis,
                     [list(map(float, w)) for w in res.windows], summary)


def _as_job(job: Job | dict | str | Path, path: str | Path | None) -> Job:
    if isinstance(job, Job):
        return job
    if isinstance(job, str | Path):
        path = Path(job)
        with open(path, "rb") as fh:
            job = tomllib.load(fh)
    return load_job_dict(job, path)


def run_one(job: Job | dict | str | Path, seed: int, settings: MonteCarloSettings | None = None,
            path: str | Path | None = None) -> RunRecord:
    """One Monte Carlo run (the work unit sent to the workers).

    ``job`` is a job dict as parsed from TOML (with ``path`` the file it came from, for
    relative paths), a path to the TOML file (it must be readable on the worker) or a
    :class:`~insgnss.config.Job`. A filter that stops early is an error of this run.
    """
    from .pipeline import run_job

    job = _as_job(job, path)
    if not job.simulation or job["inputs"]["imu"]["path"] is not None:
        raise ConfigError("a Monte Carlo job must simulate its data: scenario tables and no "
                          "inputs.imu.path", file=job.path)
    settings = settings or MonteCarloSettings.from_table(job.simulation.get("montecarlo"),
                                                         job.path)
    if "filter.epoch_grid" not in job.given:  # the NEES needs P(k|k), P(k|N) on the grid
        values = copy.deepcopy(job.settings)
        values["filter"]["epoch_grid"] = "always"
        job = replace(job, settings=values)
    res = run_job(job, progress=False, seed=int(seed))
    if res.failure is not None:
        raise res.failure
    if not res.filter.complete:
        raise FilterHealthError(f"the filter stopped early: {res.filter.error}")
    return record_from_result(res, settings, seed)


# --- aggregation -------------------------------------------------------------------------------
def _stack(arrays: list[np.ndarray], times: list[np.ndarray], grid: np.ndarray) -> np.ndarray:
    out = np.full((len(arrays), grid.size) + arrays[0].shape[1:], np.nan)
    for m, (a, t) in enumerate(zip(arrays, times, strict=True)):
        out[m, np.searchsorted(grid, t)] = a
    return out


def _union(times: list[np.ndarray]) -> np.ndarray:
    return np.unique(np.concatenate(times)) if times else np.empty(0)


def _stat_block(v: np.ndarray, absval: bool, percentiles) -> dict:
    """Per-epoch statistics over axis 0 of (M, T) (NaN = missing)."""
    n = np.sum(np.isfinite(v), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        nn = np.where(n > 0, n, 1)
        mean = np.where(n > 0, np.nansum(v, axis=0) / nn, np.nan)
        rms = np.where(n > 0, np.sqrt(np.nansum(v * v, axis=0) / nn), np.nan)
    out = {"n": n.astype(np.int64), "mean": mean, "rms": rms}
    a = np.abs(v) if absval else v
    if v.shape[0]:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN epochs
            pv = np.nanpercentile(a, percentiles, axis=0)
    else:
        pv = np.full((len(percentiles), v.shape[1]), np.nan)
    for q, p in zip(percentiles, pv, strict=True):
        out[pct_name(q)] = p
    return out


def aggregate(records: list[RunRecord], settings: MonteCarloSettings) -> pd.DataFrame:
    """Per-epoch statistics over the runs (a long table).

    Columns: ``solution quantity time n mean rms p68 p95 p99 sigma lower upper``. For the error
    quantities the percentiles are of the absolute error and ``sigma`` is the RMS over the runs
    of the filter's std; for ``nees_pos nees_vel nees_att`` (each solution) and ``nis_<type>``
    (forward) ``mean`` is the average over the runs and ``lower``/``upper`` its chi-square
    bounds (``dof`` column).
    """
    cols = ["solution", "quantity", "time", "n", "mean", "rms",
            *[pct_name(q) for q in settings.percentiles], "sigma", "dof", "lower", "upper"]
    if not records:
        return pd.DataFrame(columns=cols)
    frames = []
    grid = _union([r.times for r in records])
    for name in settings.solutions:
        have = [r for r in records if name in r.errors]
        if not have:
            continue
        tsn = [r.times for r in have]
        E = _stack([r.errors[name] for r in have], tsn, grid)
        S = _stack([r.sigmas[name] for r in have], tsn, grid)
        X = _stack([r.nees[name] for r in have], tsn, grid)
        for q, qname in enumerate(ERROR_QUANTITIES):
            st = _stat_block(E[:, :, q], True, settings.percentiles)
            s = S[:, :, q]
            with np.errstate(invalid="ignore"):
                st["sigma"] = np.sqrt(np.nanmean(s * s, axis=0)) if len(have) else np.nan
            st.update(dof=np.nan, lower=np.nan, upper=np.nan)
            frames.append(_frame(name, qname, grid, st))
        for b, block in enumerate(NEES_BLOCKS):
            st = _stat_block(X[:, :, b], False, settings.percentiles)
            st["sigma"] = np.nan
            st["dof"] = np.full(grid.size, 3.0)
            st["lower"], st["upper"] = chi2_bounds(st["dof"], st["n"], settings.confidence)
            frames.append(_frame(name, f"nees_{block}", grid, st))
    types = sorted({k for r in records for k in r.nis})
    for typ in types:
        have = [r for r in records if typ in r.nis]
        tg = _union([r.nis[typ][0] for r in have])
        V = _stack([r.nis[typ][1] for r in have], [r.nis[typ][0] for r in have], tg)
        D = _stack([r.nis[typ][2] for r in have], [r.nis[typ][0] for r in have], tg)
        st = _stat_block(V, False, settings.percentiles)
        st["sigma"] = np.nan
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            st["dof"] = np.nanmax(D, axis=0)
        st["lower"], st["upper"] = chi2_bounds(st["dof"], st["n"], settings.confidence)
        frames.append(_frame("forward", f"nis_{typ}", tg, st))
    out = pd.concat(frames, ignore_index=True)[cols]
    for c in ("solution", "quantity"):
        out[c] = out[c].astype("category")
    return out


def _frame(solution: str, quantity: str, time: np.ndarray, st: dict) -> pd.DataFrame:
    d = {"solution": solution, "quantity": quantity, "time": time}
    d.update({k: np.broadcast_to(v, time.shape) for k, v in st.items()})
    return pd.DataFrame(d)


def runs_table(records: list[RunRecord], run_index: list[int]) -> pd.DataFrame:
    """The tidy per-run table: one row per run, solution, quantity and epoch.

    Columns ``run seed solution quantity time value sigma dof``: errors (``value``, with the
    filter's std in ``sigma``), NEES (``nees_pos nees_vel nees_att``, dof 3) and NIS
    (``nis_<type>``, forward, at the measurement times, with its dof).
    """
    parts = []
    for idx, r in zip(run_index, records, strict=True):
        for name in r.errors:
            T = r.times.size
            Q = len(ERROR_QUANTITIES)
            parts.append(pd.DataFrame({
                "run": idx, "seed": r.seed, "solution": name,
                "quantity": np.repeat(ERROR_QUANTITIES, T), "time": np.tile(r.times, Q),
                "value": r.errors[name].T.ravel(), "sigma": r.sigmas[name].T.ravel(),
                "dof": np.nan}))
            B = len(NEES_BLOCKS)
            parts.append(pd.DataFrame({
                "run": idx, "seed": r.seed, "solution": name,
                "quantity": np.repeat([f"nees_{b}" for b in NEES_BLOCKS], T),
                "time": np.tile(r.times, B), "value": r.nees[name].T.ravel(), "sigma": np.nan,
                "dof": 3.0}))
        for typ, (t, v, d) in r.nis.items():
            parts.append(pd.DataFrame({"run": idx, "seed": r.seed, "solution": "forward",
                                       "quantity": f"nis_{typ}", "time": t, "value": v,
                                       "sigma": np.nan, "dof": d}))
    cols = ["run", "seed", "solution", "quantity", "time", "value", "sigma", "dof"]
    if not parts:
        return pd.DataFrame(columns=cols)
    out = pd.concat(parts, ignore_index=True)[cols]
    out["run"] = out["run"].astype(np.int32)
    out["seed"] = out["seed"].astype(np.int64)
    for c in ("solution", "quantity"):
        out[c] = out[c].astype("category")
    return out


# --- summary numbers ---------------------------------------------------------------------------
def percentile_table(stats: pd.DataFrame, windows: list, settings: MonteCarloSettings,
                     quantities=("horizontal", "up", "heading")) -> pd.DataFrame:
    """Error statistics at the last grid epoch inside each outage (the outage windows are
    half-open: GNSS is used again at their end) and at the epoch of the largest coverage
    percentile: ``solution event time quantity unit n mean rms p.. sigma <k>sigma`` (angles
    in degrees)."""
    rows = []
    pc = [pct_name(q) for q in settings.percentiles]
    if not len(stats):
        return pd.DataFrame(rows)
    for name in settings.solutions:
        s = stats[(stats["solution"] == name)]
        if not len(s):
            continue
        events = []
        tq = np.unique(s.loc[s["quantity"] == quantities[0], "time"].to_numpy(float))
        for k, w in enumerate(windows):
            t = tq[in_windows(tq, [w])]  # half-open [start, end): GNSS is back at the end
            if t.size:
                events.append((f"outage {k + 1} end", float(t.max())))
        for qn in quantities:
            sq = s[s["quantity"] == qn].set_index("time")
            if not len(sq):
                continue
            f = np.degrees(1.0) if qn in ANGLE_QUANTITIES else 1.0
            ev = events + [("worst epoch (max p" + f"{settings.coverage_percentile:g})",
                            float(sq[pct_name(settings.coverage_percentile)].idxmax()))]
            for label, t in ev:
                r = sq.loc[t]
                row = {"solution": name, "event": label, "time": t, "quantity": qn,
                       "unit": "deg" if qn in ANGLE_QUANTITIES else "m", "n": int(r["n"]),
                       "mean": r["mean"] * f, "rms": r["rms"] * f}
                row.update({p: r[p] * f for p in pc})
                row["sigma"] = r["sigma"] * f
                row[f"{settings.coverage_sigma:g}sigma"] = settings.coverage_sigma * r["sigma"] * f
                rows.append(row)
    return pd.DataFrame(rows)


def _settled(df: pd.DataFrame, settings: MonteCarloSettings, t0: float) -> pd.DataFrame:
    return df[df["time"] >= t0 + settings.settle_time - TIME_TOL]


def consistency_summary(stats: pd.DataFrame, settings: MonteCarloSettings) -> dict:
    """NEES/NIS (mean of the run averages, fraction of epochs inside the bounds) and the
    coverage check per solution and quantity."""
    out: dict[str, Any] = {"nees": {}, "nis": {}, "coverage": {}}
    if not len(stats):
        return out
    t0 = float(stats["time"].min())
    st = _settled(stats, settings, t0)
    pq = pct_name(settings.coverage_percentile)
    for (sol, qty), g in st.groupby(["solution", "quantity"], observed=True, sort=True):
        g = g[g["n"] > 0]
        if not len(g):
            continue
        if qty.startswith("nees_") or qty.startswith("nis_"):
            inside = (g["mean"] >= g["lower"]) & (g["mean"] <= g["upper"])
            d = {"dof": float(g["dof"].median()), "mean": float(g["mean"].mean()),
                 "inside_fraction": float(inside.mean()), "below_fraction":
                 float((g["mean"] < g["lower"]).mean()), "above_fraction":
                 float((g["mean"] > g["upper"]).mean()), "epochs": int(len(g)),
                 "lower_median": float(g["lower"].median()),
                 "upper_median": float(g["upper"].median())}
            kind = "nees" if qty.startswith("nees_") else "nis"
            out[kind].setdefault(sol, {})[qty.split("_", 1)[1]] = d
        else:
            cover = settings.coverage_sigma * g["sigma"] >= g[pq]
            frac = float(cover.mean())
            ratio = g[pq] / g["sigma"]
            out["coverage"].setdefault(sol, {})[qty] = {
                "fraction": frac, "passed": frac >= settings.coverage_required,
                "max_ratio": float(ratio.max()), "median_ratio": float(ratio.median()),
                "epochs": int(len(g))}
    per = {}
    for sol, qs in out["coverage"].items():
        q_worst = min(qs, key=lambda q: qs[q]["fraction"])
        per[sol] = {"passed": all(v["passed"] for v in qs.values()),
                    "worst": {"quantity": q_worst, "fraction": qs[q_worst]["fraction"]}}
    out["coverage_check"] = {
        "statement": f"{settings.coverage_sigma:g} sigma >= p{settings.coverage_percentile:g} "
                     f"of |error| at >= {100 * settings.coverage_required:g} % of the epochs",
        "passed": bool(per) and all(v["passed"] for v in per.values()),
        "solutions": per}
    return out


# --- result ------------------------------------------------------------------------------------
@dataclass
class MonteCarloResult:
    """Output of :func:`run_montecarlo`: the tidy per-run table, the per-epoch statistics, the
    summary dict (JSON-ready), the successful :class:`RunRecord` objects and the failures."""

    runs: pd.DataFrame
    stats: pd.DataFrame
    summary: dict
    records: list = field(default_factory=list, repr=False)
    failures: list = field(default_factory=list)
    settings: MonteCarloSettings = field(default_factory=MonteCarloSettings)

    @property
    def windows(self) -> list:
        return self.summary.get("outages", [])

    def write(self, out_dir: str | Path, figures: bool = True) -> dict[str, Path]:
        """Write the tables, ``summary.json`` and the figures into ``out_dir`` (atomically)."""
        from .io.native import atomic_write_text, jsonable

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = {"runs": write_tidy(self.runs, out / "montecarlo.parquet"),
                 "statistics": write_tidy(self.stats, out / "statistics.parquet")}
        if figures and len(self.stats):
            from .plots import save_figure

            for sol in self.settings.solutions:
                if (self.stats["solution"] == sol).any():
                    p = out / ("envelopes.png" if sol == "forward" else f"envelopes_{sol}.png")
                    save_figure(envelope_figure(self.stats, self.windows, sol, self.settings), p)
                    paths[p.stem] = p
            p = out / "consistency.png"
            save_figure(consistency_figure(self.stats, self.windows, self.settings), p)
            paths["consistency"] = p
        summary = dict(self.summary)
        summary["files"] = sorted(p.name for p in [*paths.values(), out / "summary.json"])
        paths["summary"] = atomic_write_text(out / "summary.json",
                                             json.dumps(jsonable(summary), indent=2) + "\n")
        return paths


def write_tidy(df: pd.DataFrame, path: Path) -> Path:
    """Parquet (pyarrow) or, without pyarrow, CSV beside it (``.csv``); atomic."""
    from .io.native import atomic_write

    try:
        import pyarrow  # noqa: F401
    except ImportError:  # pragma: no cover - pyarrow is a dependency
        path = path.with_suffix(".csv")
        return atomic_write(path, lambda p: df.to_csv(p, index=False))
    return atomic_write(path, lambda p: df.to_parquet(p, engine="pyarrow", index=False,
                                                      compression="zstd"))


# --- driver ------------------------------------------------------------------------------------
def load_source(job: Job | dict | str | Path) -> tuple[dict, Path | None]:
    """Parsed job dict and its file (for the work units: plain data, no open files)."""
    if isinstance(job, Job):
        data = job.to_dict()
        return data, job.path
    if isinstance(job, dict):
        return job, None
    path = Path(job)
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh), path.resolve()
    except FileNotFoundError:
        raise ConfigError("job file not found", file=path) from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"not valid TOML: {exc}", file=path) from None


def run_montecarlo(job: Job | dict | str | Path, *, runs: int | None = None,
                   seed: int | None = None, executor=None, progress: bool = False,
                   settings: MonteCarloSettings | None = None, run_fn=None,
                   path: str | Path | None = None) -> MonteCarloResult:
    """Run a Monte Carlo study of a simulated job.

    Parameters
    ----------
    job : path, dict or Job
        The scenario/job (validated here before any run starts).
    runs, seed : int, optional
        Override ``[montecarlo] runs`` and the master ``seed``.
    executor : insgnss.executors.Executor, optional
        Back-end (default in-process); not closed here.
    progress : bool
        tqdm bar over the runs.
    settings : MonteCarloSettings, optional
        Instead of the job's ``[montecarlo]`` table.
    run_fn : callable, optional
        Work unit with the signature of :func:`run_one` (default); must be picklable for the
        parallel back-ends.
    """
    from ._version import __version__
    from .executors import InProcess

    data, jpath = load_source(job)
    jpath = Path(path) if path is not None else jpath
    j = load_job_dict(data, jpath)  # validate here, before any worker starts
    if not j.simulation or j["inputs"]["imu"]["path"] is not None:
        raise ConfigError("a Monte Carlo job must simulate its data: scenario tables and no "
                          "inputs.imu.path", file=jpath)
    settings = settings or MonteCarloSettings.from_table(j.simulation.get("montecarlo"), jpath)
    if runs is not None:
        settings.runs = MonteCarloSettings.from_table({"runs": runs}).runs
    if seed is not None:
        settings.seed = MonteCarloSettings.from_table({"seed": seed}).seed
    master = settings.seed if settings.seed is not None else \
        int(np.random.SeedSequence().entropy)
    seeds = draw_seeds(master, settings.runs)
    ex = executor if executor is not None else InProcess()
    fn = run_fn or run_one
    sp = None if jpath is None else str(jpath)
    tasks = [(data, s, settings, sp) for s in seeds]
    t0 = _time.perf_counter()
    outcomes = ex.run(fn, tasks, labels=seeds, progress=progress, desc="Monte Carlo")
    elapsed = _time.perf_counter() - t0
    ok = [o for o in outcomes if o.ok]
    records = [o.value for o in ok]
    failures = [{"run": o.index, "seed": seeds[o.index], "error": o.error.type,
                 "message": o.error.message, "traceback": o.error.traceback}
                for o in outcomes if not o.ok]
    stats = aggregate(records, settings)
    windows = records[0].windows if records else []
    name = data.get("scenario", {}).get("name") or data.get("job", {}).get("name", "job")
    cons = consistency_summary(stats, settings)
    ptab = percentile_table(stats, windows, settings)
    summary = {
        "insgnss_version": __version__, "scenario": name,
        "job_file": sp, "created": _time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "master_seed": master, "runs_requested": settings.runs, "runs_ok": len(ok),
        "runs_failed": len(failures),
        "failures": [{k: v for k, v in f.items() if k != "traceback"} for f in failures],
        "executor": ex.describe(), "elapsed_s": elapsed,
        "runs_per_minute": 60.0 * len(outcomes) / elapsed if elapsed > 0 else None,
        "settings": settings.to_dict(), "outages": windows,
        "grid_epochs": int(records[0].times.size) if records else 0,
        "percentile_table": ptab.to_dict(orient="records"),
        **cons,
        "runs": [{"run": o.index, "seed": seeds[o.index], "ok": o.ok,
                  "elapsed_s": o.elapsed, "cpu_s": o.cpu, "worker": o.worker,
                  **({"error": str(o.error)} if not o.ok else o.value.summary)}
                 for o in outcomes],
    }
    return MonteCarloResult(runs_table(records, [o.index for o in ok]), stats, summary,
                            records, failures, settings)


# --- figures -----------------------------------------------------------------------------------
_PANELS = (("east", "north", "up"), ("vel_e", "vel_n", "vel_u"), ("roll", "pitch", "heading"))
_UNITS = {"east": "m", "north": "m", "up": "m", "vel_e": "m/s", "vel_n": "m/s", "vel_u": "m/s",
          "roll": "deg", "pitch": "deg", "heading": "deg", "horizontal": "m"}


def _shade(ax, windows):
    for k, (a, b) in enumerate(windows):
        ax.axvspan(a, b, color="0.85", zorder=0, label="GNSS outage" if k == 0 else None)


def envelope_figure(stats: pd.DataFrame, windows: list, solution: str = "forward",
                    settings: MonteCarloSettings | None = None):
    """3 x 3 panels (position, velocity, attitude errors): the per-epoch percentiles of the
    absolute error over the runs against the filter's 1 and k sigma (k = coverage_sigma)."""
    import matplotlib.pyplot as plt

    settings = settings or MonteCarloSettings()
    s = stats[stats["solution"] == solution]
    fig, axes = plt.subplots(3, 3, figsize=(13, 9), sharex=True, layout="constrained")
    shades = plt.cm.Blues(np.linspace(0.35, 0.85, len(settings.percentiles)))
    n_runs = int(s["n"].max()) if len(s) else 0
    for r, row in enumerate(_PANELS):
        for c, qn in enumerate(row):
            ax = axes[r, c]
            g = s[s["quantity"] == qn].sort_values("time")
            t = g["time"].to_numpy(float)
            f = np.degrees(1.0) if qn in ANGLE_QUANTITIES else 1.0
            _shade(ax, windows)
            for q, col in zip(settings.percentiles, shades, strict=True):
                ax.plot(t, g[pct_name(q)].to_numpy() * f, color=col, lw=1.2,
                        label=f"p{q:g} |error|")
            sig = g["sigma"].to_numpy() * f
            ax.plot(t, sig, "k--", lw=0.9, label="filter 1 sigma")
            ax.plot(t, settings.coverage_sigma * sig, "r-", lw=0.9,
                    label=f"filter {settings.coverage_sigma:g} sigma")
            ax.set_ylabel(f"|{qn} error| [{_UNITS[qn]}]")
            ax.set_yscale("log")
            ax.grid(True, which="both", alpha=0.3)
            if r == 2:
                ax.set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=7, loc="lower right")
    fig.suptitle(f"Monte Carlo error envelopes ({solution}, {n_runs} runs)")
    return fig


def consistency_figure(stats: pd.DataFrame, windows: list,
                       settings: MonteCarloSettings | None = None):
    """Average NEES (each solution) and NIS over the runs with their chi-square bounds (linear
    scale up to twice the upper bound)."""
    import matplotlib.pyplot as plt

    settings = settings or MonteCarloSettings()
    qs = stats[stats["quantity"].astype(str).str.match(r"ne|ni")]
    present = set(zip(qs["solution"].astype(str), qs["quantity"].astype(str), strict=True))
    nis = sorted(q for _, q in present if q.startswith("nis_"))
    keys = [(s, f"nees_{b}") for s in settings.solutions for b in NEES_BLOCKS] + \
        [("forward", q) for q in nis]
    keys = [k for k in keys if k in present]
    n = max(len(keys), 1)
    ncol = 3
    nrow = int(np.ceil(n / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(13, 3.0 * nrow), squeeze=False,
                             layout="constrained")
    for ax, (sol, q) in zip(axes.flat, keys, strict=False):
        g = qs[(qs["solution"] == sol) & (qs["quantity"] == q)].sort_values("time")
        t = g["time"].to_numpy(float)
        _shade(ax, windows)
        y = g["mean"].to_numpy(float)
        tl = t
        if t.size > 2:  # break the line across gaps (outages, for the NIS)
            gap = np.flatnonzero(np.diff(t) > 1.5 * np.median(np.diff(t))) + 1
            tl, y = np.insert(t, gap, np.nan), np.insert(y, gap, np.nan)
        ax.plot(tl, y, lw=0.9, label="average over runs")
        ax.plot(t, g["lower"], "r--", lw=0.8, label=f"{100 * settings.confidence:g} % bounds")
        ax.plot(t, g["upper"], "r--", lw=0.8)
        ax.set_ylim(0.0, 2.0 * float(np.nanmedian(g["upper"])))
        ax.set_title(f"{q} ({sol}, dof {g['dof'].median():g})", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.set_xlabel("time [s]")
    for ax in list(axes.flat)[len(keys):]:
        ax.set_visible(False)
    if keys:
        axes.flat[0].legend(fontsize=7)
    return fig
