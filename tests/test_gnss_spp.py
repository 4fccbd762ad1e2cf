"""Single-point positioning: simulation with known geometry and truth (NEES, clock and
inter-system bias recovery, fault exclusion, Doppler velocity), and the real walk."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from conftest import shared_data
from gnss_helpers import (
    ALPHA,
    BETA,
    CFG,
    ION,
    T0,
    pr_noise,
    simulate_observations,
    synthetic_constellation,
    write_rinex_nav,
    write_rinex_obs,
)

from insgnss.earth import ecef_to_enu_matrix, ecef_to_geodetic, geodetic_to_ecef, geodetic_to_enu
from insgnss.gnss import (
    GnssModelConfig,
    SppConfig,
    decode_subframes,
    read_rinex_nav,
    read_rinex_obs,
    read_ubx,
    spp,
)

R0 = np.array(geodetic_to_ecef(np.radians(40.1), np.radians(-105.15), 1600.0))
V0 = np.array([3.0, -2.0, 0.5])  # ECEF velocity [m/s]



def _sim(n_epochs=150, noise=pr_noise, seed=1):
    eph = synthetic_constellation(T0)
    times = T0 + 5.0 + np.arange(n_epochs) * 2.0
    obs, truth = simulate_observations(
        eph, times, lambda t: R0 + V0 * (t - T0), lambda t: -4.6e5 - 70.0 * (t - T0),
        isb={"E": 12.5}, iono=(ALPHA, BETA), noise=noise, rng=np.random.default_rng(seed))
    return eph, obs, truth


@pytest.fixture(scope="module")
def sim():
    return _sim()


def test_spp_simulation_consistent_with_truth(sim):
    eph, obs, truth = sim
    res = spp(obs, eph, ION, SppConfig(model=CFG))
    sol = res.solution
    assert len(sol) == len(truth)
    # indexed by the true reception time (tag minus the estimated clock offset)
    assert np.allclose(sol.index, [tr["t"] for tr in truth], atol=1e-6, rtol=0)  # float64: 0.24 us
    assert np.allclose(sol["receiver_time"], [tr["t_tag"] for tr in truth], atol=1e-6, rtol=0)
    nees, dclk, disb = [], [], []
    for row, tr in zip(sol.itertuples(), truth, strict=True):
        lat, lon, h = ecef_to_geodetic(*tr["r"])
        e, n, u = geodetic_to_enu(row.lat, row.lon, row.height, lat, lon, h)
        err = np.array([e, n, u])
        P = np.diag([row.east_std, row.north_std, row.up_std]) ** 2
        nees.append(err @ np.linalg.solve(P, err))
        dclk.append(row.clock_bias_G - tr["b"])
        disb.append(row.clock_bias_E - row.clock_bias_G - 12.5)
    nees = np.array(nees)
    # diagonal covariance ignores correlations: NEES mean 3 +- 0.5 over 150 epochs
    assert 2.3 < nees.mean() < 3.8
    assert np.mean(nees > 14.2) < 0.02  # 3-dof 99.7 % bound
    assert abs(np.mean(dclk)) < 1.0 and np.std(dclk) < 5.0
    assert abs(np.mean(disb)) < 1.0
    # velocity and drift from the (noise-free) Doppler: ~mm/s (the position error tilts the
    # lines of sight by ~1e-7 rad/m; ionosphere/troposphere rates are not modelled)
    Cel = ecef_to_enu_matrix(*ecef_to_geodetic(*R0)[:2])
    v_enu = Cel @ V0
    assert np.allclose(sol[["vel_e", "vel_n", "vel_u"]].to_numpy(), v_enu, atol=1e-2)
    assert np.allclose(sol["clock_drift"], -70.0, atol=1e-2)
    assert sol["raim_ok"].mean() > 0.97
    assert (sol["pdop"] > 1.0).all() and (sol["hdop"] < sol["pdop"]).all()


def test_spp_dop_matches_geometry(sim):
    eph, obs, truth = sim
    res = spp(obs[obs.index == obs.index[0]], eph, ION, SppConfig(model=CFG))
    r = res.residuals[res.residuals["used"]]
    el, az = r["el"].to_numpy(), r["az"].to_numpy()
    G = np.column_stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el),
                         (r["sat"].str[0] == "G"), (r["sat"].str[0] == "E")]).astype(float)
    G[:, :3] *= -1.0
    D = np.linalg.inv(G.T @ G)
    row = res.solution.iloc[0]
    assert row.pdop == pytest.approx(np.sqrt(np.trace(D[:3, :3])), rel=1e-6)
    assert row.hdop == pytest.approx(np.sqrt(D[0, 0] + D[1, 1]), rel=1e-6)


def test_spp_excludes_a_faulty_satellite():
    eph, obs, truth = _sim(n_epochs=5, noise=lambda el, cn0, ura, io: 0.3 * np.ones(el.size))
    obs = obs.copy()
    bad = (obs["sat"] == "G03").to_numpy()
    obs.loc[bad, "pr"] += 80.0
    res = spp(obs, eph, ION, SppConfig(model=CFG))
    sol, r = res.solution, res.residuals
    assert (sol["n_excluded"] == 1).all() and sol["raim_ok"].all()
    assert not r.loc[r["sat"] == "G03", "used"].any()
    for row, tr in zip(sol.itertuples(), truth, strict=True):
        lat, lon, h = ecef_to_geodetic(*tr["r"])
        e, n, u = geodetic_to_enu(row.lat, row.lon, row.height, lat, lon, h)
        assert np.hypot(e, n) < 5.0
    # without fault exclusion the 80 m error leaks into the solution
    res0 = spp(obs, eph, ION, SppConfig(model=CFG, false_alarm=0.0))
    assert (res0.solution["n_excluded"] == 0).all()


def test_spp_empty_input_gives_empty_table(sim):
    eph, obs, _ = sim
    res = spp(obs, eph, ION, SppConfig(model=GnssModelConfig(signals={"C": ("6I",)})))
    assert res.solution.empty and "lat" in res.solution.columns


# --- real data: the walk --------------------------------------------------------------------

@pytest.fixture(scope="module")
def walk():
    d = shared_data("gnss-imu-rtklibexplorer", "walk_0827")
    ubx = read_ubx(d / "gnss_1730.ubx")
    eph, ion = decode_subframes(ubx.subframes)
    return d, ubx, eph, ion


def _enu_error(sol, ref):
    j = ref.reindex(sol.index, method="nearest", tolerance=0.02)
    ok = np.isfinite(j["lat"].to_numpy())
    lat0, lon0 = float(ref["lat"].iloc[0]), float(ref["lon"].iloc[0])
    e, n, u = geodetic_to_enu(sol["lat"][ok], sol["lon"][ok], sol["height"][ok], lat0, lon0, 0.0)
    e2, n2, u2 = geodetic_to_enu(j["lat"][ok], j["lon"][ok], j["height"][ok], lat0, lon0, 0.0)
    return np.column_stack([e - e2, n - n2, u - u2])


def test_walk_ubx_contents(walk):
    _, ubx, eph, ion = walk
    assert len(ubx.epochs) == 536 and len(ubx.subframes) == 2328 and len(ubx.nav_pvt) == 536
    assert set(eph["system"]) == {"G", "E", "C"}
    assert set(eph["source"]) == {"lnav", "cnav", "inav", "d1"}
    assert {"G", "E", "C"} <= set(ion["system"])
    # the ephemerides' satellites are the tracked ones, with plausible orbits
    assert ((eph["sqrt_a"] > 5000) & (eph["sqrt_a"] < 5500)).all()


def test_walk_lnav_and_cnav_agree(walk):
    """Two independent broadcast messages (different formats, bit layouts and scale factors)
    of the same GPS satellites give the same orbit and L1 C/A clock."""
    from insgnss.gnss.ephemeris import group_delay, satellite_states

    _, ubx, eph, _ = walk
    t = float(ubx.epochs.index[0])
    both = [s for s in eph["sat"].unique()
            if {"lnav", "cnav"} <= set(eph.loc[eph["sat"] == s, "source"])]
    assert len(both) >= 4
    for sat in both:
        rows = eph.index[(eph["sat"] == sat)].to_numpy()
        st = satellite_states(eph, rows, t)
        gd = group_delay("G", eph.iloc[rows], "1C")
        assert np.linalg.norm(st["pos"][0] - st["pos"][1]) < 2.0
        assert abs(((st["clock"][0] - gd[0]) - (st["clock"][1] - gd[1])) * 299792458.0) < 0.5


def test_walk_spp_against_rtk_and_nav_pvt(walk):
    d, ubx, eph, ion = walk
    from insgnss.io import read_rtklib_pos

    ref = read_rtklib_pos(d / "gnss_1730_sf.pos")
    res = spp(ubx.observations, eph, ion)
    sol = res.solution
    assert len(sol) == 536
    err = _enu_error(sol, ref)
    hor = np.hypot(err[:, 0], err[:, 1])
    # RMS a few metres: ~8 m, of which a constant offset common to GPS-only, Galileo-only and
    # BeiDou-only solutions (the RTK reference's base coordinates); scatter about it ~1 m
    assert np.sqrt(np.mean(hor**2)) < 12.0
    off = err[:, :2].mean(axis=0)
    assert np.sqrt(np.mean(np.sum((err[:, :2] - off) ** 2, axis=1))) < 2.0
    means = []
    for s, sig in (("G", "1C"), ("E", "1C"), ("C", "6I")):
        one = spp(ubx.observations, eph, ion, SppConfig(model=GnssModelConfig(signals={s: (sig,)}),
                                                        velocity=False)).solution
        assert len(one) > 500
        means.append(_enu_error(one, ref)[:, :2].mean(axis=0))
    means = np.array(means)
    assert np.max(np.linalg.norm(means - means.mean(axis=0), axis=1)) < 2.0
    assert np.linalg.norm(means.mean(axis=0)) > 5.0  # the offset is in the reference
    # residuals: every used pseudorange within 5 sigma, RMS a fraction of a metre to metres
    r = res.residuals[res.residuals["used"]]
    assert (np.abs(r["pr_residual"]) < 5 * r["pr_std"]).mean() > 0.995
    assert np.sqrt(np.mean(r["pr_residual"] ** 2)) < 2.0
    # velocity: the walk's speed (<= 1.8 m/s) to ~0.1 m/s against the RTK velocity
    j = ref.reindex(sol.index, method="nearest", tolerance=0.02)
    dv = sol[["vel_e", "vel_n"]].to_numpy() - j[["vel_e", "vel_n"]].to_numpy()
    assert np.sqrt(np.nanmean(np.sum(dv**2, axis=1))) < 0.25
    # the receiver's NAV-PVT is the RTK solution of the reference file on the same epochs
    e_pvt = _enu_error(ubx.nav_pvt.assign(height=ubx.nav_pvt["height_msl"]), ref)
    assert np.abs(e_pvt).max() < 1e-3


def test_walk_rinex_round_trip_gives_the_same_spp(walk, tmp_path):
    _, ubx, eph, ion = walk
    sig = {"G": ("1C",), "E": ("1C",), "C": ("6I",)}
    obs = ubx.observations
    obs = obs[obs.index < obs.index[0] + 2.1]
    write_rinex_nav(eph, ion, tmp_path / "walk.nav")
    write_rinex_obs(obs, tmp_path / "walk.obs", sig)
    e2, i2 = read_rinex_nav(tmp_path / "walk.nav")
    o2 = read_rinex_obs(tmp_path / "walk.obs")
    assert set(e2["sat"]) == set(eph.loc[eph["source"] != "cnav", "sat"])
    cfg = SppConfig(model=GnssModelConfig(signals=sig))
    lnav_only = eph[eph["source"] != "cnav"].reset_index(drop=True)
    a = spp(obs, lnav_only, ion, cfg).solution
    b = spp(o2, e2, i2, cfg).solution
    assert len(a) == len(b) == 9
    assert np.allclose(a.index, b.index, atol=1e-6)
    # equal to the rounding of the RINEX fields (1 mm pseudoranges, 5-digit Klobuchar
    # coefficients in the header)
    err = _enu_error(b, a)
    assert np.abs(err[:, :2]).max() < 0.01 and np.abs(err[:, 2]).max() < 0.05


def test_keep_highest_satellites_inside_windows(sim):
    from insgnss.gnss import prepare_observations
    from insgnss.gnss.observations import keep_highest_satellites

    eph, obs, truth = sim
    prep = prepare_observations(obs, eph, CFG)
    sol = spp(obs, eph, ION, SppConfig(model=CFG), prepared=prep).solution
    t = np.asarray(prep.index, float)
    win = [(t[0] + 20.0, t[0] + 40.0)]
    thin = keep_highest_satellites(prep, win, 3, sol)
    ti = np.asarray(thin.index, float)
    inside = (ti >= win[0][0]) & (ti < win[0][1])
    counts = pd.Series(1, index=ti[inside]).groupby(level=0).size()
    assert (counts == 3).all() and len(counts) == 10
    assert (~inside).sum() == ((t < win[0][0]) | (t >= win[0][1])).sum()
    # the three kept are the three highest of the residual table at that epoch
    r = spp(obs, eph, ION, SppConfig(model=CFG), prepared=prep).residuals
    t1 = counts.index[0]
    top = r[r["time"] == t1].nlargest(3, "el")["sat"]
    assert set(thin.loc[thin.index == t1, "sat"]) == set(top)
    assert thin.attrs["thinned_rows"] == len(prep) - len(thin)
    # SPP is impossible with 3 satellites of 2 systems (5 unknowns): a loose filter loses the fix
    assert len(spp(obs, eph, ION, SppConfig(model=CFG), prepared=thin).solution) == len(sol) - 10
