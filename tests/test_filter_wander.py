"""The wander-azimuth process model of the filter (ECEF error state): F against a numerical
Jacobian (also at the pole), agreement with the LLF filter where both run, feedback across the
pole, and the filter over the pole with GNSS positions where the ENU filter cannot run."""

import numpy as np
import pandas as pd
import pytest
from filter_sim import (
    car_truth,
    corrupt_imu,
    gnss_from_truth,
    nav_errors,
    perturbed_initial,
    polar_flight,
)
from scipy.linalg import expm

from insgnss.attitude import (
    attitude_error,
    dcm_to_rotvec,
    euler_to_dcm,
    rotvec_to_dcm,
    skew,
)
from insgnss.earth import (
    OMEGA_E,
    ecef_to_geodetic,
    enu_to_ecef_dcm,
    geodetic_to_ecef,
    normal_gravity,
)
from insgnss.errors import ConfigError
from insgnss.filter import (
    BodyVelocity,
    FilterConfig,
    GnssPosition,
    GnssVelocity,
    StateLayout,
    Zupt,
    run_filter,
)
from insgnss.filter.ecef_dynamics import ecef_error_dynamics
from insgnss.filter.wander_model import WanderModel, ecef_position, run_wander_filter
from insgnss.imu import grade, increments_table
from insgnss.mechanization.strapdown import NavState
from insgnss.mechanization.wander import wander_state

D = np.pi / 180.0
W = np.array([0.0, 0.0, OMEGA_E])


# --- F against a numerical Jacobian of the exact ECEF equations ------------------------------
def _rates(r, v, C, f, w):
    lat, lon, h = ecef_to_geodetic(*r)
    u = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    dv = C @ f - 2 * np.cross(W, v) - normal_gravity(lat, h) * u
    return v, dv, skew(C @ w) - skew(W)


def _error_rate(nom, dx, f, w, tau=1e-4):
    r, v, C = nom
    rt, vt, Ct = r - dx[0:3], v - dx[3:6], rotvec_to_dcm(-dx[6:9]) @ C
    pn, vn, On = _rates(r, v, C, f, w)
    pt, vt_, Ot = _rates(rt, vt, Ct, f + dx[12:15], w + dx[9:12])
    E = C @ Ct.T
    out = np.zeros(15)
    out[0:3] = pn - pt
    out[3:6] = vn - vt_
    out[6:9] = (dcm_to_rotvec(expm(On * tau) @ E @ expm(-Ot * tau))
                - dcm_to_rotvec(expm(-On * tau) @ E @ expm(Ot * tau))) / (2 * tau)
    return out


EPS = np.array([10.0] * 3 + [0.1] * 3 + [1e-4] * 3 + [1e-5] * 3 + [1e-3] * 3)


@pytest.mark.parametrize("lat,lon,alpha", [(60 * D, 0.3, 0.4), (-20 * D, 2.0, -1.0),
                                           (89.99999 * D, 1.0, 2.5), (np.pi / 2, 0.0, 0.0)])
def test_ecef_error_dynamics_match_numerical_jacobian(lat, lon, alpha):
    """Every entry to 1e-4 of itself (floor: the numerical Jacobian's rounding), including the
    gravity gradient at and next to the pole."""
    h = 1200.0
    C_bl = euler_to_dcm(0.2, -0.1, 1.3)
    v_l = np.array([150.0, -120.0, 8.0])
    x0 = NavState(lat, lon, h, v_l, C_bl)
    x0.wander_angle = alpha
    Cne, _, vw, Cbw = wander_state(x0)
    f, w = np.array([0.5, 1.0, 10.5]), np.array([0.01, -0.02, 0.05])
    Fa = ecef_error_dynamics(Cne, h, Cbw, f, w, StateLayout())
    nom = (ecef_position(Cne, h), Cne @ vw, Cne @ Cbw)
    Fn = np.zeros((15, 15))
    for j in range(15):
        d = np.zeros(15)
        d[j] = EPS[j]
        Fn[:, j] = (_error_rate(nom, d, f, w) - _error_rate(nom, -d, f, w)) / (2 * EPS[j])
    floor = np.full((15, 15), 1e-12)
    floor[3:6, 0:3] = 1e-13  # the gradient block (entries ~1e-6 1/s^2), numerical noise ~1e-14
    bad = np.argwhere(np.abs(Fa - Fn) > 1e-4 * np.abs(Fn) + floor)
    assert bad.size == 0, [(i, j, Fa[i, j], Fn[i, j]) for i, j in bad]
    # the gradient is there: vertical ~ +2 g / R along the normal, horizontal ~ -g / R
    u = Cne[:, 2]
    assert u @ Fa[3:6, 0:3] @ u == pytest.approx(3.08e-6, rel=0.01)
    e1 = Cne[:, 0]
    assert e1 @ Fa[3:6, 0:3] @ e1 == pytest.approx(-1.54e-6, rel=0.01)


