"""What the report shows, computed once from a run: errors against the reference with the
filter's sigmas, single-run NEES and NIS, drift inside outages, excursions beyond 3 sigma.

The static report (:mod:`insgnss.report`, matplotlib figures of :mod:`insgnss.plots`) and the
interactive page (:mod:`insgnss.report_interactive`) draw the same :class:`ReportData`.

Errors (estimate minus reference)
---------------------------------
- position: ENU metres at the reference epochs, from :func:`insgnss.pipeline.evaluate_solution`
  (the solution interpolated in ECEF and moved to the reference point by the lever arm);
- velocity (ENU) and attitude (roll, pitch, heading, wrapped to +-180 deg): where the reference
  has ``vel_e vel_n vel_u`` / ``roll pitch heading`` (a simulated truth has them, real references
  often only positions), by :func:`insgnss.consistency.solution_errors` on the solution sampled at
  the reference epochs (linear interpolation, heading unwrapped). A reference that measures the
  antenna (``point = "antenna"``) with a non-zero lever arm has the antenna's velocity
  ``v + C (w x l)``: velocity errors are then not formed (the body rate is not in the tables) and
  the report says so.

NEES / NIS (single run; Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4)
-----------------------------------------------------------------------
At each filter epoch that coincides with a reference epoch, ``e^T P^-1 e`` of the position,
velocity and attitude blocks (3 dof each; attitude ``e`` is the misalignment ``phi`` of
``C_est = exp([phi x]) C_true``, :func:`insgnss.attitude.attitude_error`) with the full
``P(e|e)`` of the forward filter or the smoothed ``P``; :func:`insgnss.consistency.nees_blocks`.
A process that keeps no epoch covariances (the foot preset) gets the diagonal of its std
columns, said in the figure. NIS comes from the innovation log (``nis``, ``dof``). Bounds: the
two-sided 95 % interval of one chi-square(dof) sample, and of the moving mean over ``window``
samples, ``chi2.ppf((1 -+ 0.95) / 2, window dof) / window``
(:func:`insgnss.consistency.chi2_bounds`).

Rate
----
The report shows the run at the rate of its trajectory files (``[outputs] rate_hz``, default
``"auto"``: 10 Hz, and the samples around every GNSS and control-point epoch,
:func:`output_table`): the solution tables, and the reference epochs against which the
errors, NEES, excursions and drift are formed, are thinned the same way
(:func:`insgnss.io.native.decimation_rows`); the solution is still sampled at those epochs
from its full-rate table. ``rate_hz = "imu"`` gives every sample and every reference epoch.
A figure shows at most a few thousand points per series anyway (:func:`insgnss.plots.decimate`),
and a 1 h log at 200 Hz with a 200 Hz reference is then drawn from 36,000 instead of 720,000
epochs.

Drift inside outages
--------------------
Per outage and solution: the horizontal error at the reference epochs inside it, the filter's
predicted ``3 sqrt(sigma_E^2 + sigma_N^2)``, the distance travelled since the outage start (along
the reference, or the solution without one), and the drift, the growth of the horizontal error
vector since the first epoch of the outage, as a percentage of that distance (shown once at least
``MIN_DISTANCE`` has been travelled). Without a reference the forward-minus-smoothed difference
stands for the error.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .earth import geodetic_to_enu
from .outages import window_index

#: quantities of the error figures: (name, columns, std columns, unit, scale to the unit)
QUANTITIES = {
    "position": (("east", "north", "up"), ("east_std", "north_std", "up_std"), "m", 1.0),
    "velocity": (("vel_e", "vel_n", "vel_u"), ("vel_e_std", "vel_n_std", "vel_u_std"), "m/s", 1.0),
    "attitude": (("roll", "pitch", "heading"), ("roll_std", "pitch_std", "heading_std"), "deg",
                 float(np.degrees(1.0))),
}
#: axis labels of the error columns
LABELS = {"east": "east", "north": "north", "up": "up", "vel_e": "east", "vel_n": "north",
          "vel_u": "up", "roll": "roll", "pitch": "pitch", "heading": "heading"}
#: names and units of the measurement components in the innovation log, by measurement type
#: (pipeline.build_measurements: NHC constrains body right and up, the odometer body forward)
COMPONENTS = {
    "gnss_pos": (("east", "north", "up"), "m", 1.0),
    "gnss_vel": (("east", "north", "up"), "m/s", 1.0),
    "zupt": (("east", "north", "up"), "m/s", 1.0),
    "cupt": (("east", "north", "up"), "m", 1.0),
    "zaru": (("x (right)", "y (forward)", "z (up)"), "deg/s", float(np.degrees(1.0))),
    "nhc": (("right", "up"), "m/s", 1.0),
    "odometer": (("forward",), "m/s", 1.0),
    "heading": (("heading",), "deg", float(np.degrees(1.0))),
}
#: foot preset innovation columns (insgnss.foot): suffix -> component name
FOOT_SUFFIX = {"e": "east", "n": "north", "u": "up", "x": "x", "y": "y", "z": "z"}
NEES_NAMES = ("position", "velocity", "attitude")
CONFIDENCE = 0.95
NEES_WINDOW = 20  #: samples in the moving mean of NEES / NIS
MIN_DISTANCE = 5.0  #: distance travelled before drift is shown as % of it [m]
SENSOR_BLOCKS = {  # estimated sensor errors: (columns, unit, scale from SI)
    "gyro_bias": (("gyro_bias_x", "gyro_bias_y", "gyro_bias_z"), "deg/h",
                  float(np.degrees(1.0)) * 3600.0),
    "accel_bias": (("accel_bias_x", "accel_bias_y", "accel_bias_z"), "mg", 1.0 / 9.80665e-3),
    "gyro_scale": (("gyro_scale_x", "gyro_scale_y", "gyro_scale_z"), "ppm", 1e6),
    "accel_scale": (("accel_scale_x", "accel_scale_y", "accel_scale_z"), "ppm", 1e6),
}


@dataclass
class SolutionData:
    """One solution (``forward`` or ``smoothed``) and its comparison with the reference."""

    name: str
    table: pd.DataFrame
    errors: pd.DataFrame | None = None  #: at reference epochs: error and std columns
    nees: pd.DataFrame | None = None  #: at matched filter epochs: position velocity attitude
    nees_note: str = ""


@dataclass
class ReportData:
    """Everything the report draws (see the module docstring)."""

    title: str
    summary: dict
    windows: list
    solutions: dict  #: name -> SolutionData (forward first)
    origin: tuple  #: (lat, lon, height) [rad, rad, m] of the ENU axes of the track
    reference: pd.DataFrame | None = None
    reference_kinds: tuple = ()  #: subset of ("position", "velocity", "attitude")
    notes: list = field(default_factory=list)  #: what is not shown and why
    innovations: pd.DataFrame | None = None
    sensor_truth: pd.DataFrame | None = None  #: simulated biases / scale factors, SI
    drift: pd.DataFrame | None = None

    @property
    def best(self) -> SolutionData:
        """The smoothed solution when there is one, else the forward."""
        return self.solutions.get("smoothed") or self.solutions["forward"]

    def has_reference(self, kind: str = "position") -> bool:
        return kind in self.reference_kinds and any(
            s.errors is not None for s in self.solutions.values())


def _angle_cols(df: pd.DataFrame) -> list[str]:
    return [c for c in ("roll", "pitch", "heading") if c in df.columns]


def sample_at(sol: pd.DataFrame, times: np.ndarray) -> pd.DataFrame:
    """``sol`` at ``times`` inside its span: the rows themselves where the times coincide (1 us),
    else linear interpolation of every column (angles unwrapped, lon too)."""
    from .consistency import match_times as _match

    ts = sol.index.to_numpy(float)
    times = np.asarray(times, float)
    times = times[(times >= ts[0] - 1e-6) & (times <= ts[-1] + 1e-6)]
    k = _match(times, ts)
    if np.all(k >= 0):
        return sol.iloc[k]
    out = {}
    ang = set(_angle_cols(sol)) | {"lon"}
    for c in sol.columns:
        y = sol[c].to_numpy(float)
        if c in ang:
            y = np.unwrap(y)
        out[c] = np.interp(times, ts, y)
    return pd.DataFrame(out, index=pd.Index(times, name=sol.index.name))


def _state_errors(sol: pd.DataFrame, ref: pd.DataFrame, kinds: tuple) -> tuple:
    """Velocity / attitude errors and stds at the reference epochs, and the 9-vector error state
    (:func:`insgnss.consistency.solution_errors`)."""
    from .consistency import ERROR_QUANTITIES, solution_errors
    from .validate import time_slice

    need = ["lat", "lon", "height", "vel_e", "vel_n", "vel_u", "roll", "pitch", "heading"]
    ts = sol.index.to_numpy(float)
    # the reference epochs inside the solution's span: a slice of the (sorted) table, not a
    # copy of it (40 MiB at the output rate of a 10 h log)
    r = time_slice(ref, ts[0] - 1e-6, ts[-1] + 1e-6)
    # solution_errors takes all columns; absent kinds are dropped below
    absent = {c: np.nan for c in need if c not in r.columns}
    times = r.index.to_numpy(float)
    # in blocks of epochs: the per-epoch temporaries (attitude matrices, the solution rows)
    # stay small on a long log; every quantity is formed epoch by epoch (the same numbers)
    # written into arrays of the whole length (blocks concatenated at the end held every
    # result twice: 90 MiB at the peak of a 10 h report)
    out = None
    for a in range(0, max(times.size, 1), STATE_BLOCK):
        part = solution_errors(sample_at(sol, times[a:a + STATE_BLOCK]),
                               r.iloc[a:a + STATE_BLOCK].assign(**absent),
                               times[a:a + STATE_BLOCK])
        if out is None:
            out = [np.empty((times.size, *p.shape[1:]), p.dtype) for p in part]
        for o, p in zip(out, part, strict=True):
            o[a:a + len(p)] = p
    err, sig, x = out
    cols = {}
    for q, name in enumerate(ERROR_QUANTITIES):
        if name in QUANTITIES["velocity"][0] and "velocity" in kinds or \
                name in QUANTITIES["attitude"][0] and "attitude" in kinds:
            cols[name] = err[:, q]
            cols[f"{name}_std"] = sig[:, q]
    return pd.DataFrame(cols, index=r.index, copy=False), x, times  # views: joined below


def _nees(res_filter, name: str, sol: pd.DataFrame, x: np.ndarray, t_x: np.ndarray,
          kinds: tuple) -> tuple[pd.DataFrame | None, str]:
    from .consistency import NEES_BLOCKS, nees_blocks
    from .consistency import match_times as _match

    P = getattr(res_filter, "P_filtered" if name == "forward" else "P_smoothed", None)
    ep = getattr(res_filter, "epoch_times", None)
    blocks = dict(zip(NEES_NAMES, NEES_BLOCKS.values(), strict=True))
    if P is not None and ep is not None and len(ep):
        ep = np.asarray(ep, float)[: P.shape[0]]
        k = _match(t_x, ep)
        use = k >= 0
        if not np.any(use):
            return None, "no filter epoch coincides with a reference epoch"
        rows = np.flatnonzero(use)
        ne = np.empty((rows.size, len(NEES_NAMES)))
        for a in range(0, rows.size, COVARIANCE_BLOCK):  # the epochs' covariances a block at
            r = rows[a:a + COVARIANCE_BLOCK]             # a time, not all copied at once
            ne[a:a + r.size] = nees_blocks(x[r], P[k[r]])
        df = pd.DataFrame(ne, index=pd.Index(t_x[use], name="time"), columns=NEES_NAMES)
        note = "full epoch covariance"
    else:  # no stored covariances: diagonal of the std columns
        stds = {"position": ("east_std", "north_std", "up_std"),
                "velocity": ("vel_e_std", "vel_n_std", "vel_u_std"),
                "attitude": ("roll_std", "pitch_std", "heading_std")}
        s = sample_at(sol, t_x)
        cols = {}
        for q, sl in blocks.items():
            if all(c in s.columns for c in stds[q]):
                sd = s[list(stds[q])].to_numpy(float)
                cols[q] = np.sum((x[: len(s), sl] / sd) ** 2, axis=1)
        if not cols:
            return None, "no covariance stored"
        df = pd.DataFrame(cols, index=pd.Index(s.index.to_numpy(float), name="time"))
        note = "diagonal covariance (the process stores no epoch covariances)"
    for q in NEES_NAMES:
        if q in df.columns and q not in kinds:
            df = df.drop(columns=q)
    df = df.replace([np.inf, -np.inf], np.nan)
    return (df if df.shape[1] else None), note


def _reference_kinds(ref: pd.DataFrame | None) -> tuple:
    if ref is None or not len(ref):
        return ()
    kinds = ["position"]
    for q in ("velocity", "attitude"):
        if all(c in ref.columns for c in QUANTITIES[q][0]):
            kinds.append(q)
    return tuple(kinds)


def _distance_along(df: pd.DataFrame, origin) -> tuple[np.ndarray, np.ndarray]:
    """Times and cumulative horizontal path length [m] of a trajectory table."""
    e, n, _ = geodetic_to_enu(df["lat"].to_numpy(float), df["lon"].to_numpy(float),
                              df["height"].to_numpy(float), *origin)
    d = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(e), np.diff(n)))])
    return df.index.to_numpy(float), d


def drift_table(data: ReportData) -> pd.DataFrame | None:
    """Long table of the drift inside each outage: ``solution kind outage start t_rel horizontal
    drift sigma3 distance percent`` (see the module docstring); without a reference the forward-minus-smoothed
    horizontal difference stands for the error (``kind`` says which)."""
    if not data.windows:
        return None
    rows = []
    path_src = data.reference if data.reference is not None else data.best.table
    t_path, d_path = _distance_along(path_src, data.origin)
    for name, s in data.solutions.items():
        if s.errors is not None and "east" in s.errors.columns:
            t = s.errors.index.to_numpy(float)
            en = s.errors[["east", "north"]].to_numpy(float)
            kind = "error"
        elif name == "forward" and "smoothed" in data.solutions:
            diff = forward_minus_smoothed(data)
            t = diff.index.to_numpy(float)
            en = diff[["east", "north"]].to_numpy(float)
            kind = "forward - smoothed"
        else:
            continue
        hz = np.hypot(en[:, 0], en[:, 1])
        tab = s.table
        sig = np.hypot(tab["east_std"].to_numpy(float), tab["north_std"].to_numpy(float)) \
            if {"east_std", "north_std"} <= set(tab.columns) else np.full(len(tab), np.nan)
        s3 = 3.0 * np.interp(t, tab.index.to_numpy(float), sig)
        k = window_index(t, data.windows)
        for w, (a, _) in enumerate(data.windows):
            m = k == w
            if not np.any(m):
                continue
            dist = np.interp(t[m], t_path, d_path) - np.interp(a, t_path, d_path)
            # drift: growth of the horizontal error vector since the first epoch of the outage
            growth = np.hypot(*(en[m] - en[m][0]).T)
            pct = np.where(dist >= MIN_DISTANCE, 100.0 * growth / np.maximum(dist, 1e-9),
                           np.nan)
            rows.append(pd.DataFrame({"solution": name, "kind": kind, "outage": w,
                                      "start": a, "t_rel": t[m] - a, "horizontal": hz[m],
                                      "drift": growth, "sigma3": s3[m], "distance": dist,
                                      "percent": pct}))
    return pd.concat(rows, ignore_index=True) if rows else None


def forward_minus_smoothed(data: ReportData) -> pd.DataFrame:
    """Forward minus smoothed solution at the forward samples: ENU position [m], ENU velocity
    [m/s] and roll/pitch/heading [rad, wrapped]."""
    f = data.solutions["forward"].table
    s = sample_at(data.solutions["smoothed"].table, f.index.to_numpy(float))
    f = f.loc[s.index] if len(s) != len(f) else f
    lat0, lon0, h0 = data.origin
    ef = np.column_stack(geodetic_to_enu(f["lat"].to_numpy(float), f["lon"].to_numpy(float),
                                         f["height"].to_numpy(float), lat0, lon0, h0))
    es = np.column_stack(geodetic_to_enu(s["lat"].to_numpy(float), s["lon"].to_numpy(float),
                                         s["height"].to_numpy(float), lat0, lon0, h0))
    out = pd.DataFrame(ef - es, index=s.index, columns=["east", "north", "up"])
    for c in ("vel_e", "vel_n", "vel_u"):
        if c in f.columns:
            out[c] = f[c].to_numpy(float) - s[c].to_numpy(float)
    for c in _angle_cols(f):
        d = f[c].to_numpy(float) - s[c].to_numpy(float)
        out[c] = (d + np.pi) % (2 * np.pi) - np.pi
    return out


def time_origin(data: ReportData) -> float:
    """Time origin of the figures and tables: the first forward sample, unless the run already
    starts near 0 s."""
    t = float(data.solutions["forward"].table.index[0])
    return 0.0 if abs(t) < 1.0 else t


def excursions(errors: pd.DataFrame, col: str, std_col: str, k: float = 3.0) -> dict:
    """Where ``|error| > k sigma``: mask, fraction of epochs, first time, longest run [s]."""
    e = errors[col].to_numpy(float)
    s = errors[std_col].to_numpy(float)
    ok = np.isfinite(e) & np.isfinite(s)
    out_ = ok & (np.abs(e) > k * s)
    t = errors.index.to_numpy(float)
    longest = 0.0
    if np.any(out_):
        d = np.diff(np.concatenate([[0], out_.astype(np.int8), [0]]))
        a, b = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
        longest = float(np.max(t[b] - t[a]))
    return {"mask": out_, "fraction": float(out_.sum() / max(ok.sum(), 1)),
            "n": int(out_.sum()), "first": float(t[out_][0]) if np.any(out_) else np.nan,
            "longest": longest}


def excursion_table(data: ReportData) -> pd.DataFrame:
    """Per solution and error component: epochs compared, % outside +-3 sigma, first time
    (since :func:`time_origin`) and longest excursion (a consistent Gaussian filter: 0.27 %)."""
    rows = []
    t0 = time_origin(data) if data.solutions else 0.0
    for name, s in data.solutions.items():
        if s.errors is None:
            continue
        for q, (cols, stds, _, _) in QUANTITIES.items():
            for c, sc in zip(cols, stds, strict=True):
                if c in s.errors.columns and sc in s.errors.columns:
                    x = excursions(s.errors, c, sc)
                    n = int(np.isfinite(s.errors[c].to_numpy(float)).sum())
                    rows.append({"solution": name, "quantity": q, "component": LABELS[c],
                                 "epochs": n, "outside 3 sigma [%]": 100 * x["fraction"],
                                 "first outside [s]": x["first"] - t0,
                                 "longest excursion [s]": x["longest"]})
    return pd.DataFrame(rows)


def innovation_groups(inn: pd.DataFrame, mtype: str) -> list[tuple]:
    """Panels of one measurement type's innovations: ``(title, unit, scale, comps)`` with
    ``comps`` a list of ``(column, component name, std column or None)``; the engine's log has
    ``innov_k`` / ``innov_std_k``, the foot preset's ``zupt_e .. zaru_z`` (two panels)."""
    names, unit, scale = COMPONENTS.get(mtype, ((), "", 1.0))
    comps = []
    k = 0
    while f"innov_{k}" in inn.columns:
        std = f"innov_std_{k}" if f"innov_std_{k}" in inn.columns else None
        comps.append((f"innov_{k}", names[k] if k < len(names) else f"component {k}", std))
        k += 1
    if comps:
        return [(mtype, unit, scale, comps)]
    out = []
    for prefix in ("zupt", "zaru"):  # foot preset: <type>_<suffix> columns
        cols = [c for c in inn.columns if c.startswith(prefix + "_")
                and c.split("_")[-1] in FOOT_SUFFIX]
        if cols:
            _, u, sc = COMPONENTS[prefix]
            out.append((prefix, u, sc, [(c, f"{prefix} {FOOT_SUFFIX[c.split('_')[-1]]}", None)
                                        for c in cols]))
    return out


