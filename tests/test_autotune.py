"""Self-tuning (insgnss.autotune, insgnss.job.tuning): the likelihood, the search and its
observability rule on analytic cases; on a simulation with known noise the estimates of ARW,
VRW and the GNSS sigma scale and the NEES coverage they give."""

import math

import numpy as np
import pandas as pd
import pytest

from insgnss.autotune import (
    COAST_SUFFIX,
    OBSERVABLE_DLL,
    Parameter,
    innovation_terms,
    tune,
    view_weights,
)
from insgnss.config import load_job_dict
from insgnss.pipeline import load_inputs, run_job


def _log(types, nu, std):
    nu, std = np.atleast_2d(nu), np.atleast_2d(std)
    rows = {"time": np.arange(nu.shape[0], dtype=float), "type": types, "dof": nu.shape[1],
            "nis": 0.0, "threshold": np.inf, "accepted": True, "recovered": False}
    for j in range(nu.shape[1]):
        rows[f"innov_{j}"] = nu[:, j]
    for j in range(nu.shape[1]):
        rows[f"innov_std_{j}"] = std[:, j]
    return pd.DataFrame(rows)


def test_innovation_terms_is_the_gaussian_log_likelihood():
    nu = np.array([[0.3, -1.0], [1.5, 0.5]])
    s = np.array([[1.0, 2.0], [0.5, 1.0]])
    (n, mean), = innovation_terms(_log("gnss_pos", nu, s)).values()
    q = (nu / s) ** 2
    expect = np.mean(np.sum(-0.5 * (np.log(2 * np.pi * s ** 2) + q), axis=1))
    assert n == 2 and mean == pytest.approx(expect)
    # the robust cap bounds an outlier's term (5 sigma -> capped at the 1-dof gate, 15.1)
    (_, capped), = innovation_terms(_log("gnss_pos", [[5.0]], [[1.0]])).values()
    assert capped == pytest.approx(-0.5 * (np.log(2 * np.pi) + 15.137))
    # ... but the coast view's cap is higher: an overconfident dead reckoning pays
    (_, coast), = innovation_terms(_log("gnss_pos" + COAST_SUFFIX, [[5.0]], [[1.0]])).values()
    assert coast == pytest.approx(-0.5 * (np.log(2 * np.pi) + 25.0))


def test_view_weights_balance_one_step_and_coast():
    w = view_weights({"gnss_pos": 900, "nhc": 100, "gnss_pos" + COAST_SUFFIX: 50})
    assert w["gnss_pos"] == 900 and w["nhc"] == 100
    assert w["gnss_pos" + COAST_SUFFIX] == pytest.approx(1000)


def _scale_problem(true_scale, n=400, seed=1):
    """Innovations whose sigma is sqrt(a^2 + (s r)^2): 'filter' runs for a noise scale s."""
    rng = np.random.default_rng(seed)
    a, r = 0.3, 1.0
    z = rng.standard_normal(n)
    truth = math.hypot(a, true_scale * r)

    def run(theta):
        s = theta["scale"]
        std = math.hypot(a, s * r)
        return _log("gnss_pos", (truth * z)[:, None], np.full((n, 1), std))

    return run


def test_tune_finds_the_maximum_likelihood_scale():
    run = _scale_problem(3.0)
    res = tune(run, [Parameter("scale", 1.0, 0.1, 30.0)], sweeps=3)
    row = res.parameters["scale"]
    # the ML estimate of the innovation sigma is the sample RMS: the scale that matches it
    z = run({"scale": 1.0})["innov_0"].to_numpy()
    s_ml = math.sqrt(max(np.mean(z ** 2) - 0.3 ** 2, 0.0))
    assert row["observable"] and row["estimate"] == pytest.approx(s_ml, rel=0.05)
    assert res.values["scale"] == row["estimate"]
    assert res.log_likelihood["final"] >= res.log_likelihood["prior"]


