"""Tightly coupled GNSS in jobs (``[aiding] gnss = "tight"``, ``[inputs.gnss_raw]``,
``outages.keep_satellites``): key checks, and the walk job on the shared data (docs/tight.md,
bench/bench_tight.py): per-satellite updates, at most N satellites inside the outage windows,
and the end-of-outage drift with 3 satellites below 2 m relative to the run's own non-outage
error."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest
from conftest import shared_data

from insgnss.config import load_job_dict
from insgnss.earth import geodetic_to_enu
from insgnss.errors import ConfigError

JOB = Path(__file__).resolve().parents[1] / "scenarios" / "walk_0827_tight.toml"


def _job_dict() -> dict:
    with open(JOB, "rb") as f:
        return tomllib.load(f)


def test_tight_keys_are_range_checked():
    d = _job_dict()
    d["aiding"]["gnss"] = "tightly"
    with pytest.raises(ConfigError, match="aiding.gnss"):
        load_job_dict(d, JOB)
    d = _job_dict()
    d["outages"]["keep_satellites"] = -1
    with pytest.raises(ConfigError, match="keep_satellites"):
        load_job_dict(d, JOB)
    d = _job_dict()
    d["inputs"]["gnss_raw"]["elevation_mask_deg"] = 95.0
    with pytest.raises(ConfigError, match="elevation_mask_deg"):
        load_job_dict(d, JOB)
    # keep_satellites belongs to tight coupling: a loose job does not read it
    d = _job_dict()
    d["aiding"] = {"gnss": "loose", "zupt": True}
    with pytest.raises(ConfigError, match="keep_satellites"):
        load_job_dict(d, JOB)
    d = _job_dict()
    d["inputs"]["gnss_raw"]["format"] = "rinex"
    with pytest.raises(ConfigError, match="nav_path"):
        from insgnss.job.inputs import read_gnss_raw

        read_gnss_raw(load_job_dict(d, JOB))


def test_tight_without_raw_observations_is_an_error(tmp_path):
    from insgnss.job.aiding import build_aiding
    from insgnss.job.inputs import Inputs

    d = _job_dict()
    job = load_job_dict(d, JOB)
    imu = __import__("pandas").DataFrame({"gyro_x": [0.0, 0.0]}, index=[0.0, 1.0])
    with pytest.raises(ConfigError, match="gnss_raw"):
        build_aiding(job, Inputs(imu=imu), [], imu)


@pytest.fixture(scope="module")
def walk_run():
    shared_data("gnss-imu-rtklibexplorer", "walk_0827")
    from insgnss.job.run import run_job

    return run_job(load_job_dict(_job_dict(), JOB), progress=False)


def test_walk_tight_job_uses_each_satellite(walk_run):
    res = walk_run
    assert res.filter.complete and res.failure is None
    fw = res.filter.forward
    for c in ("clock_bias", "clock_drift", "clock_bias_std", "isb_E", "isb_C"):
        assert c in fw.columns
    # the receiver clock (~ -4.6e5 m, drifting tens of m/s) is tracked to metres
    assert np.nanmedian(fw["clock_bias_std"].to_numpy()[fw.index > fw.index[0] + 20]) < 5.0
    inn = res.filter.innovations
    pr = inn[inn["type"] == "pseudorange"]
    assert (pr["label"] != "").all() and pr["accepted"].mean() > 0.95
    t = pr["time"].to_numpy()
    per_epoch = pr.groupby("time").size()
    for a, b in res.windows:
        inside = per_epoch[(per_epoch.index >= a) & (per_epoch.index < b)]
        assert len(inside) > 50 and inside.max() == 3
    outside = per_epoch[~np.any([(per_epoch.index >= a) & (per_epoch.index < b)
                                 for a, b in res.windows], axis=0)]
    assert outside.median() > 12
    assert t.min() > res.filter.forward.index[0]
    counts = res.summary["measurements"]
    assert counts["pseudorange"]["offered"] == len(pr) and counts["doppler"]["applied"] > 0


def test_walk_tight_drift_with_three_satellites_below_two_metres(walk_run):
    """End-of-outage horizontal error relative to the run's own mean non-outage error (the
    reference's datum is ~(6, 5) m from the broadcast orbits' frame): below 2 m in both
    windows (issue 19; bench/bench_tight.py prints it with the shared scorer)."""
    res = walk_run
    ref = res.inputs.reference
    ref = ref[ref["q"] == 1]
    fw = res.filter.forward
    tr = ref.index.to_numpy(float)
    tf = fw.index.to_numpy(float)
    tr = tr[(tr >= tf[0] + 10.0) & (tr <= tf[-1])]
    lat0, lon0 = float(ref["lat"].iloc[0]), float(ref["lon"].iloc[0])
    lat, lon = np.interp(tr, tf, fw["lat"].to_numpy()), np.interp(tr, tf, fw["lon"].to_numpy())
    e, n, _ = geodetic_to_enu(lat, lon, 0.0 * tr, lat0, lon0, 0.0)
    r = ref.loc[tr]
    e2, n2, _ = geodetic_to_enu(r["lat"].to_numpy(), r["lon"].to_numpy(), 0.0 * tr, lat0, lon0,
                                0.0)
    err = np.column_stack([e - e2, n - n2])
    out = np.zeros(tr.size, bool)
    for a, b in res.windows:
        out |= (tr >= a) & (tr < b + 1.0)
    bias = err[~out].mean(axis=0)
    assert 4.0 < np.hypot(*bias) < 12.0  # the datum offset, as SPP shows it
    ends = [np.flatnonzero((tr >= a) & (tr < b))[-1] for a, b in res.windows]
    drift = np.hypot(*(err[ends] - bias).T)
    rel_non = np.sqrt(np.mean(np.sum((err[~out] - bias) ** 2, axis=1)))
    print("end-of-outage drift", drift.round(2), "non-outage RMS about the offset", round(rel_non, 2))
    assert drift.mean() < 2.0 and rel_non < 1.0


def test_rinex_raw_input_gives_the_spp_gnss_table(tmp_path):
    """``[inputs.gnss_raw] format = "rinex"``: RINEX 3 observation + navigation files are read,
    and their single-point solution is the job's GNSS table (GPS time, positions at the
    simulated receiver to metres, the clock of the simulation)."""
    from gnss_helpers import (
        ALPHA,
        BETA,
        CFG,
        ION,
        T0,
        simulate_observations,
        synthetic_constellation,
        write_rinex_nav,
        write_rinex_obs,
    )

    from insgnss.earth import ecef_to_geodetic, geodetic_to_ecef
    from insgnss.job.inputs import read_gnss_raw

    eph = synthetic_constellation(T0)
    r0 = np.array(geodetic_to_ecef(np.radians(40.1), np.radians(-105.15), 1600.0))
    times = T0 + 10.0 + np.arange(5.0)
    obs, truth = simulate_observations(eph, times, lambda t: r0, lambda t: -4.6e5 - 70.0 * (t - T0),
                                       iono=(ALPHA, BETA))
    write_rinex_obs(obs, tmp_path / "rx.obs", {"G": ("1C",), "E": ("1C",)})
    write_rinex_nav(eph, ION, tmp_path / "rx.nav")
    d = _job_dict()
    d["inputs"]["gnss_raw"] = {"format": "rinex", "path": str(tmp_path / "rx.obs"),
                               "nav_path": str(tmp_path / "rx.nav"),
                               "cn0_mask": CFG.cn0_mask}
    raw, sol = read_gnss_raw(load_job_dict(d, JOB))
    assert len(raw.observations) == len(obs) and len(sol) == times.size
    assert sol.attrs["time_base"] == "gps"
    np.testing.assert_allclose(sol.index.to_numpy(float), times, atol=1e-6)
    lat, lon, h = ecef_to_geodetic(*r0)
    assert np.all(np.abs(sol["lat"] - lat) * 6.4e6 < 1.0)
    assert np.all(np.abs(sol["height"] - h) < 2.0)
    np.testing.assert_allclose(sol["clock_bias_G"], [s["b"] for s in truth], atol=2.0)
