"""Monte Carlo (issue 9): seeds, settings, per-epoch statistics on synthetic runs with known
distributions, and a tiny simulated car study run in-process, on a local process pool and on a
Dask LocalCluster with 2 workers - identical bit for bit - with a failing run that is reported
and does not stop the others."""

from __future__ import annotations

import functools
import json
import tomllib

import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2

from insgnss.cli import main as cli_main
from insgnss.errors import ConfigError
from insgnss.executors import DaskCluster, InProcess, LocalPool
from insgnss.montecarlo import (
    ERROR_QUANTITIES,
    MonteCarloSettings,
    RunRecord,
    aggregate,
    consistency_summary,
    draw_seeds,
    run_montecarlo,
    run_one,
)

MASTER = 20240609
RUNS = 20


TINY = f"""
# 90 s car at 50 Hz (20 s static, two turns), tactical IMU, 1 Hz GNSS, one 20 s outage
[scenario]
name = "mc_tiny"
seed = 1
imu_rate = 50.0

[trajectory]
vehicle = "land"
lat = 45.0
lon = 7.0
height = 300.0
heading = 30.0
segments = [
  {{ type = "static", duration = 20.0 }},
  {{ type = "accelerate", speed = 15.0, acceleration = 2.0 }},
  {{ type = "turn", angle = 90.0, rate = 15.0 }},
  {{ type = "hold", duration = 15.0 }},
  {{ type = "turn", angle = -60.0, rate = 10.0 }},
  {{ type = "hold", duration = 30.0 }},
]

[imu]
grade = "tactical"

[gnss]
rate = 1.0
horizontal_std = 1.0
vertical_std = 2.0
velocity = true
velocity_std = 0.05
q = 5

[initialization]
method = "static"
static_duration = 15.0
position_std = 2.0

[aiding]
gnss_position = true
gnss_velocity = true
q_scale = {{ 5 = 1.0 }}

[outages]
windows = [[45.0, 65.0]]

[filter]
bias_model = "random_walk"

[outputs]
report = false
progress = false

[montecarlo]
runs = {RUNS}
seed = {MASTER}
"""


def tiny_job() -> dict:
    return tomllib.loads(TINY)


def fail_on(job, seed, settings=None, path=None, *, bad=()):
    """Work unit that raises for the seeds in ``bad`` (module level: it pickles by name)."""
    if seed in bad:
        raise RuntimeError(f"injected failure for seed {seed}")
    return run_one(job, seed, settings, path)


# --- seeds and settings ---------------------------------------------------------------------------
def test_seeds_reproducible_independent_and_extendable():
    a = draw_seeds(7, 200)
    assert a == draw_seeds(7, 200)
    assert a[:20] == draw_seeds(7, 20)          # a bigger study extends a smaller one
    assert len(set(a)) == 200
    assert all(0 <= s < 2**63 for s in a)
    assert set(a).isdisjoint(draw_seeds(8, 200))
    with pytest.raises(ConfigError):
        draw_seeds(-1, 3)


def test_settings_validation_names_the_key():
    s = MonteCarloSettings.from_table({"runs": 5, "seed": 3, "percentiles": [95, 50],
                                       "coverage_percentile": 99.7})
    assert (s.runs, s.seed) == (5, 3)
    assert s.percentiles == [50.0, 95.0, 99.7]  # the coverage percentile is always computed
    for bad, key in [({"runs": 0}, "montecarlo.runs"), ({"rusn": 3}, "montecarlo.rusn"),
                     ({"solutions": ["backward"]}, "montecarlo.solutions"),
                     ({"confidence": 1.5}, "montecarlo.confidence"),
                     ({"grid_interval": "1"}, "montecarlo.grid_interval"),
                     ({"seed": True}, "montecarlo.seed")]:
        with pytest.raises(ConfigError) as e:
            MonteCarloSettings.from_table(bad, file="x.toml")
        assert e.value.column == key and "x.toml" in str(e.value)


def test_job_without_simulation_is_refused():
    job = tiny_job()
    job["inputs"] = {"imu": {"path": "imu.csv", "format": "native"}}
    with pytest.raises(ConfigError, match="simulate"):
        run_montecarlo(job, runs=2)
    job = tiny_job()
    job["montecarlo"]["percentiles"] = [101]
    with pytest.raises(ConfigError, match="percentiles"):
        run_montecarlo(job, runs=2)


# --- statistics on synthetic runs with known distributions ------------------------------------------
def synthetic_records(m: int, t: np.ndarray, sigma: float, claimed: float, seed: int = 0):
    """Runs whose errors are N(0, sigma) per component while the filter claims ``claimed``."""
    rng = np.random.default_rng(seed)
    q = len(ERROR_QUANTITIES)
    recs = []
    for _ in range(m):
        e = rng.normal(0.0, sigma, (t.size, q))
        e[:, 3] = np.hypot(e[:, 0], e[:, 1])
        s = np.full((t.size, q), claimed)
        s[:, 3] = np.hypot(claimed, claimed)
        nees = np.sum(rng.normal(0.0, sigma / claimed, (t.size, 3, 3)) ** 2, axis=2)
        nis = {"gnss_pos": (t, np.sum(rng.normal(0, 1, (t.size, 3)) ** 2, axis=1),
                            np.full(t.size, 3.0))}
        recs.append(RunRecord(1, t, {"forward": e}, {"forward": s}, {"forward": nees}, nis,
                              [[10.0, 20.0]]))
    return recs