# --- agreement with the LLF filter at mid latitude ---------------------------------------------
def test_wander_filter_equals_llf_filter_at_mid_latitude():
    """Same IMU, GNSS (with a lever arm), initial state: the two error representations give the
    same trajectory and stds (linear maps of each other up to second-order terms: the rotation
    between the ENU frames of the nominal and the true point) - any wrong sign or rotation in
    the wander model shows up here."""
    rng = np.random.default_rng(1)
    truth = car_truth(60.0, rate=50.0)
    imu, _ = corrupt_imu(truth, grade("tactical"), rng)
    gnss = gnss_from_truth(truth, rng)
    x0, _ = perturbed_initial(truth, rng, 1.0, 0.1, (0.005, 0.005, 0.02))
    x0.wander_angle = 0.7
    cfg = FilterConfig(imu_model="tactical", initial_att_std=(0.005, 0.005, 0.02))
    # NHC with an odometer scale-factor state: an extra state and body-frame H through observe
    tr = truth.iloc[5::10]
    speed = np.linalg.norm(tr[["vel_e", "vel_n", "vel_u"]].to_numpy(), axis=1)
    nhc = BodyVelocity(tr.index, values=speed[:, None] * [0.0, 1.0, 0.0], axes=(0, 1, 2),
                       std=0.1, scale_state="odometer_scale", scale_std=0.01)
    ms = [GnssPosition(gnss), GnssVelocity(gnss, lever_arm=(0.3, 1.0, 1.2)), nhc]
    a = run_filter(imu, x0, ms, cfg)
    b = run_wander_filter(imu, x0, ms, cfg)
    assert a.complete and b.complete
    for A, B in ((a.forward, b.forward), (a.smoothed, b.smoothed)):
        d = nav_errors(B, A.loc[B.index]).abs().max()
        assert d[["east", "north", "up"]].max() < 3e-4  # measured 7e-5 m (up)
        assert d[["vel_e", "vel_n", "vel_u"]].max() < 5e-6  # 1.3e-6 m/s
        assert d[["phi_e", "phi_n", "phi_u"]].max() < 1e-6  # 2.6e-7 rad
        stds = [c for c in A.columns if c.endswith("_std")]
        assert np.allclose(A[stds], B[stds], rtol=1e-4, atol=1e-9)
        par = ["gyro_bias_x", "gyro_bias_z", "accel_bias_x", "accel_bias_z", "odometer_scale"]
        assert ((A[par] - B[par]).abs().max() < 1e-3 * A[par].abs().max()).all()  # 1e-5..1e-4
    assert np.allclose(a.innovations["nis"], b.innovations["nis"], rtol=1e-4, atol=1e-8)
    # the nominal moved: the filter did work (errors of order metres were corrected)
    assert nav_errors(a.forward, truth).abs().max()["north"] < 3.0


