"""Input policies reachable from the job file (issue 8): IMU gaps bridged / stopped / split,
duplicated samples dropped or refused, GNSS outliers rejected by the gate and listed in
rejected.csv. Inputs are files written from a small seeded simulation."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pandas as pd
import pytest
from robustness_helpers import SMALL_JOB_TOML, small_job

from insgnss.config import load_job
from insgnss.earth import enu_displacement_to_geodetic
from insgnss.errors import ConfigError, DataGapError, InsgnssWarning, TimeOrderError
from insgnss.imu import increments, rates_table
from insgnss.io.native import write_table
from insgnss.pipeline import load_inputs, run_job, write_outputs

GAP = (50.0, 52.0)  # samples strictly inside are removed: a 2 s logger gap while driving


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("policies")
    sim = load_inputs(small_job())
    t, dth, dv = increments(sim.imu)
    dt = np.diff(t, prepend=t[0] - 0.01)[:, None]
    imu = rates_table(t, dth / dt, dv / dt)  # a rate logger: bridging integrates trapezoids
    imu.to_csv(d / "imu_full.csv", index_label="time", float_format="%.17g")
    imu[~((t > GAP[0]) & (t < GAP[1]))].to_csv(d / "imu_gap.csv", index_label="time",
                                               float_format="%.17g")
    write_table(sim.gnss, d / "gnss.csv")
    write_table(sim.truth.iloc[::10][["lat", "lon", "height"]], d / "truth.csv")
    return d


def _job(d, imu_file: str, **imu_keys):
    keys = "".join(f"{k} = {json.dumps(v)}\n" for k, v in imu_keys.items())
    text = f"""
[inputs.imu]
format = "csv"
path = "{imu_file}"
rate_hz = 100.0
{keys}
[inputs.gnss]
format = "native"
path = "gnss.csv"

[inputs.reference]
format = "native"
path = "truth.csv"
point = "imu"