def output_table(result, df) -> pd.DataFrame:
    """``df`` (a solution or the reference of ``result``) at the run's trajectory output rate
    (``[outputs] rate_hz``), keeping the samples around the GNSS and control-point epochs, as
    the trajectory files are written (:func:`insgnss.io.native.decimation_rows`). A solution
    held as arrays (:class:`insgnss.filter.store.Table`, possibly memory-mapped) gives only
    those rows, read in blocks."""
    from .filter.store import select_rows
    from .io.native import decimation_rows

    job = getattr(result, "job", None)
    if job is None:
        return select_rows(df, lambda t: None)
    inputs = result.inputs
    epochs = [x.index for x in (getattr(inputs, "gnss", None),
                                getattr(inputs, "control_points", None)) if x is not None]
    return select_rows(df, lambda t: decimation_rows(t, job["outputs"]["rate_hz"], epochs,
                                                     job["process"]["preset"]))


#: solution columns the state errors and the NEES read (:func:`_state_errors`, :func:`_nees`):
#: the rows around the reference epochs are taken with these only, not every output column
STATE_COLUMNS = ("lat", "lon", "height", "vel_e", "vel_n", "vel_u", "roll", "pitch", "heading",
                 "east_std", "north_std", "up_std", "vel_e_std", "vel_n_std", "vel_u_std",
                 "roll_std", "pitch_std", "heading_std")