def test_converged_line_search_skips_the_vertex_run(monkeypatch):
    """A vertex the parabola predicts to gain less than MIN_VERTEX_GAIN costs no filter run;
    one that gains more is evaluated."""
    from insgnss import autotune as at

    p = Parameter("u", 0.0, -5.0, 5.0, step=0.5, log=False)

    def sharp(th):  # maximum at 0.3, gain at the vertex 2.0 from the bracket around 0.5
        return -50.0 * (th["u"] - 0.3) ** 2

    def each(f):  # the objectives of several parameter sets (_line_search's interface)
        return lambda thetas: [f(th) for th in thetas]

    u, f = at._line_search(p, {"u": 0.0}, sharp({"u": 0.0}), each(sharp), 1.0)
    assert u == pytest.approx(0.3, abs=1e-12) and f == pytest.approx(0.0, abs=1e-12)

    def calls_on_flat():
        calls = []

        def flat(th):  # predicted vertex gain 1e-6, far below MIN_VERTEX_GAIN
            calls.append(th["u"])
            return -1e-4 * th["u"] ** 2
        u, _ = at._line_search(p, {"u": 0.1}, flat({"u": 0.1}), each(flat), 1.0)
        return u, len(calls)

    u, n = calls_on_flat()
    assert u == pytest.approx(0.1) and n == 5  # start, two neighbours, the bracket again
    monkeypatch.setattr(at, "MIN_VERTEX_GAIN", 0.0)
    u0, n0 = calls_on_flat()
    assert n0 == n + 1 and u0 != pytest.approx(0.1)  # the vertex run (a 1e-6 gain)
    assert at.MIN_VERTEX_GAIN < OBSERVABLE_DLL


def test_unobservable_parameter_keeps_its_prior():
    run = _scale_problem(1.0)

    def run2(theta):  # "other" does not change the innovations at all
        return run({"scale": theta["scale"]})

    res = tune(run2, [Parameter("scale", 2.0, 0.1, 30.0), Parameter("other", 0.5, 0.01, 10.0)])
    row = res.parameters["other"]
    assert not row["observable"] and row["dll_prior"] < OBSERVABLE_DLL
    assert res.values["other"] == 0.5


def test_converged_coordinate_sits_out_the_next_sweep(monkeypatch):
    """A coordinate whose line search gained less than MIN_VERTEX_GAIN is not searched again
    while the others change the likelihood by less than OBSERVABLE_DLL: fewer filter runs, the
    same estimates (the polish still tests it a full step either way)."""
    from insgnss import autotune as at

    run = _scale_problem(3.0)

    def counted():
        calls = []

        def run2(theta):  # "other" does not change the innovations: its search gains 0
            calls.append(dict(theta))
            return run({"scale": theta["scale"]})
        res = tune(run2, [Parameter("other", 0.5, 0.01, 10.0), Parameter("scale", 2.5, 0.1, 30.0)],
                   sweeps=3)
        return res, calls

    res, calls = counted()
    converged = at._converged
    monkeypatch.setattr(at, "_converged", lambda *a: False)
    full, full_calls = counted()
    assert res.evaluations == len(calls) < full.evaluations == len(full_calls)
    assert res.values == full.values and res.parameters["scale"]["observable"]
    assert converged(0.01, -10.0, -9.0) and not converged(0.01, -10.0, -10.0 + 2.0)
    assert not converged(0.1, -10.0, -10.0)


def test_runs_together_give_the_serial_result():
    """The two sides of a bracket and of the polish go to run_many at once (forked helpers in a
    job); the search, its evaluations and its result are those of one run after the other."""
    from insgnss.executors import fork_map

    scale, nhc = _scale_problem(3.0), _scale_problem(0.5, seed=2)

    def run(theta):
        b = nhc({"scale": theta["nhc"]})
        b["type"] = "nhc"
        return pd.concat([scale(theta), b], ignore_index=True)

    params = [Parameter("scale", 1.0, 0.1, 30.0), Parameter("nhc", 1.0, 0.01, 10.0)]
    serial = tune(run, params, sweeps=3)
    batches = []

    def run_many(thetas):
        batches.append(len(thetas))
        return fork_map(run, thetas, 1)

    together = tune(run, params, sweeps=3, run_many=run_many)
    assert together.values == serial.values and together.parameters == serial.parameters
    assert together.log_likelihood == serial.log_likelihood
    assert together.evaluations == serial.evaluations
    assert batches and set(batches) == {2}  # pairs, each counted once
    assert sum(batches) < serial.evaluations