[initialization]""" + SMALL_JOB_TOML.split("[initialization]")[1]
    name = f"job_{imu_file}_{abs(hash(keys))}.toml"
    (d / name).write_text(text)
    return load_job(d / name)


def _run(job):
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        res = run_job(job, progress=False)
    return res, [str(r.message) for r in rec if issubclass(r.category, InsgnssWarning)]


def test_long_gap_stops_by_default_naming_file_and_row(files):
    with pytest.raises(DataGapError) as e:
        run_job(_job(files, "imu_gap.csv"), progress=False)
    err = e.value
    assert err.file.endswith("imu_gap.csv") and err.column == "time"
    # header = line 1, sample i = line i + 2; the first sample after the gap is t = 52.0
    assert err.row == 5003
    assert "2 s" in str(err) and "gap_policy.max_bridge" in str(err)


def test_gap_bridged_with_a_warning_and_recorded(files, tmp_path):
    res, warned = _run(_job(files, "imu_gap.csv", gap_policy="bridge"))
    assert any("1 gap(s) bridged" in w and "row 5003" in w for w in warned)
    gaps = res.summary["imu"]["gaps"]
    assert len(gaps) == 1 and gaps[0]["action"] == "bridged" and gaps[0]["row"] == 5003
    assert gaps[0]["duration"] == pytest.approx(2.0) and gaps[0]["missing"] == 199
    assert res.summary["imu"]["bridged_s"] == pytest.approx(2.0)
    write_outputs(res, tmp_path)
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["imu"]["gaps"][0]["start"] == pytest.approx(50.0)
    # a longer max_gap bridges it under the default "error" policy too
    res2, warned2 = _run(_job(files, "imu_gap.csv", max_gap=3.0))
    assert res2.summary["complete"] and res2.summary["imu"]["gaps"][0]["action"] == "bridged"
    assert any("bridged" in w for w in warned2)


def test_split_processes_the_segments_separately(files, tmp_path):
    res, warned = _run(_job(files, "imu_gap.csv", gap_policy="split"))
    assert any("split into 2 segments" in w for w in warned)
    assert res.summary["complete"]
    segs = res.summary["segments"]
    assert [s["initialization"] for s in segs] == ["static", "gnss_velocity"]
    assert segs[0]["end"] == pytest.approx(GAP[0]) and segs[1]["start"] == pytest.approx(GAP[1])
    for name in ("forward", "smoothed"):
        df = getattr(res.filter, name)
        t = df.index.to_numpy()
        assert not ((t > GAP[0]) & (t < GAP[1])).any()  # nothing invented inside the gap
        assert set(df["segment"]) == {0, 1}
        assert np.all(np.diff(t) > 0)
    # the second segment restarts from GNSS instead of dead-reckoning 2 s of unknown motion
    assert res.summary["evaluation"]["smoothed"]["rms_h_m"] < 0.35
    paths = write_outputs(res, tmp_path)
    assert "segment" in pd.read_csv(paths["forward.csv"]).columns
    assert len(json.loads((tmp_path / "summary.json").read_text())["segments"]) == 2


def test_gap_noise_keeps_a_bridged_gap_honest(files):
    """Bridging 2 s of driving: without the gap's process noise the filter is overconfident
    afterwards and its smoothed error more than doubles."""
    on, _ = _run(_job(files, "imu_gap.csv", gap_policy="bridge"))
    off, _ = _run(_job(files, "imu_gap.csv", gap_policy="bridge", gap_noise=False))
    rms_on = on.summary["evaluation"]["smoothed"]["rms_h_m"]
    rms_off = off.summary["evaluation"]["smoothed"]["rms_h_m"]
    assert rms_on < 0.35 and rms_off > 2.0 * rms_on


def test_duplicated_samples_dropped_or_refused(files):
    lines = (files / "imu_full.csv").read_text().splitlines()
    dup_lines = [1002, 3003, 7004]  # 1-based lines repeated right after themselves
    out = []
    for i, s in enumerate(lines, 1):
        out.append(s)
        if i in dup_lines:
            out.append(s)
    (files / "imu_dup.csv").write_text("\n".join(out) + "\n")
    res, warned = _run(_job(files, "imu_dup.csv"))
    assert any("3 sample(s) with a duplicated time stamp dropped" in w for w in warned)
    rows = [d["row"] for d in res.summary["imu"]["dropped_duplicates"]]
    assert rows == [1003, 3005, 7007]  # the copies, as an editor numbers the file's lines
    assert res.summary["complete"] and res.summary["imu_samples"] > 9000
    with pytest.raises(TimeOrderError) as e:
        run_job(_job(files, "imu_dup.csv", duplicates="error"), progress=False)
    assert e.value.row == 1003 and e.value.file.endswith("imu_dup.csv")


def test_in_memory_tables_get_the_same_policies():
    """Data built or modified in memory (no reader involved) is checked by the pipeline."""
    job = small_job()
    inputs = load_inputs(job)
    imu = inputs.imu
    inputs.imu = pd.concat([imu.iloc[:2000], imu.iloc[1999:2000], imu.iloc[2000:]])
    with pytest.warns(InsgnssWarning, match="duplicated time stamp"):
        res = run_job(job, inputs=inputs, progress=False)
    d = res.summary["imu"]["dropped_duplicates"]
    assert len(d) == 1 and d[0]["row"] == 2001 and res.summary["complete"]
    inputs = load_inputs(job)
    t = inputs.imu.index.to_numpy()
    inputs.imu = inputs.imu[(t < 40.0) | (t > 41.5)]
    with pytest.raises(DataGapError, match="sample numbers"):
        run_job(job, inputs=inputs, progress=False)


def test_gnss_outliers_are_rejected_and_listed(tmp_path):
    job = small_job()
    inputs = load_inputs(job)
    g = inputs.gnss.copy()
    rng = np.random.default_rng(3)
    k = np.sort(rng.choice(np.arange(25, len(g) - 2), size=6, replace=False))
    mag, az = rng.uniform(30.0, 100.0, k.size), rng.uniform(0.0, 2 * np.pi, k.size)
    lat, lon, h = (g[c].to_numpy().copy() for c in ("lat", "lon", "height"))
    dlat, dlon, _ = enu_displacement_to_geodetic(lat[k], h[k], mag * np.sin(az),
                                                 mag * np.cos(az), 0.0 * mag)
    lat[k] += dlat
    lon[k] += dlon
    g["lat"], g["lon"] = lat, lon
    inputs.gnss = g
    res = run_job(job, inputs=inputs, progress=False)
    write_outputs(res, tmp_path)
    rej = pd.read_csv(tmp_path / "rejected.csv")
    t_rej = rej.loc[rej["type"] == "gnss_pos", "time"].to_numpy()
    t_jump = g.index.to_numpy()[k]
    assert all(np.abs(t_rej - tj).min() < 1e-6 for tj in t_jump)
    assert len(t_rej) == k.size  # and nothing else
    c = res.summary["measurements"]["gnss_pos"]
    assert c["rejected"] == k.size and c["applied"] == c["offered"] - k.size
    assert (rej["nis"] > rej["threshold"]).all()


def test_policy_keys_are_validated(files):
    with pytest.raises(ConfigError) as e:
        _job(files, "imu_gap.csv", gap_policy="skip")
    assert e.value.column == "inputs.imu.gap_policy"
    with pytest.raises(ConfigError) as e:
        _job(files, "imu_gap.csv", duplicates="keep")
    assert e.value.column == "inputs.imu.duplicates"


def test_gap_noise_of_a_rate_step_across_a_gap():
    from insgnss.policies import gap_noise

    t = np.round(np.arange(0.0, 20.0, 0.01), 10)
    w = np.zeros((t.size, 3))
    w[t >= 10.0, 2] = 0.2  # the vehicle starts turning while the logger is away
    f = np.tile([0.0, 0.0, 9.81], (t.size, 1))
    keep = ~((t > 9.75) & (t < 10.25))
    imu = rates_table(t[keep], w[keep], f[keep])
    gaps = [{"start": 9.75, "end": 10.25, "duration": 0.5, "action": "bridged"}]
    xn = gap_noise(imu, gaps)
    assert list(xn.index) == [10.25]
    assert xn["att_std"].iloc[0] == pytest.approx(0.5 * 0.2 / 2, rel=1e-9)
    assert xn["vel_std"].iloc[0] < 1e-9 and xn["pos_std"].iloc[0] < 1e-9
    assert gap_noise(imu, [dict(gaps[0], action="split")]) is None
    tt, dth, dv = increments(imu)
    from insgnss.imu import increments_table

    assert gap_noise(increments_table(tt, dth, dv), gaps) is None


def test_extra_noise_enters_the_predicted_covariance():
    from insgnss.filter.engine import run_filter
    from insgnss.pipeline import build_measurements, filter_config, initialize

    job = small_job()
    inputs = load_inputs(job)
    init = initialize(job, inputs, inputs.imu_model)
    imu = inputs.imu.loc[init.state.time:]
    meas = build_measurements(job, inputs, [], imu)
    cfg = filter_config(job, inputs.imu_model, init)
    cfg.smoother = False
    r0 = run_filter(imu, init.state, meas, cfg)
    cfg.extra_noise = pd.DataFrame({"pos_std": [0.1], "vel_std": [0.2], "att_std": [0.01]},
                                   index=pd.Index([30.05], name="time"))
    r1 = run_filter(imu, init.state, meas, cfg)
    e = int(np.searchsorted(r0.epoch_times, 30.05))
    np.testing.assert_array_equal(r1.P_predicted[:e], r0.P_predicted[:e])
    d = r1.P_predicted[e] - r0.P_predicted[e]
    np.testing.assert_allclose(np.diag(d)[:9], [0.01] * 3 + [0.04] * 3 + [1e-4] * 3, rtol=1e-9)
    d[np.arange(9), np.arange(9)] = 0.0
    assert np.abs(d).max() < 1e-12