def test_aggregate_recovers_known_distributions():
    t = np.arange(40.0)
    st = MonteCarloSettings(solutions=["forward"])
    stats = aggregate(synthetic_records(4000, t, 0.5, 0.5), st)
    east = stats[(stats.quantity == "east")]
    assert np.all(east["n"] == 4000)
    # per epoch (4000 samples) loosely, averaged over the 40 epochs tightly
    assert np.allclose(east["rms"], 0.5, rtol=0.07)
    assert abs(east["rms"].mean() - 0.5) < 0.004
    assert np.allclose(east["mean"], 0.0, atol=0.04)
    for q, z in ((68, 0.9945), (95, 1.960), (99, 2.576)):   # percentiles of |N(0, 0.5)|
        assert np.allclose(east[f"p{q}"], 0.5 * z, rtol=0.1), q
        assert abs(east[f"p{q}"].mean() / (0.5 * z) - 1) < 0.015, q
    hz = stats[stats.quantity == "horizontal"]              # Rayleigh: p99 = sigma sqrt(-2 ln .01)
    assert abs(hz["p99"].mean() / (0.5 * np.sqrt(-2 * np.log(0.01))) - 1) < 0.015
    assert np.allclose(hz["sigma"], 0.5 * np.sqrt(2))
    nees = stats[stats.quantity == "nees_pos"]
    lo, hi = chi2.ppf([0.025, 0.975], 3 * 4000) / 4000
    assert np.allclose(nees["lower"], lo) and np.allclose(nees["upper"], hi)
    assert np.allclose(nees["mean"], 3.0, rtol=0.08) and abs(nees["mean"].mean() - 3) < 0.02
    nis = stats[stats.quantity == "nis_gnss_pos"]
    assert np.all(nis["dof"] == 3) and np.allclose(nis["mean"], 3.0, rtol=0.08)
    c = consistency_summary(stats, st)
    assert c["coverage_check"]["passed"]
    assert c["nees"]["forward"]["pos"]["inside_fraction"] > 0.85


def test_overconfident_filter_fails_the_checks():
    t = np.arange(40.0)
    st = MonteCarloSettings(solutions=["forward"])
    stats = aggregate(synthetic_records(400, t, 0.5, 0.25), st)   # claims half the true sigma
    c = consistency_summary(stats, st)
    assert not c["coverage_check"]["passed"]
    assert c["coverage"]["forward"]["east"]["fraction"] < 0.05
    assert c["nees"]["forward"]["pos"]["above_fraction"] > 0.95
    assert 11.0 < c["nees"]["forward"]["pos"]["mean"] < 13.0     # 3 * 2^2


# --- the simulated study on three back-ends ----------------------------------------------------------
@pytest.fixture(scope="module")
def reference():
    """20 runs in this process (the reference back-end)."""
    return run_montecarlo(tiny_job(), executor=InProcess())


@pytest.fixture(scope="module")
def dask2():
    pytest.importorskip("dask.distributed")
    with DaskCluster(n_workers=2, processes=True) as ex:
        yield ex


def assert_identical(a, b):
    pd.testing.assert_frame_equal(a.runs, b.runs, check_exact=True)
    pd.testing.assert_frame_equal(a.stats, b.stats, check_exact=True)


def test_reference_study_is_sane(reference):
    s = reference.summary
    assert s["runs_ok"] == RUNS and s["runs_failed"] == 0 and s["master_seed"] == MASTER
    assert [r["seed"] for r in s["runs"]] == draw_seeds(MASTER, RUNS)
    r = reference.runs
    assert set(r["run"]) == set(range(RUNS)) and set(r["solution"]) == {"forward", "smoothed"}
    fwd = reference.stats.query("solution == 'forward' and quantity == 'horizontal'")
    assert fwd["n"].eq(RUNS).all() and fwd["time"].diff().dropna().eq(1.0).all()
    # the outage shows: forward error grows inside it, the smoother removes most of it
    end = s["percentile_table"]
    f_end = next(x for x in end if x["solution"] == "forward" and x["quantity"] == "horizontal"
                 and x["event"] == "outage 1 end")
    s_end = next(x for x in end if x["solution"] == "smoothed" and x["quantity"] == "horizontal"
                 and x["event"] == "outage 1 end")
    assert f_end["time"] == 64.0
    assert f_end["p95"] > 3 * s_end["p95"]
    before = fwd.set_index("time").loc[44.0, "rms"]
    assert fwd.set_index("time").loc[64.0, "rms"] > 3 * before
    # NEES of every block exists where the filter has epochs (1 Hz) and is finite
    nees = reference.runs.query("quantity == 'nees_pos'")
    assert np.isfinite(nees["value"]).all() and (nees["value"] >= 0).all()


