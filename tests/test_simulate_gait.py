"""Foot gait simulator (insgnss.simulate.gait): kinematics, duality, intra-interval motion,
clipping, and the foot INS on a simulated level walk."""

from __future__ import annotations

import numpy as np
import pytest

from insgnss.earth import geodetic_to_enu
from insgnss.errors import ConfigError
from insgnss.foot import FootConfig, run_foot_ins
from insgnss.imu import coning_sculling, increments, increments_table
from insgnss.mechanization.strapdown import NavState, mechanize
from insgnss.simulate.gait import (
    FOOT_FLAT,
    IMPACT,
    STANCE_ROLL,
    GaitParams,
    quintic,
    simulate_walk,
)

LAT = np.radians(45.0)


def walk(steps=6, rate=200.0, oversample=8, **kw):
    gait = {k: kw.pop(k) for k in list(kw) if k in GaitParams.__dataclass_fields__}
    return simulate_walk([{"type": "stand", "duration": 1.0}, {"type": "walk", "steps": steps,
                                                               **gait},
                          {"type": "stand", "duration": 1.0}], rate=rate, lat=LAT,
                         oversample=oversample, **kw)


def enu(tr):
    return np.column_stack(geodetic_to_enu(tr.lat.values, tr.lon.values, tr.height.values,
                                           tr.lat.iloc[0], tr.lon.iloc[0], tr.height.iloc[0]))


def foot_end_error(w, imu, still=None):
    tr = w.truth
    res = run_foot_ins(imu, FootConfig(), lat=tr.lat.iloc[0], lon=tr.lon.iloc[0],
                       height=tr.height.iloc[0],
                       still=tr.stationary.to_numpy() > 0.5 if still is None else still)
    p = enu(tr)
    sol = res.trajectory[["east", "north", "up"]].to_numpy()
    return sol[-1] - p[-1]


def test_quintic_matches_its_end_conditions():
    u = np.array([0.0, 1.0])
    v, d = quintic(u, 0.5, 1.0, 2.0, 0.0, -1.0, 0.5, 0.0)
    np.testing.assert_allclose(v, [1.0, -1.0], atol=1e-12)
    np.testing.assert_allclose(d, [2.0, 0.5], atol=1e-12)
    # numerical derivative of the value equals the returned rate
    uu = np.linspace(0, 1, 2001)
    v, d = quintic(uu, 0.5, 0.0, -3.0, 4.0, 0.2, 1.0, -2.0)
    np.testing.assert_allclose(np.gradient(v, uu * 0.5)[1:-1], d[1:-1], atol=2e-5)


def test_level_walk_kinematics():
    p = GaitParams()
    w = walk(steps=6)
    tr = w.truth
    # foot flat is truly still, and every stance sits at the same height: a level floor
    ff = tr.phase.to_numpy() == FOOT_FLAT
    assert ff.any()
    np.testing.assert_array_equal(tr.loc[ff, ["vel_e", "vel_n", "vel_u"]].to_numpy(), 0.0)
    st = w.stances
    assert len(st) == 6 + 1  # initial stand + one stance per step (the last one continues)
    np.testing.assert_allclose(st.up.to_numpy(), 0.0, atol=2e-6)
    np.testing.assert_allclose(np.diff(st.north.to_numpy()), p.stride_length, atol=2e-6)
    # realistic dynamics: swing rates of several hundred deg/s, a heel-strike shock
    t, dth, dv = increments(w.imu)
    dt = np.diff(t)[0]
    assert 300 < np.degrees(np.abs(dth / dt).max()) < 900
    imp = tr.phase.to_numpy() == IMPACT
    a_imp = np.linalg.norm(dv[imp] / dt, axis=1).max()
    vc = np.hypot(*p.heel_strike_velocity)
    assert a_imp > 9.81 + 0.5 * 2 * vc / p.impact_time  # raised cosine: peak 2 |v_c| / tau


