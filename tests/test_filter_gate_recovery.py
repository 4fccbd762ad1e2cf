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


def _lost(sim, **cfg):
    r = sim.truth.iloc[0]
    x0 = NavState.from_euler(r.lat, r.lon, r.height, (r.vel_e, r.vel_n, r.vel_u), r.roll,
                             r.pitch, r.heading + np.radians(25.0))
    c = FilterConfig(imu_model="tactical", smoother=False,
                     initial_att_std=(np.radians(0.2), np.radians(0.2), np.radians(0.5)), **cfg)
    return run_filter(sim.imu, x0, [GnssPosition(sim.gnss)], c)


def test_runaway_nis_counts_only_after_a_recovery(sim):
    """The 25 deg heading error drives the GNSS NIS far above the runaway bound before the
    recovery; the run that recovered is not stopped (issue 22), the one without recovery is."""
    kw = {"nis_window": 10.0, "nis_min_count": 5}
    res = _lost(sim, gate_recovery=5.0, **kw)
    inn = res.innovations
    t_rec = inn.loc[inn.recovered, "time"].min()
    before = inn[inn.time < t_rec]
    assert np.median(before.nis.to_numpy()[-5:] / 3.0) > 25.0  # would have tripped the check
    assert res.complete, res.error
    off = _lost(sim, gate_recovery=None, **kw)
    assert not off.complete and "runaway NIS" in str(off.error)


def test_runaway_restart_empties_the_windows():
    from insgnss.errors import FilterHealthError
    from insgnss.filter.health import RunawayNis

    rw = RunawayNis(2, window=10.0, bound=25.0, min_count=3)
    for k in range(2):
        rw.push(0, "gnss_pos", float(k), 100.0)
    rw.restart()
    rw.push(0, "gnss_pos", 2.0, 100.0)  # 3 values in the window, but only 1 after the restart
    rw.push(0, "gnss_pos", 3.0, 100.0)
    with pytest.raises(FilterHealthError, match="runaway NIS"):
        rw.push(0, "gnss_pos", 4.0, 100.0)  # stays high after the restart: stopped
    from insgnss import aot
    from insgnss.filter import health

    if aot.status().startswith("used"):  # a gate recovery in a run needs no numba either
        assert health.runaway_restart.exports


def test_runaway_count_is_of_epochs_not_rows():
    """Ten per-satellite rows at one epoch count as one epoch: the check waits for
    ``min_count`` distinct times of the type, however many rows each holds."""
    from insgnss.errors import FilterHealthError
    from insgnss.filter.health import RunawayNis

    rw = RunawayNis(1, window=30.0, bound=25.0, min_count=3, capacity=64)
    for k in range(2):  # 2 epochs x 10 satellites: 20 rows, all 10 sigma off
        for _ in range(10):
            rw.push(0, "pseudorange", 1.5 * k, 100.0)
    assert int(rw.state[0, 1]) == 20  # 20 values held, the check has not applied
    with pytest.raises(FilterHealthError, match="at 3 epochs"):
        for _ in range(10):
            rw.push(0, "pseudorange", 3.0, 100.0)  # the third epoch: stopped
    # before the change the first epoch's tenth row (10 >= min_count rows) stopped it
    rw = RunawayNis(1, window=30.0, bound=25.0, min_count=10, capacity=64)
    for _ in range(12):
        rw.push(0, "pseudorange", 0.0, 100.0)


def test_violated_constraint_is_never_forced_in(sim):
    """A lateral-velocity constraint violated by 0.8 m/s from the turn on (a skidding car, an
    IMU far from the rear axle): rejected for longer than the recovery time, never
    force-applied; the same measurement declared recoverable is."""
    from insgnss.filter.measurements import BodyVelocity

    t = sim.imu.index.to_numpy(float)
    tn = t[::25][1:]
    w = sim.truth["heading"].reindex(tn, method="nearest").diff().abs().to_numpy()
    turning = np.cumsum(np.nan_to_num(w) > np.radians(1.0)) > 0  # 10 deg/s over 0.5 s
    lateral = np.where(turning, 0.8, 0.0)
    r = sim.truth.iloc[0]
    x0 = NavState.from_euler(r.lat, r.lon, r.height, (r.vel_e, r.vel_n, r.vel_u), r.roll,
                             r.pitch, r.heading)
    cfg = FilterConfig(imu_model="tactical", smoother=False, gate_recovery=2.0)
    out = {}
    for rec in (False, True):
        cls = type("Nhc", (BodyVelocity,), {"recoverable": rec})
        nhc = cls(tn, lateral, axes=(0,), std=0.05, name="nhc")
        res = run_filter(sim.imu, x0, [GnssPosition(sim.gnss), nhc], cfg)
        inn = res.innovations[res.innovations.type == "nhc"]
        assert res.complete  # the rejected constraint does not stop the run (health.py)
        out[rec] = (int((~inn.accepted & np.isin(inn.time, tn[turning])).sum()),
                    int(inn.recovered.sum()))
    assert out[False][0] > 100 and out[False][1] == 0  # rejected throughout, never forced in
    assert out[True][0] >= 3 and out[True][1] >= 1
