"""Per-recording stance-threshold selection (insgnss.detect.select_threshold) with the foot INS
as its forward filter, on a simulated walk followed by a run (two gaits whose stance valleys
differ by two decades of the SHOE statistic)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from insgnss.detect import (
    DetectorConfig,
    Stillness,
    decide,
    imu_rates,
    select_threshold,
    statistic_arrays,
    threshold_candidates,
)
from insgnss.earth import geodetic_to_enu
from insgnss.foot import FootConfig, run_foot_ins
from insgnss.imu import ImuErrorModel
from insgnss.simulate.gait import simulate_walk
from insgnss.simulate.sensors import simulate_imu

RUN = {"stride_time": 0.75, "stride_length": 2.2, "foot_flat": 0.12, "heel_off": 0.22,
       "toe_off": 0.4, "toe_off_rate": np.radians(-500.0)}


@pytest.fixture(scope="module")
def walk_and_run():
    w = simulate_walk([{"type": "stand", "duration": 2.0},
                       {"type": "walk", "steps": 12, "stance_roll": np.radians(1.0)},
                       {"type": "walk", "steps": 12, "stance_roll": np.radians(1.0), **RUN},
                       {"type": "stand", "duration": 2.0}], rate=200.0, oversample=10)
    # VN-100-class white noise (the PyShoe sensor)
    imu = simulate_imu(w.ideal, ImuErrorModel(gyro_arw=6.1e-5, accel_vrw=1.4e-3), 3).imu
    return w, imu


def test_selection_picks_a_consistent_threshold(walk_and_run):
    w, imu = walk_and_run
    tr = w.truth
    site = (tr.lat.iloc[0], tr.lon.iloc[0], tr.height.iloc[0])
    e, n, _ = geodetic_to_enu(tr.lat.values, tr.lon.values, tr.height.values, *site)
    cfg = FootConfig()
    det = DetectorConfig(**{**cfg.detector.to_dict(), "method": "valley"})
    t, gyro, acc = imu_rates(imu)
    stat, _ = statistic_arrays(t, gyro, acc, det)
    idx = pd.Index(t)
    fwd_cfg = FootConfig(**{**cfg.to_dict(), "smooth": False})

    def forward(still):
        st = Stillness(pd.Series(still, idx), pd.Series(stat, idx), pd.Series(stat, idx), "x")
        return run_foot_ins(imu, fwd_cfg, still=st, lat=site[0], lon=site[1], height=site[2])

    sel = select_threshold(t, stat, det, lambda s: forward(s).innovations[
        ["zupt_e", "zupt_n", "zupt_u"]].to_numpy())
    # forward (causal) horizontal RMS error of every candidate against the truth
    rms = []
    for _, _, thr in threshold_candidates(t, stat, det):
        f = forward(decide(t, stat, thr, det)).forward
        rms.append(float(np.sqrt(np.mean((f.east - e) ** 2 + (f.north - n) ** 2))))
    rms = np.array(rms)
    tab = sel.table.assign(rms=rms)
    chosen = tab[(tab.family == sel.family) & (tab.log10 == sel.log10)].iloc[0]
    assert chosen.criterion == tab.criterion.min() == sel.criterion
    # the choice is within 30 % of the best candidate the truth would pick
    assert chosen.rms <= 1.3 * rms.min()
    # low fixed thresholds miss every running stance: 1-2 m of forward error, and the criterion
    # sees it (the first stance after the run enters at 2.4 m/s)
    low = tab[(tab.family == "fixed") & (tab.log10 == 5.5)].iloc[0]
    assert low.rms > 10 * chosen.rms and low.criterion > 5 * chosen.criterion
    # very high ones make stances of mid-swing: rejected as well
    high = tab[(tab.family == "fixed") & (tab.log10 == 9.0)].iloc[0]
    assert high.rms > 5 * chosen.rms and high.criterion > 5 * chosen.criterion
    assert sel.still.dtype == bool and sel.still.shape == t.shape


def test_run_foot_ins_selects_by_default(walk_and_run):
    w, imu = walk_and_run
    tr = w.truth
    site = dict(lat=tr.lat.iloc[0], lon=tr.lon.iloc[0], height=tr.height.iloc[0])
    r = run_foot_ins(imu, FootConfig(), **site)
    assert r.selection is not None and r.stillness.method == "select"
    assert len(r.selection.table) == 29  # 17 fixed + 12 valley candidates
    np.testing.assert_array_equal(r.stillness.still.to_numpy(), r.selection.still)
    # the same choice as select_threshold with the foot INS's forward pass
    det = FootConfig().detector
    t, gyro, acc = imu_rates(imu)
    stat, _ = statistic_arrays(t, gyro, acc, det)
    idx = pd.Index(t)
    fwd = FootConfig(smooth=False)

    def forward(still):
        st = Stillness(pd.Series(still, idx), pd.Series(stat, idx), pd.Series(stat, idx), "x")
        return run_foot_ins(imu, fwd, still=st, **site).innovations[
            ["zupt_e", "zupt_n", "zupt_u"]].to_numpy()

    sel = select_threshold(t, stat, det, forward)
    assert (sel.family, sel.log10) == (r.selection.family, r.selection.log10)
    assert sel.criterion == pytest.approx(r.selection.criterion, rel=1e-9)
    # without the selection the valley detector decides alone (factor 10)
    r0 = run_foot_ins(imu, FootConfig(threshold_selection="none"), **site)
    assert r0.selection is None and r0.stillness.method == "valley"