def test_rerun_reproduces_every_run_bit_for_bit(reference):
    # a smaller study with the same master seed repeats the first runs exactly
    again = run_montecarlo(tiny_job(), runs=5, seed=MASTER)
    ref5 = reference.runs[reference.runs["run"] < 5].reset_index(drop=True)
    pd.testing.assert_frame_equal(again.runs, ref5, check_exact=True, check_categorical=False)
    # and one run on its own, from its seed alone
    k = 7
    rec = run_one(tiny_job(), reference.summary["runs"][k]["seed"])
    for name in ("forward", "smoothed"):
        assert np.array_equal(rec.errors[name], reference.records[k].errors[name])
        assert np.array_equal(rec.sigmas[name], reference.records[k].sigmas[name])
        assert np.array_equal(rec.nees[name], reference.records[k].nees[name], equal_nan=True)


def test_dask_local_cluster_identical_to_in_process(reference, dask2):
    assert dask2.workers == 2
    res = run_montecarlo(tiny_job(), executor=dask2)
    assert res.summary["executor"]["backend"] == "dask"
    workers = {r["worker"] for r in res.summary["runs"]}
    assert len(workers) == 2, workers          # the runs really went to two processes
    assert_identical(reference, res)


def test_failing_run_is_reported_and_the_others_go_on(reference, dask2):
    n = 6
    seeds = draw_seeds(MASTER, n)
    fn = functools.partial(fail_on, bad=frozenset({seeds[1], seeds[4]}))
    res = run_montecarlo(tiny_job(), runs=n, executor=dask2, run_fn=fn)
    s = res.summary
    assert (s["runs_ok"], s["runs_failed"]) == (n - 2, 2)
    assert [(f["run"], f["seed"], f["error"]) for f in s["failures"]] == \
        [(1, seeds[1], "RuntimeError"), (4, seeds[4], "RuntimeError")]
    assert "injected failure" in s["failures"][0]["message"]
    assert "injected failure" in res.failures[0]["traceback"]   # the worker's traceback
    assert [r["ok"] for r in s["runs"]] == [True, False, True, True, False, True]
    keep = reference.runs["run"].isin([0, 2, 3, 5])
    pd.testing.assert_frame_equal(res.runs.reset_index(drop=True),
                                  reference.runs[keep].reset_index(drop=True),
                                  check_exact=True, check_categorical=False)
    assert res.stats.query("quantity == 'east'")["n"].eq(n - 2).all()


def test_local_pool_and_cli_write_the_results(tmp_path, reference):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY.replace(f"runs = {RUNS}", "runs = 4"))
    out = tmp_path / "mc"
    assert cli_main(["montecarlo", str(path), "--workers", "2", "-o", str(out),
                     "--no-progress"]) == 0
    files = {p.name for p in out.iterdir()}
    assert {"montecarlo.parquet", "statistics.parquet", "summary.json", "envelopes.png",
            "envelopes_smoothed.png", "consistency.png"} <= files
    assert not [f for f in files if f.endswith(".tmp")]
    runs = pd.read_parquet(out / "montecarlo.parquet")
    ref4 = reference.runs[reference.runs["run"] < 4].reset_index(drop=True)
    pd.testing.assert_frame_equal(runs, ref4, check_exact=True, check_categorical=False)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["executor"] == {"backend": "local-pool", "workers": 2}
    assert summary["runs_ok"] == 4 and summary["master_seed"] == MASTER
    assert summary["coverage_check"]["statement"].startswith("3 sigma >= p99")
    assert {"nees", "nis", "coverage", "percentile_table"} <= set(summary)
    # a bad [montecarlo] key is a clean CLI error (exit 2) naming the key
    path.write_text(TINY + "bogus = 1\n")
    assert cli_main(["montecarlo", str(path), "-o", str(out)]) == 2


def test_local_pool_reports_a_dead_worker():
    """A worker process that dies fails its task (reported); the pool is rebuilt."""
    import os

    with LocalPool(1) as ex:
        out = ex.run(os._exit, [(3,)], labels=["dies"])
        assert not out[0].ok and out[0].label == "dies"
        assert out[0].error.type == "BrokenProcessPool"
        ok = ex.run(divmod, [(7, 2), (9, 4)])
        assert [o.value for o in ok] == [(3, 1), (2, 1)]


def test_runs_lay_the_epoch_grid_at_every_grid_time(monkeypatch):
    """The NEES needs P at the grid epochs: a run sets ``filter.epoch_grid = "always"`` unless
    the job sets the key itself."""
    import insgnss.pipeline

    seen = []

    def capture(job, **kw):
        seen.append(job["filter"]["epoch_grid"])
        raise RuntimeError("captured")

    monkeypatch.setattr(insgnss.pipeline, "run_job", capture)
    for extra, want in (("", "always"), ('epoch_grid = "gaps"\n', "gaps")):
        job = tomllib.loads(TINY.replace('bias_model = "random_walk"\n',
                                         'bias_model = "random_walk"\n' + extra))
        with pytest.raises(RuntimeError, match="captured"):
            run_one(job, 1)
        assert seen[-1] == want