def test_wander_model_feedback_across_the_pole():
    """A 3 m feedback that moves the nominal from 1 m before the pole to 2 m beyond it: ECEF
    position, velocity and attitude change exactly by the error, the frame stays orthonormal."""
    lat = np.pi / 2 - 1.0 / 6.36e6
    x0 = NavState(lat, 0.4, 900.0, np.array([0.0, 250.0, 0.0]), euler_to_dcm(0.1, 0.02, 0.0))
    t = np.arange(3) * 0.01
    imu = increments_table(t, np.zeros((3, 3)), np.zeros((3, 3)))
    m = WanderModel(imu, x0, [], FilterConfig(imu_model="tactical"))
    r0, v0, C0 = ecef_position(m.Cne, m.hv[0]), m.Cne @ m.vel, m.Cne @ m.C
    x = np.zeros(15)
    x[0:3] = -3.0 * (m.Cne @ np.array([0.0, 1.0, 0.0]))  # nominal minus true: true is ahead
    x[3:6] = [0.1, -0.2, 0.3]
    x[6:9] = [1e-3, -2e-3, 3e-3]
    m.feedback(x)
    assert np.abs(ecef_position(m.Cne, m.hv[0]) - (r0 - x[0:3])).max() < 1e-6
    assert np.abs(m.Cne @ m.vel - (v0 - x[3:6])).max() < 1e-9
    assert np.abs(attitude_error(m.Cne @ m.C, rotvec_to_dcm(-x[6:9]) @ C0)).max() < 1e-12
    assert np.abs(m.Cne.T @ m.Cne - np.eye(3)).max() < 1e-14
    assert np.degrees(m.pos[0]) > 89.99997 and abs(m.pos[1] - 0.4) > 3.0  # over the pole
    with pytest.raises(ConfigError, match="high-rate"):
        run_wander_filter(imu, x0, [Zupt(t, high_rate=True)], FilterConfig(imu_model="tactical"))
    xn = pd.DataFrame({"pos_std": [0.1], "up_std": [0.2]}, index=[0.01])
    with pytest.raises(ConfigError, match="up_std"):
        run_wander_filter(imu, x0, [Zupt(t)], FilterConfig(imu_model="tactical", extra_noise=xn))


# --- over the pole ------------------------------------------------------------------------------
def _ecef(df):
    return np.column_stack(geodetic_to_ecef(df["lat"].to_numpy(), df["lon"].to_numpy(),
                                            df["height"].to_numpy()))


@pytest.fixture(scope="module")
def polar_run():
    """The issue's route with a tactical IMU and 1 Hz GNSS positions
    (:func:`filter_sim.polar_flight`), through the wander and the ENU filter."""
    truth, imu, gnss, x0, cfg = polar_flight(np.random.default_rng(7))
    res = run_wander_filter(imu, x0, [GnssPosition(gnss)], cfg)
    enu = run_filter(imu, x0, [GnssPosition(gnss)], cfg)
    return truth, res, enu


def _errors(est, truth):
    tr = truth.loc[est.index]
    Cl = enu_to_ecef_dcm(tr["lat"].to_numpy(), tr["lon"].to_numpy())
    de = np.einsum("kji,kj->ki", Cl, _ecef(est) - _ecef(tr))  # ENU at the true point
    C_est = enu_to_ecef_dcm(est["lat"].to_numpy(), est["lon"].to_numpy()) @ euler_to_dcm(
        est["roll"].to_numpy(), est["pitch"].to_numpy(), est["heading"].to_numpy())
    C_tru = Cl @ euler_to_dcm(tr["roll"].to_numpy(), tr["pitch"].to_numpy(),
                              tr["heading"].to_numpy())
    phi = np.einsum("kji,kj->ki", Cl, attitude_error(C_est, C_tru))  # in ENU axes
    return de, phi