#: reference epochs per block of :func:`_state_errors`
STATE_BLOCK = 1 << 13
#: filter epochs per block of the NEES (their covariances, 1.8 kB each for 15 states)
COVARIANCE_BLOCK = 1 << 9


def _bracketing_rows(ts: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Sorted rows of the samples ``ts`` on either side of each of ``times`` (all a linear
    interpolation at ``times`` or a match within 1 us needs: :func:`sample_at`)."""
    if not ts.size:
        return np.empty(0, np.int64)
    j = np.searchsorted(ts, np.asarray(times, float), side="right")
    return np.unique(np.clip(np.concatenate([j - 1, j]), 0, ts.size - 1))


def build_report_data(result) -> ReportData:
    """Assemble :class:`ReportData` from a :class:`~insgnss.pipeline.JobResult`."""
    f = result.filter
    s = result.summary
    sols = {}
    inputs = result.inputs
    ref = inputs.reference if result.evaluation or inputs.reference is not None else None
    kinds = _reference_kinds(ref) if result.evaluation else ()
    notes = []
    la = np.asarray(getattr(inputs, "lever_arm", np.zeros(3)), float)
    if "velocity" in kinds and getattr(inputs, "reference_point", "imu") == "antenna" \
            and np.any(la != 0):
        kinds = tuple(k for k in kinds if k != "velocity")
        notes.append("The reference measures the antenna and the lever arm is not zero: "
                     "velocity errors are not formed (the antenna velocity needs the body rate).")
    if ref is not None and len(ref):  # the reference epochs the report evaluates (see Rate)
        from .io.spill import release_frame

        full_ref, ref = ref, output_table(result, ref)
        release_frame(full_ref)  # a mapped reference (job/inputs.py): its pages go back
    if ref is not None and kinds:
        missing = [q for q in ("velocity", "attitude") if q not in _reference_kinds(ref)]
        if missing:
            notes.append(f"The reference has no {' or '.join(missing)}: "
                         f"{' and '.join(missing)} are shown by the filter's sigmas and the "
                         "forward-minus-smoothed difference.")
    from .filter.store import select_rows, solution_table

    for name in ("forward", "smoothed"):
        full = solution_table(f, name)
        if full is None or not len(full):
            continue
        sd = SolutionData(name, output_table(result, full))
        ev = result.evaluation.get(name)
        if ev:
            err = ev["errors"]
            if ref is not None and len(ref) < len(err):
                from .consistency import match_times

                err = err[match_times(err.index.to_numpy(float),
                                      ref.index.to_numpy(float)) >= 0]
            # the solution rows around the evaluated epochs (not the whole log)
            at = err.index.to_numpy(float) if ref is None else \
                np.union1d(err.index.to_numpy(float), ref.index.to_numpy(float))
            tab = select_rows(full, lambda t, at=at: _bracketing_rows(t, at),
                              STATE_COLUMNS)
            err = err[["east", "north", "up", "horizontal"]
                      + [c for c in ("east_std", "north_std", "up_std")
                         if c in err.columns]].copy()
            x = np.column_stack([err[["east", "north", "up"]].to_numpy(float),
                                 np.full((len(err), 6), np.nan)])
            t_x = err.index.to_numpy(float)
            if len(kinds) > 1:
                st, xs, t_s = _state_errors(tab, ref, kinds)
                err = err.join(st, how="left")
                pos = pd.DataFrame(x[:, :3], index=t_x)
                x = np.column_stack([pos.reindex(t_s).to_numpy(float), xs[:, 3:]])
                t_x = t_s
            sd.errors = err
            ok = np.isfinite(x[:, :3]).all(axis=1)
            sd.nees, sd.nees_note = _nees(f, name, tab, x[ok], t_x[ok], kinds)
            tab = x = xs = None  # before the next solution's rows are taken
        sols[name] = sd
    best = sols.get("smoothed") or sols["forward"]
    origin = tuple(float(best.table[c].iloc[0]) for c in ("lat", "lon", "height"))
    inn = getattr(f, "innovations", None)
    truth = None
    st = getattr(inputs, "sensor_truth", None)
    if st is not None:
        truth = st
    data = ReportData(title=str(s.get("job")), summary=s, windows=list(result.windows),
                      solutions=sols, origin=origin, reference=ref if kinds else None,
                      reference_kinds=kinds, notes=notes,
                      innovations=inn if inn is not None and len(inn) else None,
                      sensor_truth=truth)
    if not kinds and ref is None:
        data.notes.append("No reference: the figures show the filter's sigmas and the "
                          "forward-minus-smoothed difference instead of errors.")
    data.drift = drift_table(data)
    return data


#: keys of the report figures in page order (insgnss.plots.REPORT_FIGURES draws them); each is
#: written as ``fig_<key>.<ext>`` when ``[outputs] figures`` asks for files
FIGURE_KEYS = ("track", "position_errors", "velocity_errors", "attitude_errors",
               "position_sigma", "velocity_sigma", "attitude_sigma", "position_difference",
               "velocity_difference", "attitude_difference", "heading", "sensor_errors",
               "outage_drift", "innovations", "nis", "nees")
FIGURE_FORMATS = ("png", "pdf", "svg")  #: file formats of ``[outputs] figures``
INTERACTIVE_NAME = "report_interactive.html"


def figure_file(key: str, ext: str) -> str:
    """File name of a report figure saved beside the report."""
    return f"fig_{key}.{ext}"


#: every file the report may write besides report.html (for the output set's stale list)
REPORT_FILES = (INTERACTIVE_NAME,) + tuple(figure_file(k, e) for k in FIGURE_KEYS
                                           for e in FIGURE_FORMATS)