def test_ideal_increments_are_the_exact_dual_and_the_foot_ins_is_exact():
    w = walk(steps=8, oversample=4)
    tr = w.truth
    init = NavState(tr.lat.iloc[0], tr.lon.iloc[0], tr.height.iloc[0], np.zeros(3),
                    np.eye(3), tr.index[0])
    from insgnss.attitude import euler_to_dcm
    init.C = euler_to_dcm(0.0, tr.pitch.iloc[0], tr.heading.iloc[0])
    nav = mechanize(w.ideal, init)
    # velocity and attitude exactly; position to the trapezoid truncation of the output rate
    # (the truth position is the fine-grid integral: 0.1 mm in a swing, 1 um per stance)
    np.testing.assert_allclose(nav[["vel_e", "vel_n", "vel_u"]].to_numpy(),
                               tr[["vel_e", "vel_n", "vel_u"]].to_numpy(), atol=1e-9)
    np.testing.assert_allclose(nav.height.to_numpy(), tr.height.to_numpy(), atol=1e-4)
    err = foot_end_error(w, w.ideal)
    assert np.abs(err).max() < 1e-4


def test_intra_interval_motion_climbs_and_coning_sculling_removes_it():
    """Summed increments carry coning/sculling; without the two-sample correction a 60 Hz
    foot INS climbs (the sign is that of the gait, not random); with it the error vanishes."""
    w = walk(steps=24, rate=60.0, oversample=32)
    t, dth, dv = increments(w.imu)
    raw = foot_end_error(w, w.imu)[2]
    corr = foot_end_error(w, increments_table(t, *coning_sculling(dth, dv)))[2]
    dist = 24 * GaitParams().stride_length
    assert raw / dist > 2e-3            # > 0.2 % of the distance walked
    assert abs(corr) / dist < 2e-4


def test_clipping_limits_the_fine_samples():
    rng = 6 * 9.81
    w = walk(steps=2, oversample=8, accel_range=rng, impact_time=0.006,
             heel_strike_velocity=(0.6, 0.6))
    t, dth, dv = increments(w.imu)
    assert np.abs(dv[1:] / np.diff(t)[:, None]).max() <= rng * (1 + 1e-9)
    ref = walk(steps=2, oversample=8, impact_time=0.006, heel_strike_velocity=(0.6, 0.6))
    assert np.abs(increments(ref.imu)[2][1:] / np.diff(t)[:, None]).max() > rng * 1.5


def test_stance_roll_moves_the_sensor_during_stance():
    roll = np.radians(1.0)
    w = walk(steps=4, stance_roll=roll, roll_pivot=0.0)
    tr = w.truth
    r = tr.phase.to_numpy() == STANCE_ROLL
    assert r.any() and not (tr.stationary.to_numpy()[r] > 0).any()
    # the foot pitches toes-down by the roll angle during each mid-stance
    assert tr.pitch.to_numpy()[r].min() == pytest.approx(-roll, abs=1e-3)
    # rotation about the heel: the sensor, ahead of it, moves down
    assert tr.vel_u.to_numpy()[r].mean() < 0


def test_turns_and_stairs():
    w = walk(steps=4, turn=np.radians(90.0) / 4, rise=0.17)
    st = w.stances
    np.testing.assert_allclose(st.up.to_numpy()[1:], 0.17 * np.arange(1, 5), atol=1e-5)
    assert np.degrees(w.truth.heading.iloc[-1]) == pytest.approx(90.0, abs=1e-6)


def test_bad_gait_parameters():
    with pytest.raises(ConfigError, match="phase fractions"):
        GaitParams(foot_flat=0.5, heel_off=0.4)
    with pytest.raises(ConfigError, match="impact"):
        GaitParams(impact_time=0.2)
    with pytest.raises(ConfigError, match="unknown gait parameter"):
        simulate_walk([{"type": "walk", "steps": 1, "stride": 1.0}])
    with pytest.raises(ConfigError, match="steps"):
        simulate_walk([{"type": "walk", "steps": 0}])