def test_wander_filter_flies_over_the_pole_with_gnss(polar_run):
    truth, res, _ = polar_run
    assert res.complete and len(res.forward) == len(truth)
    assert np.degrees(res.smoothed["lat"].max()) > 89.99999  # within ~1 m of the pole
    assert np.isfinite(res.smoothed.to_numpy()).all()
    for est, bound in ((res.forward, 2.5), (res.smoothed, 1.0)):
        de, phi = _errors(est, truth)
        assert np.linalg.norm(de, axis=1).max() < bound
        sig = est[["east_std", "north_std", "up_std"]].to_numpy()
        assert (np.abs(de) < 3 * sig).mean() > 0.9
        late = est.index.to_numpy() > 60.0  # after the initial 0.1-0.6 deg have settled
        assert np.degrees(np.abs(phi[late, :2]).max()) < 0.2  # tilt
        assert np.degrees(np.abs(phi[late, 2]).max()) < 1.2  # heading (straight flight)
        assert (np.abs(phi[:, 2]) < 3 * est["heading_std"].to_numpy()).mean() > 0.9
    # GNSS innovations consistent: mean NIS / dof near 1, nothing rejected
    nis = res.innovations["nis"].to_numpy()
    assert 0.7 < nis.mean() / 3 < 1.3 and res.innovations["accepted"].all()


def test_enu_filter_cannot_fly_over_the_pole(polar_run):
    """The LLF filter on the same data: its transport rate and longitude rate blow up at the
    pole passage (t = 225 s): 116 m forward, 1.5 km smoothed, GNSS rejected, NIS ~ 37 (before
    the longitude-wrap fix of ``enu_offset`` it stopped on a runaway NIS, 7 km off)."""
    truth, _, enu = polar_run
    if not enu.complete:
        return
    err = [np.linalg.norm(_ecef(est) - _ecef(truth.loc[est.index]), axis=1).max()
           for est in (enu.forward, enu.smoothed)]
    assert err[0] > 50.0 and err[1] > 500.0
    assert (~enu.innovations["accepted"]).sum() > 0


def test_job_key_frame_wander_runs_the_wander_model():
    """``[filter] frame = "wander"`` in a job: the same solution as the ENU job (mid latitude)."""
    from robustness_helpers import small_job

    from insgnss.job.run import run_job

    a = run_job(small_job(), progress=False)
    b = run_job(small_job(filter='frame = "wander"'), progress=False)
    assert a.failure is None and b.failure is None
    A, B = a.filter.smoothed, b.filter.smoothed
    assert len(A) == len(B) > 1000
    assert nav_errors(B, A).abs().max()[["east", "north", "up"]].max() < 1e-3
    assert np.allclose(A["east_std"], B["east_std"], rtol=1e-3)
    # the wander model ran: its final state carries the wander angle the route turned it by
    # (d alpha = -sin(lat) d lon), the LLF state none
    assert a.filter.final.wander_angle == 0.0
    assert 1e-5 < abs(b.filter.final.wander_angle) < 1e-3


def test_enu_offsets_across_the_antimeridian_and_next_to_the_pole():
    """GNSS offsets: the LLF nominal wraps the longitude difference; the wander nominal's is an
    exact ECEF difference, also 1 m from the pole where a longitude difference means nothing."""
    from insgnss.earth import radii
    from insgnss.filter.measurements import NominalState
    from insgnss.filter.wander_model import WanderNominalState

    lat, h = 0.8, 100.0
    M, N = radii(lat)
    nav = NominalState()
    nav.lat, nav.lon, nav.height, nav.M, nav.N = lat, np.pi - 1e-6, h, M, N
    d = nav.enu_offset(lat, -np.pi + 1e-6, h)
    assert d[0] == pytest.approx(-2e-6 * (N + h) * np.cos(lat), rel=1e-9)
    # wander: nominal 1 m from the pole on lon 0, the point 1 m beyond it (lon 180)
    la = np.pi / 2 - 1.0 / 6.4e6
    w = WanderNominalState()
    w.lat, w.lon, w.height = la, 0.0, h
    w.r_e = np.array(geodetic_to_ecef(la, 0.0, h))
    w.Cel = enu_to_ecef_dcm(la, 0.0).T
    d = w.enu_offset(la, np.pi, h)
    assert d[1] == pytest.approx(-2.0, abs=2e-3) and abs(d[0]) < 1e-6 and abs(d[2]) < 1e-6