def test_failed_runs_are_rejected():
    run = _scale_problem(2.0)

    def run2(theta):  # the filter 'diverges' for small scales
        return None if theta["scale"] < 1.0 else run(theta)

    res = tune(run2, [Parameter("scale", 1.0, 0.1, 30.0)])
    assert res.values["scale"] >= 1.0
    with pytest.raises(RuntimeError):
        tune(lambda theta: None, [Parameter("scale", 1.0, 0.1, 30.0)])


# --- simulation with known noise ------------------------------------------------------------
TRUE_ARW, TRUE_VRW, TRUE_SCALE = 0.5, 0.3, 2.0  # deg/sqrt(h), m/s/sqrt(h), file std x 1/2


def _sim_job(autotune: bool):
    hold = {"type": "hold", "duration": 60.0}
    return load_job_dict({
        "scenario": {"name": "autotune_sim", "seed": 7, "imu_rate": 100.0},
        "trajectory": {"vehicle": "land", "lat": 45.0, "lon": 7.0, "height": 200.0,
                       "heading": 10.0, "segments": [
                           {"type": "static", "duration": 20.0},
                           {"type": "accelerate", "speed": 12.0, "acceleration": 1.5}, hold,
                           {"type": "turn", "angle": 90.0, "rate": 10.0}, hold,
                           {"type": "turn", "angle": -120.0, "rate": 8.0},
                           {"type": "accelerate", "speed": 16.0, "acceleration": 1.0}, hold,
                           {"type": "turn", "angle": 60.0, "rate": 12.0}, hold]},
        # white noise and constant turn-on biases only: ARW and VRW are the noise to find
        "imu": {"gyro_arw_deg_sqrt_h": TRUE_ARW, "accel_vrw_m_s_sqrt_h": TRUE_VRW,
                "gyro_bias_deg_h": 50.0, "accel_bias_mg": 5.0},
        "gnss": {"rate": 5.0, "horizontal_std": 0.1, "vertical_std": 0.2, "q": 5},
        "initialization": {"method": "static", "static_duration": 15.0, "heading_deg": 10.0},
        "aiding": {"gnss_position": True, "q_scale": {"5": 1.0}},
        "outages": {"windows": [[100.0, 115.0], [200.0, 215.0]]},
        "filter": {"imu_grade": "tactical", "autotune": autotune, "smoother": False,
                   "bias_model": "random_constant",
                   **({"autotune_parameters": ["gnss_pos_scale_q5", "accel_vrw", "gyro_arw"]}
                      if autotune else {}),
                   # the fixed model: white noise 3x too small, biases right
                   "imu_model": {"gyro_arw_deg_sqrt_h": TRUE_ARW / 3,
                                 "accel_vrw_m_s_sqrt_h": TRUE_VRW / 3,
                                 "gyro_bias_deg_h": 50.0, "accel_bias_mg": 5.0,
                                 "gyro_bias_instability_deg_h": 0.0,
                                 "accel_bias_instability_ug": 0.0}},
        "outputs": {"report": False, "progress": False},
    })


def _run(autotune: bool):
    job = _sim_job(autotune)
    inputs = load_inputs(job)
    g = inputs.gnss.copy()
    g.attrs = dict(inputs.gnss.attrs)
    for c in ("east_std", "north_std", "up_std"):  # the file understates its sigma by 2
        g[c] = g[c] / TRUE_SCALE
    inputs.gnss = g
    return run_job(job, progress=False, inputs=inputs)


def _coverage(res):
    """Share of forward epochs (after 30 s) whose east and north errors are inside 3 sigma, and
    the mean horizontal NEES (2 for a consistent filter)."""
    e = res.evaluation["forward"]["errors"]
    e = e[e.index > e.index[0] + 30.0]
    inside = (np.abs(e["east"]) <= 3 * e["east_std"]) & (np.abs(e["north"]) <= 3 * e["north_std"])
    nees = (e["east"] / e["east_std"]) ** 2 + (e["north"] / e["north_std"]) ** 2
    return float(inside.mean()), float(nees.mean())


