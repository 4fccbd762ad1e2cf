"""Self-tuning of noise parameters by maximum likelihood of the filter's innovations.

Method (docs/filter.md, "Self-tuning")
--------------------------------------
For a Kalman filter the innovations ``nu_k = z_k - H_k x_k|k-1`` are, under the model,
independent zero-mean Gaussians with covariance ``S_k = H P_k|k-1 H^T + R_k``: the likelihood of
the whole record factorises into them (prediction-error decomposition; Schweppe 1965, Mehra
1970). The noise parameters ``theta`` (IMU white noise and bias instability, GNSS sigma scale
per solution quality, NHC and ZUPT sigmas, the IMU time offset) are estimated by maximising

    L(theta) = sum_types n_type * mean_rows sum_j -1/2 [ log(2 pi S_jj) + rho(nu_j^2 / S_jj) ]

over the rows of the filter's innovation log (``innov_j``, ``innov_std_j``), where the filter
is re-run for every ``theta`` tried. Details that make it robust on real data:

- **composite (marginal) likelihood** over the components ``j`` of a measurement: the log keeps
  only ``S_jj``, and the marginals are exact under the model, so their sum is an unbiased
  estimating function (Varin, Reid and Firth 2011) without the full ``S``;
- **robust**: ``rho(q) = min(q, c)`` with ``c`` the filter's gate (chi-square, 1 dof): an outlier
  the gate rejects does not drive the noise up;
- **the same rows for every theta**: each type's mean per row is weighted by its row count in
  the prior run (speed-gated ZUPT/NHC evaluate a few more or fewer rows as the nominal changes);
  a run that stops early (runaway NIS, a non-positive-definite P) is rejected.

Search: coordinate-wise in ``log theta`` (time offsets linearly), each a parabolic line search
through the current value and one step either side (an unbounded side is expanded by doubling
steps), the vertex clamped to two steps and the bounds, and evaluated only when the parabola
predicts a gain of at least :data:`MIN_VERTEX_GAIN` there (a converged coordinate costs no
extra filter run); ``sweeps`` passes over the parameters, the step halving after each. Runs
that do not depend on each other (the two sides of a bracket or of the polish, the
observability tests) are asked for together (``run_many``: in parallel in a job). A
coordinate whose line search gained less than :data:`MIN_VERTEX_GAIN` sits out the next sweeps
while the other coordinates change the likelihood by less than :data:`OBSERVABLE_DLL` since
(its optimum cannot have moved by more than its uncertainty). Every filter run is memoised by
the parameter vector, so a point a sweep or the polish revisits costs nothing. A
parameter is **observable** when moving it one step either way from its estimate (a factor 2
for scales) lowers the likelihood by at least :data:`OBSERVABLE_DLL` (1.92: the 95 %
likelihood-ratio test, chi-square 1 dof over 2); one that is not keeps its prior.

This module holds no navigation or job logic: :func:`tune` takes a function that runs the
filter for a ``theta`` and returns its innovation log (:mod:`insgnss.job.tuning` builds it from
a job), so it works with any process model whose result has the engine's innovation columns
(``time type dof nis threshold accepted recovered innov_k innov_std_k``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

#: log-likelihood drop (one step either side) below which a parameter is not observable
OBSERVABLE_DLL = 1.92
#: suffix of the measurement types of the coast view (withheld over tuning windows)
COAST_SUFFIX = "_coast"
#: cap of the coast view's normalised squared residual: an overconfident dead reckoning must
#: pay for it, only gross GNSS outliers are bounded
COAST_CAP = 100.0
#: most full steps the final polish moves one parameter
POLISH_STEPS = 4
#: cap of the normalised squared innovation (robust likelihood), chi-square 1 dof at 0.9999
INNOVATION_CAP = 15.137
#: log-likelihood gain the parabola must predict at its vertex for the vertex to be evaluated
#: (a filter run): far below :data:`OBSERVABLE_DLL`, so a skipped vertex could not change an
#: observability decision
MIN_VERTEX_GAIN = 0.05


@dataclass
class Parameter:
    """One tunable parameter.

    Attributes
    ----------
    name : str
        Key in the ``theta`` mapping (and in ``summary.json`` ``"autotune"``).
    prior : float
        Starting value and the value kept when not observable.
    lower, upper : float
        Bounds of the search.
    step : float
        Initial step: a factor (``log=True``, e.g. 2.0) or an additive step (``log=False``).
    log : bool
        Search in ``log(value)`` (scales, sigmas) or linearly (time offsets).
    unit : str
        Unit of the value as reported.
    doc : str
        What the parameter is (for reports).
    """

    name: str
    prior: float
    lower: float
    upper: float
    step: float = 2.0
    log: bool = True
    unit: str = ""
    doc: str = ""

    def __post_init__(self):
        if self.log and not (0 < self.lower <= self.prior <= self.upper):
            raise ValueError(f"parameter {self.name}: need 0 < lower <= prior <= upper")
        if not self.log and not (self.lower <= self.prior <= self.upper):
            raise ValueError(f"parameter {self.name}: need lower <= prior <= upper")

    # search coordinate u <-> value
    def to_u(self, v: float) -> float:
        return math.log(v) if self.log else float(v)

    def to_value(self, u: float) -> float:
        return math.exp(u) if self.log else float(u)

    @property
    def h(self) -> float:
        return math.log(self.step) if self.log else float(self.step)

    @property
    def bounds_u(self) -> tuple[float, float]:
        return self.to_u(self.lower), self.to_u(self.upper)


@dataclass
class TuneResult:
    """Outcome of :func:`tune`.

    ``values`` are the parameters to use (the estimate where observable, else the prior);
    ``parameters`` holds per parameter ``value prior unit observable estimate dll_down dll_up
    at_bound``; ``log_likelihood`` the prior's and the final value; ``sweeps`` and
    ``evaluations`` the work done.
    """

    values: dict
    parameters: dict
    log_likelihood: dict
    sweeps: int
    evaluations: int
    types: list = field(default_factory=list)
    #: tuning windows of the coast view [s] (set by the caller that withheld them)
    tuning_windows: list = field(default_factory=list)
    #: wall time of the search [s] (set by the caller, with the filter runs it timed)
    seconds: float | None = None
    #: filter runs of the one-step stage, when the search ran in two stages
    one_step_evaluations: int | None = None

    def as_dict(self) -> dict:
        """JSON-ready form (``summary.json`` ``"autotune"``)."""
        return {"method": "innovation maximum likelihood (composite, robust)",
                "sweeps": self.sweeps, "evaluations": self.evaluations,
                "one_step_evaluations": self.one_step_evaluations, "seconds": self.seconds,
                "log_likelihood": dict(self.log_likelihood), "types": list(self.types),
                "tuning_windows": [list(w) for w in self.tuning_windows],
                "parameters": {k: dict(v) for k, v in self.parameters.items()}}


def innovation_terms(innovations: pd.DataFrame, cap: float = INNOVATION_CAP,
                     coast_cap: float = COAST_CAP) -> dict:
    """Per measurement type: ``(number of rows, mean per row of the composite log-likelihood
    sum_j -1/2 [log(2 pi S_jj) + min(nu_j^2 / S_jj, cap)])`` (module docstring; ``coast_cap``
    for the coast types)."""
    out = {}
    if innovations is None or not len(innovations):
        return out
    ncomp = sum(1 for c in innovations.columns if c.startswith("innov_") and
                not c.startswith("innov_std_"))
    for typ, g in innovations.groupby("type", sort=False):
        c = coast_cap if str(typ).endswith(COAST_SUFFIX) else cap
        tot = np.zeros(len(g))
        for j in range(ncomp):
            v = g[f"innov_{j}"].to_numpy(float)
            s = g[f"innov_std_{j}"].to_numpy(float)
            ok = np.isfinite(v) & np.isfinite(s) & (s > 0)
            q = np.minimum((v[ok] / s[ok]) ** 2, c)
            tot[ok] += -0.5 * (np.log(2.0 * np.pi * s[ok] ** 2) + q)
        out[str(typ)] = (int(len(g)), float(np.mean(tot)))
    return out


def log_likelihood(terms: dict, weights: dict, types: Sequence[str] | None = None) -> float:
    """``sum_types weights[type] * mean[type]`` over ``types`` (default: every weighted type);
    ``-inf`` when a weighted type has no rows."""
    total = 0.0
    for typ, n in weights.items():
        if types is not None and typ not in types:
            continue
        if typ not in terms:
            return -math.inf
        total += n * terms[typ][1]
    return total


def view_weights(counts: dict) -> dict:
    """Weights of the measurement types from their row counts in the prior run: a type weighs
    its count, and the *coast* view (types ending in :data:`COAST_SUFFIX`: measurements
    withheld over tuning windows and predicted by dead reckoning) weighs as much in total as
    the one-step view (every other type)."""
    one = {t: n for t, n in counts.items() if not t.endswith(COAST_SUFFIX)}
    coast = {t: n for t, n in counts.items() if t.endswith(COAST_SUFFIX)}
    n1, nc = sum(one.values()), sum(coast.values())
    if nc and n1:
        coast = {t: n * n1 / nc for t, n in coast.items()}
    return {**one, **coast}


def tune(run: Callable[[dict], pd.DataFrame | None], parameters: Sequence[Parameter], *,
         sweeps: int = 2, types: Sequence[str] | None = None,
         progress: Callable[[str], None] | None = None,
         reference: dict | None = None,
         run_many: Callable[[list[dict]], list] | None = None) -> TuneResult:
    """Maximum-likelihood estimate of ``parameters`` (module docstring).

    Parameters
    ----------
    run : callable
        ``run(theta) -> innovations`` runs the filter with the parameter values ``theta``
        (``{name: value}``) and returns its innovation log, or None when the run failed
        (stopped early): that ``theta`` is rejected.
    parameters : sequence of Parameter
    sweeps : int
        Passes over the parameters.
    types : sequence of str, optional
        Measurement types whose innovations form the likelihood (default: every type of the
        prior run).
    progress : callable, optional
        Receives a line of text per evaluation.
    reference : dict, optional
        The values the likelihood-ratio test of observability compares with and that an
        unobservable parameter keeps (default: the priors, which are also the start).
    run_many : callable, optional
        ``run_many([theta, ...]) -> [innovations, ...]``: ``run`` of several parameter sets
        that do not depend on each other (the two sides of a line search or of the polish,
        the observability tests), e.g. in parallel (:class:`insgnss.executors.ForkedHelpers`). The
        search evaluates the same points either way, so the result is the same.
    """
    params = list(parameters)
    theta0 = {p.name: p.prior for p in params}
    cache: dict = {}
    state = {"weights": None, "evaluations": 0}

    def key(theta):
        return tuple(round(p.to_u(theta[p.name]), 9) for p in params)

    def objectives(thetas: list[dict]) -> list[float]:
        """The log-likelihood of each parameter set; the new ones run together (``run_many``)."""
        todo = {}
        for th in thetas:
            k = key(th)
            if k not in cache and k not in todo:
                todo[k] = dict(th)
        if todo:
            new = list(todo.values())
            runs = run_many(new) if run_many is not None and len(new) > 1 else \
                [run(th) for th in new]
            for k, th, inn in zip(todo, new, runs, strict=True):
                cache[k] = value(th, inn)
        return [cache[key(th)] for th in thetas]

    def value(theta, inn) -> float:
        state["evaluations"] += 1
        if inn is None:
            val = -math.inf
        else:
            terms = innovation_terms(inn)
            if state["weights"] is None:  # the prior run fixes the rows' weights
                state["weights"] = view_weights({t: n for t, (n, _) in terms.items()
                                                 if types is None or t in types})
            val = log_likelihood(terms, state["weights"], types)
        if progress is not None:
            progress(", ".join(f"{p.name}={theta[p.name]:.4g}" for p in params)
                     + f": log-likelihood {val:.2f}")
        return val

    def objective(theta) -> float:
        return objectives([theta])[0]

    L0 = objective(theta0)
    if not math.isfinite(L0):
        raise RuntimeError("the filter run with the prior noise parameters failed: nothing to "
                           "tune from")
    theta, best = dict(theta0), L0
    scale = 1.0
    done = 0
    last: dict = {}  # name -> (gain of its last line search, likelihood after it)
    for _ in range(int(sweeps)):
        moved = False
        for p in params:
            if p.name in last and _converged(*last[p.name], best):
                continue
            u_new, f_new = _line_search(p, theta, best, objectives, scale)
            gain = max(f_new - best, 0.0)
            if f_new > best + 1e-9:
                theta[p.name], best = p.to_value(u_new), f_new
                moved = True
            last[p.name] = (gain, best)
        done += 1
        scale *= 0.5
        if not moved:
            break
    # polish and observability: one (initial) step either way from the estimate; a side that
    # is better moves the estimate there (the coordinate search had not converged)
    table, values, tests = {}, {}, []
    for p in params:
        lo, hi = p.bounds_u
        for _ in range(POLISH_STEPS):
            u = p.to_u(theta[p.name])
            d, better = {}, None
            sides = (("down", max(u - p.h, lo)), ("up", min(u + p.h, hi)))
            inside = [(side, uu) for side, uu in sides if abs(uu - u) >= 1e-12]
            fs = dict(zip([side for side, _ in inside],
                          objectives([{**theta, p.name: p.to_value(uu)} for _, uu in inside]),
                          strict=True))
            for side, uu in sides:
                if side not in fs:
                    d[side] = None  # at the bound
                    continue
                f = fs[side]
                d[side] = best - f
                if f > best and (better is None or f > better[1]):
                    better = (uu, f)
            if better is None:
                break
            theta[p.name], best = p.to_value(better[0]), better[1]
        # the likelihood-ratio test of the prior against the estimate, the others at theirs
        # now: its run does not change the search, so the tests of all parameters run
        # together after the polish (same points, same values)
        prior = p.prior if reference is None else reference[p.name]
        tests.append((p, prior, {**theta, p.name: prior}, best, theta[p.name], d))
    for (p, prior, _, best_p, estimate, d), f_prior in zip(
            tests, objectives([t[2] for t in tests]), strict=True):
        dll_prior = best_p - f_prior
        observable = bool(dll_prior >= OBSERVABLE_DLL)
        values[p.name] = estimate if observable else prior
        table[p.name] = {"value": values[p.name], "prior": prior, "estimate": estimate,
                         "unit": p.unit, "observable": observable,
                         "at_bound": d["down"] is None or d["up"] is None,
                         "dll_prior": dll_prior, "dll_down": d["down"], "dll_up": d["up"],
                         "doc": p.doc}
    final = objective(values)
    return TuneResult(values=values, parameters=table,
                      log_likelihood={"prior": L0, "estimate": best, "final": final},
                      sweeps=done, evaluations=state["evaluations"],
                      types=sorted(state["weights"] or {}))


def _converged(gain: float, after: float, best: float) -> bool:
    """A coordinate is left out of the next sweep (module docstring) when its last line search
    gained less than :data:`MIN_VERTEX_GAIN` and the other coordinates have since changed the
    likelihood by less than :data:`OBSERVABLE_DLL` (so they cannot have moved its optimum by
    more than its own uncertainty); the polish still tests it a full step either way."""
    return gain < MIN_VERTEX_GAIN and best - after < OBSERVABLE_DLL


def _line_search(p: Parameter, theta: dict, f0: float, objectives, scale: float
                 ) -> tuple[float, float]:
    """Parabolic line search of one coordinate (module docstring): ``(best u, its value)``.
    ``objectives([theta, ...])``: the log-likelihoods of parameter sets (the two sides of a
    bracket are evaluated together)."""
    lo, hi = p.bounds_u
    u0 = p.to_u(theta[p.name])
    h = p.h * scale

    def fs(*us):
        us = [min(max(u, lo), hi) for u in us]
        vals = objectives([{**theta, p.name: p.to_value(u)} for u in us])
        return list(zip(vals, us, strict=True))

    def f(u):
        return fs(u)[0]

    (fm, um), (fp, up) = fs(u0 - h, u0 + h)
    best_u, best_f = u0, f0
    for uu, ff in ((um, fm), (up, fp)):
        if ff > best_f:
            best_u, best_f = uu, ff
    # expand while the best is at an end of the bracket (monotone so far), up to 3 doublings
    step = h
    for _ in range(3):
        if best_u == u0 or best_u in (lo, hi):
            break
        direction = 1.0 if best_u > u0 else -1.0
        step *= 2.0
        fn, un = f(best_u + direction * step)
        if fn > best_f:
            u0, f0, best_u, best_f = best_u, best_f, un, fn
        else:
            break
    # parabola through (best - h, best, best + h) where all three are known
    a_u, b_u = best_u - h, best_u + h
    (fa, ua), (fb, ub) = fs(a_u, b_u)
    if ua < best_u < ub and math.isfinite(fa) and math.isfinite(fb):
        den = fa - 2.0 * best_f + fb
        # concave: the vertex, unless the parabola predicts less than MIN_VERTEX_GAIN there
        # (the gain at the vertex is (fa - fb)^2 / (-8 den))
        if den < 0 and (fa - fb) ** 2 / (-8.0 * den) >= MIN_VERTEX_GAIN:
            ux = best_u + 0.5 * h * (fa - fb) / den
            ux = min(max(ux, best_u - 2 * h, lo), best_u + 2 * h, hi)
            fx, ux = f(ux)
            if fx > best_f:
                best_u, best_f = ux, fx
    for uu, ff in ((ua, fa), (ub, fb)):
        if ff > best_f:
            best_u, best_f = uu, ff
    return best_u, best_f


__all__ = ["COAST_CAP", "COAST_SUFFIX", "INNOVATION_CAP", "MIN_VERTEX_GAIN", "OBSERVABLE_DLL",
           "Parameter", "TuneResult", "innovation_terms", "log_likelihood", "tune", "view_weights"]
