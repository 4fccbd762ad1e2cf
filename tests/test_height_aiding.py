"""Height aiding measurement models (insgnss.filter.height_aiding): level floor between
stances and barometric height, unit checks of (z, H, R) and the engine on simulated walks
(insgnss.simulate.gait) with a vertical accelerometer scale error that makes the INS climb."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from insgnss.attitude import euler_to_dcm
from insgnss.earth import geodetic_to_enu, pressure_altitude
from insgnss.errors import InputFormatError, InvalidValueError
from insgnss.filter import run_filter
from insgnss.filter.engine import FilterConfig
from insgnss.filter.height_aiding import BaroHeight, LevelFloor
from insgnss.filter.measurements import NominalState, Zupt
from insgnss.imu import ImuErrorModel, increments, increments_table
from insgnss.io import read_imu_csv
from insgnss.mechanization.strapdown import NavState
from insgnss.simulate.gait import simulate_walk
from insgnss.strides import still_runs

LEVEL = [{"type": "stand", "duration": 1.0}, {"type": "walk", "steps": 20},
         {"type": "stand", "duration": 1.0}]
STAIRS = [{"type": "stand", "duration": 1.0}, {"type": "walk", "steps": 6},
          {"type": "walk", "steps": 8, "rise": 0.34, "stride_length": 0.6},
          {"type": "walk", "steps": 6}, {"type": "stand", "duration": 1.0}]


class _Layout:
    def __init__(self, n, blocks=None):
        self.n = n
        self._b = blocks or {}

    def __getitem__(self, k):
        return self._b[k]


class _Nav:
    """The attributes of a NominalState the height models read."""

    enu_offset = NominalState.enu_offset

    def __init__(self, height, n=16, params=None, blocks=None, north=0.0):
        self.height = height
        self.layout = _Layout(n, blocks)
        self.params = np.zeros(n - 9) if params is None else params
        self.lat, self.lon = 0.7 + north / 6.4e6, 0.1
        self.M = self.N = 6.4e6 - height  # (M + h) = 6.4e6 m: north metres as given

    def param(self, name):
        s = self.layout[name]
        return self.params[s.start - 9:s.stop - 9]


def test_level_floor_compares_each_stance_with_the_previous_one():
    m = LevelFloor([(0.0, 1.0), (2.0, 3.0), (4.0, 5.0)], std=0.003, max_step=0.05)
    np.testing.assert_array_equal(m.times, [1.0, 2.0, 3.0, 4.0, 5.0])
    assert m.evaluate(0, _Nav(10.0)) is None          # end of stance 0: reference recorded
    z, H, R = m.evaluate(1, _Nav(10.012))             # start of stance 1
    assert z[0] == pytest.approx(0.012) and H[0, 2] == 1.0 and H.sum() == 1.0
    assert R[0, 0] == pytest.approx(0.003**2)
    assert m.evaluate(2, _Nav(10.2)) is None          # end of stance 1 -> reference 10.2
    assert m.evaluate(3, _Nav(10.37)) is None         # a stair step (> max_step): skipped
    assert (m.applied, m.skipped) == (1, 1)
    with pytest.raises(InvalidValueError):
        LevelFloor([(0.0, 1.0), (0.5, 2.0)])


def test_level_floor_tells_a_stair_from_the_error_of_a_long_stride():
    """A change above max_step is a stair only when it is also steeper than max_slope: 0.12 m
    over a 1.6 m running stride (0.075) is constrained, 0.17 m over a 0.3 m tread is not."""
    m = LevelFloor([(0.0, 1.0), (2.0, 3.0), (4.0, 5.0)], std=0.003, max_step=0.05,
                   max_slope=0.2)
    m.evaluate(0, _Nav(10.0))
    z, _, _ = m.evaluate(1, _Nav(9.88, north=1.6))
    assert z[0] == pytest.approx(-0.12)
    m.evaluate(2, _Nav(9.88, north=1.6))
    assert m.evaluate(3, _Nav(10.05, north=1.9)) is None
    assert (m.applied, m.skipped) == (1, 1)
    only_step = LevelFloor([(0.0, 1.0), (2.0, 3.0)], max_step=0.05, max_slope=np.inf)
    only_step.evaluate(0, _Nav(10.0))
    assert only_step.evaluate(1, _Nav(10.02, north=1e3)) is not None
    lax = LevelFloor([(0.0, 1.0), (2.0, 3.0)], max_step=0.05, max_slope=0.0)
    lax.evaluate(0, _Nav(10.0))
    assert lax.evaluate(1, _Nav(9.88, north=1.6)) is None  # max_slope 0: max_step alone
    with pytest.raises(InvalidValueError):
        LevelFloor([(0.0, 1.0)], max_slope=-0.1)


def test_baro_height_and_offset_state():
    t = np.arange(0.0, 10.0, 0.1)
    p = 101325.0 * (1 - 0.0065 * 50.0 / 288.15) ** (1 / 0.190263) * np.ones(t.size)
    assert pressure_altitude(p[0]) == pytest.approx(50.0, abs=1e-6)
    m = BaroHeight(pd.DataFrame({"pressure": p}, index=t), std=0.3, interval=1.0)
    assert m.times.size == 10 and m.source_column == "pressure"
    (st,) = m.extra_states()
    assert st.name == "baro_offset" and st.size == 1
    nav = _Nav(20.0, n=16, params=np.array([0, 0, 0, 0, 0, 0, 30.0]),
               blocks={"baro_offset": slice(15, 16)})
    z, H, R = m.evaluate(0, nav)
    assert z[0] == pytest.approx(20.0 + 30.0 - 50.0, abs=1e-6)
    assert H[0, 2] == 1.0 and H[0, 15] == 1.0 and R[0, 0] == pytest.approx(0.09)
    with pytest.raises(InvalidValueError, match="pressure"):
        BaroHeight(pd.DataFrame({"pressure": p * 0 + 500.0}, index=t))
    with pytest.raises(InputFormatError, match="barometer"):
        BaroHeight(pd.DataFrame({"temp": p}, index=t))


def _engine(segs, extra, scale=1.01, stride_noise=0.0):
    """Engine ZUPT run on a simulated walk whose vertical accelerometer reads ``scale`` high;
    ``stride_noise`` [m] is position process noise added at every stance (the real per-stride
    height error of a foot INS, which ZUPT alone does not model)."""
    w = simulate_walk(segs, rate=100.0, oversample=1, lat=np.radians(45.0))
    tr = w.truth
    t = tr.index.to_numpy()
    tt, dth, dv = increments(w.ideal)
    imu = increments_table(tt, dth, dv @ np.diag([1.0, 1.0, scale]).T)
    st = tr.stationary.to_numpy() > 0.5
    stances = [(t[a], t[b - 1]) for a, b in still_runs(st)]
    init = NavState(tr.lat.iloc[0], tr.lon.iloc[0], tr.height.iloc[0], np.zeros(3),
                    euler_to_dcm(0.0, tr.pitch.iloc[0], tr.heading.iloc[0]), t[0])
    model = ImuErrorModel(gyro_bias=1e-4, accel_bias=0.01, gyro_bias_instability=1e-6,
                          accel_bias_instability=1e-5, bias_correlation_time=1e5,
                          gyro_arw=3e-3, accel_vrw=0.01)
    noise = None
    if stride_noise > 0:
        noise = pd.DataFrame({"pos_std": stride_noise, "vel_std": 0.0, "att_std": 0.0},
                             index=pd.Index([a for a, _ in stances[1:]], name="time"))
    cfg = FilterConfig(imu_model=model, propagation_interval=0.01, epoch_interval=0.5,
                       gate_probability=0, gate_recovery=None, smoother=False,
                       initial_pos_std=1e-3, initial_vel_std=0.01,
                       initial_att_std=(1e-3, 1e-3, 1e-3), nis_window=None, extra_noise=noise)
    meas = [Zupt(t[st][1:], std=0.01), *extra(tr, stances)]
    res = run_filter(imu, init, meas, cfg)
    u = geodetic_to_enu(res.forward.lat.values, res.forward.lon.values,
                        res.forward.height.values, init.lat, init.lon, init.height)[2]
    tu = geodetic_to_enu(tr.lat.values, tr.lon.values, tr.height.values, init.lat, init.lon,
                         init.height)[2]
    return u[-1] - tu[-1], tu[-1], meas


def test_level_floor_removes_most_of_a_climb_and_keeps_stairs():
    free, _, _ = _engine(LEVEL, lambda tr, s: [])
    assert free > 0.06                                   # the scale error makes it climb
    dh, _, meas = _engine(LEVEL, lambda tr, s: [LevelFloor(s)])
    assert abs(dh) < 0.3 * free and meas[1].applied == 20
    dh, truth_up, meas = _engine(STAIRS, lambda tr, s: [LevelFloor(s)])
    assert truth_up == pytest.approx(8 * 0.34, abs=0.01)
    assert abs(dh) < 0.06 and meas[1].skipped == 8       # the flight is not flattened


def test_barometer_bounds_the_height_on_stairs():
    def baro(tr, s):
        rng = np.random.default_rng(3)
        h = tr.height.to_numpy() + 40.0 + rng.normal(0.0, 0.2, len(tr))
        return [BaroHeight(pd.DataFrame({"baro_height": h}, index=tr.index), std=0.2)]

    free, _, _ = _engine(STAIRS, lambda tr, s: [], scale=1.05)
    assert abs(free) > 0.3
    # with the INS's height variance at its own (ZUPT-only) level the offset state absorbs
    # the barometer; with a per-stride height noise the barometer bounds the height
    tight, _, _ = _engine(STAIRS, baro, scale=1.05)
    dh, _, _ = _engine(STAIRS, baro, scale=1.05, stride_noise=0.03)  # ~ its 2 cm/stride
    assert abs(tight) > 0.8 * abs(free) and abs(dh) < 0.15


def test_reader_copies_a_pressure_column(tmp_path):
    t = np.arange(20) * 0.01
    rows = ["t,gx,gy,gz,ax,ay,az,p"]
    rows += [f"{x},0,0,0,0,0,9.8,{100000.0 + k}" for k, x in enumerate(t)]
    f = tmp_path / "imu.csv"
    f.write_text("\n".join(rows) + "\n")
    cols = {"time": "t", "gyro_x": "gx", "gyro_y": "gy", "gyro_z": "gz", "accel_x": "ax",
            "accel_y": "ay", "accel_z": "az", "pressure": "p"}
    df = read_imu_csv(f, columns=cols)
    np.testing.assert_array_equal(df["pressure"].to_numpy(), 100000.0 + np.arange(20))
    rows[5] = rows[5].rsplit(",", 1)[0] + ",1013.25"   # hPa in a Pa column
    f.write_text("\n".join(rows) + "\n")
    with pytest.raises(InvalidValueError) as e:
        read_imu_csv(f, columns=cols)
    assert e.value.row == 6 and e.value.column == "p"