@pytest.fixture(scope="module")
def forked_tuning():
    """The simulation's self-tuning job run with one forked helper for the paired filter runs
    (as on a 2-core machine, whatever this one has): ``(result, helpers per batch)``."""
    import multiprocessing

    from insgnss import executors

    helpers = []
    batch = executors.ForkedHelpers.map

    def counted(self, items):
        items = list(items)
        helpers.append(min(len(self._start()), len(items) - 1) if len(items) > 1 else 0)
        return batch(self, items)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(executors.ForkedHelpers, "map", counted)
        if "fork" in multiprocessing.get_all_start_methods():
            mp.setattr(executors, "usable_cores", lambda: 2)
        return _run(True), helpers


def test_autotune_recovers_known_noise_and_coverage(forked_tuning):
    fixed, tuned = _run(False), forked_tuning[0]
    at = tuned.summary["autotune"]["parameters"]
    assert at["gyro_arw"]["value"] == pytest.approx(np.radians(TRUE_ARW) / 60, rel=0.2)
    assert at["accel_vrw"]["value"] == pytest.approx(TRUE_VRW / 60, rel=0.2)
    assert at["gnss_pos_scale_q5"]["value"] == pytest.approx(TRUE_SCALE, rel=0.2)
    assert all(row["observable"] for row in at.values())
    cov_fixed, nees_fixed = _coverage(fixed)
    cov_tuned, nees_tuned = _coverage(tuned)
    # the fixed model is overconfident; the tuned one covers its errors as 3 sigma should
    assert cov_tuned >= cov_fixed and cov_tuned >= 0.97
    assert abs(nees_tuned - 2.0) < abs(nees_fixed - 2.0) and nees_tuned < 3.0
    assert tuned.summary["autotune"]["tuning_windows"]  # the coast view took part


def test_forked_runs_tune_as_one_process(forked_tuning, monkeypatch):
    """A job's self-tuning runs the filter for two parameter sets at once in a forked helper:
    the estimates and the trajectory are those of one process (the runs are deterministic)."""
    import multiprocessing

    from insgnss import executors

    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("forked helpers need fork")
    forked, helpers = forked_tuning
    # a pair: one run here, one in a helper (a pair one of whose runs an earlier stage did:
    # the other alone, here)
    assert set(helpers) == {0, 1} and helpers.count(1) > helpers.count(0)
    monkeypatch.setattr(executors, "usable_cores", lambda: 1)
    alone = _run(True)
    a, b = forked.summary["autotune"], alone.summary["autotune"]
    assert a["evaluations"] == b["evaluations"]
    assert a["parameters"] == b["parameters"] and a["log_likelihood"] == b["log_likelihood"]
    pd.testing.assert_frame_equal(forked.filter.forward, alone.filter.forward, check_exact=True)


def test_nhc_sigma_is_tuned_only_when_named():
    """The car profile's NHC sigma is not in the default parameter set (its time-correlated
    violations bias the one-step likelihood low); a job that names it gets it, with the prior
    from the job."""
    from types import SimpleNamespace

    from insgnss.imu import grade
    from insgnss.job.tuning import EXPLICIT_ONLY, parameters

    def names(filt):
        job = load_job_dict({"job": {"platform": "car"},
                             "filter": {"autotune": True, **filt}})
        ctx = SimpleNamespace(job=job, inputs=SimpleNamespace(gnss=None), windows=[])
        return {p.name: p for p in parameters(ctx, grade("consumer"))}

    default = names({})
    assert EXPLICIT_ONLY == ("nhc_std",)
    assert "nhc_std" not in default and {"gyro_arw", "accel_vrw", "zupt_std"} <= set(default)
    named = names({"autotune_parameters": ["nhc_std", "gyro_arw"]})
    assert set(named) == {"nhc_std", "gyro_arw"}
    assert named["nhc_std"].prior == pytest.approx(0.1)
