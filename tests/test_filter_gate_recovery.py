"""Gate recovery: a filter whose covariance is wrong (it rejects every GNSS epoch) recovers,
while sparse measurements separated by long gaps are not force-applied."""

import dataclasses

import numpy as np
import pytest

from insgnss.filter import FilterConfig, run_filter
from insgnss.filter.measurements import GnssPosition
from insgnss.mechanization.strapdown import NavState
from insgnss.simulate.scenario import simulate_scenario

SCENARIO = {
    "scenario": {"name": "recovery", "seed": 11, "imu_rate": 50.0},
    "trajectory": {"vehicle": "land", "lat": 45.0, "lon": 7.0, "height": 200.0, "heading": 0.0,
                   "segments": [{"type": "accelerate", "speed": 15.0, "acceleration": 1.5},
                                {"type": "hold", "duration": 40.0},
                                {"type": "turn", "angle": 90.0, "rate": 10.0},
                                {"type": "hold", "duration": 60.0}]},
    "imu": {"grade": "tactical"},
    "gnss": {"rate": 1.0, "horizontal_std": 1.0, "vertical_std": 2.0},
}


@pytest.fixture(scope="module")
def sim():
    return simulate_scenario(SCENARIO)


def _run(sim, recovery):
    r = sim.truth.iloc[0]
    # heading 25 deg wrong but claimed good to 0.5 deg: the GNSS epochs soon fail the gate
    x0 = NavState.from_euler(r.lat, r.lon, r.height, (r.vel_e, r.vel_n, r.vel_u), r.roll,
                             r.pitch, r.heading + np.radians(25.0))
    cfg = FilterConfig(imu_model="tactical", smoother=False, gate_recovery=recovery,
                       initial_att_std=(np.radians(0.2), np.radians(0.2), np.radians(0.5)))
    res = run_filter(sim.imu, x0, [GnssPosition(sim.gnss)], cfg)
    tr = sim.truth.reindex(res.forward.index, method="nearest")
    from insgnss.earth import radii

    M, N = radii(tr["lat"].to_numpy())
    dn = (res.forward["lat"] - tr["lat"]).to_numpy() * M
    de = (res.forward["lon"] - tr["lon"]).to_numpy() * N * np.cos(tr["lat"].to_numpy())
    return res, np.hypot(de, dn)


def test_lost_filter_recovers(sim):
    res, err = _run(sim, 5.0)
    assert res.innovations["recovered"].any()
    assert err[-1] < 5.0  # back on the GNSS track
    res_off, err_off = _run(sim, None)
    assert not res_off.innovations["recovered"].any()
    assert err_off[-1] > 10 * err[-1]  # without recovery the filter never comes back


def test_sparse_rejections_do_not_trigger_recovery(sim):
    """Three isolated bad epochs 20 s apart: each is rejected, none is force-applied."""
    g = sim.gnss.copy()
    bad = g.index[[30, 50, 70]]
    g.loc[bad, "lat"] += 60.0 / 6.37e6
    r = sim.truth.iloc[0]
    x0 = NavState.from_euler(r.lat, r.lon, r.height, (r.vel_e, r.vel_n, r.vel_u), r.roll,
                             r.pitch, r.heading)
    cfg = dataclasses.replace(FilterConfig(imu_model="tactical", smoother=False),
                              gate_recovery=5.0)
    res = run_filter(sim.imu, x0, [GnssPosition(g)], cfg)
    rej = res.rejected["time"].to_numpy()
    assert set(np.round(bad.to_numpy(), 6)) <= set(np.round(rej, 6))
    assert not res.innovations["recovered"].any()
