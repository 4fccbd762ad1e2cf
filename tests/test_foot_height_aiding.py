"""Height aiding of the foot-mounted INS (run_foot_ins): level floor between stances, barometer
height from a column of the IMU table, and the per-stride height noise at stance release, on
simulated walks whose vertical accelerometer reads high (a climb the ZUPT cannot see)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from insgnss.earth import geodetic_to_enu, pressure_altitude
from insgnss.filter import run_filter
from insgnss.filter.engine import FilterConfig
from insgnss.filter.measurements import Zupt
from insgnss.foot import FootConfig, run_foot_ins
from insgnss.imu import ImuErrorModel, increments, increments_table, rates_table
from insgnss.mechanization.strapdown import NavState
from insgnss.simulate.gait import simulate_walk

LEVEL = [{"type": "stand", "duration": 1.0}, {"type": "walk", "steps": 20},
         {"type": "stand", "duration": 1.0}]
STAIRS = [{"type": "stand", "duration": 1.0}, {"type": "walk", "steps": 6},
          {"type": "walk", "steps": 8, "rise": 0.34, "stride_length": 0.6},
          {"type": "walk", "steps": 6}, {"type": "stand", "duration": 1.0}]


def _walk(segs, scale):
    w = simulate_walk(segs, rate=100.0, oversample=1, lat=np.radians(45.0))
    tr = w.truth
    t, dth, dv = increments(w.ideal)
    imu = increments_table(t, dth, dv @ np.diag([1.0, 1.0, scale]).T)
    up = geodetic_to_enu(tr.lat.values, tr.lon.values, tr.height.values, tr.lat.iloc[0],
                         tr.lon.iloc[0], tr.height.iloc[0])[2]
    return imu, tr, up


def _end_height_error(imu, tr, up, **kw):
    """End height error of the forward solution with truth stances [m], and the result."""
    still = tr.stationary.to_numpy() > 0.5
    r = run_foot_ins(imu, FootConfig(**kw), still=still, lat=tr.lat.iloc[0],
                     lon=tr.lon.iloc[0], height=tr.height.iloc[0])
    return float(r.forward.up.iloc[-1] - up[-1]), r


@pytest.fixture(scope="module")
def level_walk():
    return _walk(LEVEL, 1.01)


def test_level_floor_removes_the_climb_and_keeps_the_stairs(level_walk):
    free, r0 = _end_height_error(*level_walk)
    assert free > 0.1 and r0.height_aiding == {}  # 1 % vertical scale: +0.13 m after 28 m
    dh, r = _end_height_error(*level_walk, level_floor=True)
    assert abs(dh) < 0.05 * free
    assert r.height_aiding["level_floor"] == {"applied": 20, "skipped": 0}
    # per-stride noise at the 20 releases (21 still runs): 1 % of the 1.4 m strides
    assert r.height_aiding["stride_height_noise"]["releases"] == 20
    assert r.height_aiding["stride_height_noise"]["up_std_median_m"] == pytest.approx(
        0.014, rel=0.05)
    imu, tr, up = _walk(STAIRS, 1.01)
    dh, r = _end_height_error(imu, tr, up, level_floor=True)
    assert up[-1] == pytest.approx(8 * 0.34, abs=0.01)
    assert r.height_aiding["level_floor"]["skipped"] == 8  # the flight is not flattened
    assert abs(dh) < 0.03


def test_barometer_column_and_the_stride_height_noise(level_walk):
    imu, tr, up = level_walk
    free, _ = _end_height_error(imu, tr, up)
    rng = np.random.default_rng(3)
    h = tr.height.to_numpy() + 40.0 + rng.normal(0.0, 0.2, len(tr))
    with_baro = imu.assign(baro_height=h)
    dh, r = _end_height_error(with_baro, tr, up)
    assert r.height_aiding["baro"] == {"column": "baro_height", "readings": 49}
    # without the per-stride noise the ZUPT-only height variance (mm) makes the offset state
    # absorb the barometer; with 1 % of the stride the height follows it
    tight, _ = _end_height_error(with_baro, tr, up, stride_height_noise=0.0)
    assert abs(dh) < 0.5 * free and abs(dh) < 0.75 * abs(tight)
    # the same readings as static pressure (ISA), and barometer off
    p = 101325.0 * (1.0 - 0.0065 * h / 288.15) ** (1.0 / 0.190263)
    np.testing.assert_allclose(pressure_altitude(p), h, atol=1e-6)
    dp, rp = _end_height_error(imu.assign(pressure=p), tr, up)
    assert rp.height_aiding["baro"]["column"] == "pressure" and dp == pytest.approx(dh, abs=5e-3)
    off, ro = _end_height_error(with_baro, tr, up, baro=False)
    assert ro.height_aiding == {} and off == pytest.approx(free, abs=1e-9)


def test_engine_extra_noise_on_the_up_position_only():
    """``FilterConfig.extra_noise`` ``up_std``: the up variance grows by its square at the
    epoch of the row, east and north do not."""
    t = np.arange(0.0, 10.0001, 0.01)
    imu = rates_table(t, np.zeros((t.size, 3)), np.tile([0.0, 0.0, 9.80665], (t.size, 1)))
    init = NavState(np.radians(45.0), 0.0, 0.0, np.zeros(3), np.eye(3), 0.0)
    zupt = Zupt(np.arange(1.0, 10.0001, 1.0), std=0.01)

    def stds(noise):
        cfg = FilterConfig(imu_model=ImuErrorModel(gyro_arw=1e-4, accel_vrw=1e-3),
                           propagation_interval=0.01, epoch_interval=0.5, gate_probability=0,
                           smoother=False, initial_pos_std=1e-3, nis_window=None,
                           extra_noise=noise)
        f = run_filter(imu, init, [zupt], cfg).forward
        return f[["east_std", "north_std", "up_std"]]

    base = stds(None)
    more = stds(pd.DataFrame({"up_std": [0.3]}, index=pd.Index([5.0], name="time")))
    before, after = base.index < 5.0 - 1e-9, base.index >= 5.0
    np.testing.assert_allclose(more[before].to_numpy(), base[before].to_numpy())
    np.testing.assert_allclose(more.loc[after, ["east_std", "north_std"]].to_numpy(),
                               base.loc[after, ["east_std", "north_std"]].to_numpy(), rtol=1e-9)
    np.testing.assert_allclose(more.loc[after, "up_std"] ** 2,
                               base.loc[after, "up_std"] ** 2 + 0.09, rtol=1e-6)
