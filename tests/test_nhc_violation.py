"""The NHC violation measured in a first pass's smoothed solution (insgnss.nhc_violation,
aiding.nhc_violation_from_data) and the re-linearized second pass (filter.smoother_passes), on
simulated cars: one whose body slips sideways and heaves, one whose NHC holds (a residual
mounting only), one that starts at rest with a heading error and loses GNSS as it drives off."""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from filter_sim import car_outage_setup, car_truth, outage_end_error, outage_rms

from insgnss.filter import BodyVelocity, Zaru, Zupt, run_filter
from insgnss.nhc_violation import nhc_violation_estimate

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

OUTAGES = [(40.0 + 45 * k, 55.0 + 45 * k) for k in range(4)]


def _nhc(tn, est=None):
    kw = {} if est is None else {"std": 0.02, "violation_state": "nhc_violation",
                                 "violation_std": list(est.std), "violation_tau": est.tau}
    return BodyVelocity(tn, 0.0, axes=(0, 2), name="nhc", **({"std": 0.1} | kw),
                        pitch_compliance_state="nhc_pitch_compliance",
                        misalignment_state="nhc_misalignment")


def _two_runs(truth, rng):
    """White NHC at the car profile's 0.1 m/s, the violation measured in its smoothed
    solution, then the Gauss-Markov run with it: (estimate, (end, smoothed) white, measured)."""
    imu, init, gnss, tn, cfg = car_outage_setup(truth, rng, OUTAGES, smoother=True)
    res = run_filter(imu, init, [*gnss, _nhc(tn)], cfg)
    est = nhc_violation_estimate(res.smoothed, OUTAGES)
    res2 = run_filter(imu, init, [*gnss, _nhc(tn, est)], cfg)
    return est, *((outage_end_error(r.forward, truth, OUTAGES),
                   outage_rms(r.smoothed, truth, OUTAGES)) for r in (res, res2))


def test_measured_violation_of_a_slipping_car_cuts_the_smoothed_outage_error():
    """A body slipping by a Gauss-Markov 0.1 m/s (0.05 m/s heave, 2 s, smoothed over 0.5 s):
    the smoothed solution measures 0.06 m/s lateral (the first pass's NHC pulls it down),
    0.05 m/s vertical and about a second of correlation; the Gauss-Markov states with them cut
    the smoothed in-outage RMS by a third (0.131 -> 0.087 m) at the same forward drift."""
    from bench_nhc_sigma import slipping_car

    rng = np.random.default_rng(300)
    truth = slipping_car(rng, 0.1, 2.0, duration=200.0)
    est, white, meas = _two_runs(truth, rng)
    assert 0.04 < est.std[0] < 0.12 and 0.03 < est.std[1] < 0.08, est
    assert 0.5 < est.tau < 3.0, est
    assert meas[1] < 0.75 * white[1], (white, meas)
    assert meas[0] < 1.05 * white[0], (white, meas)


def test_measured_violation_of_a_car_whose_nhc_holds_is_small_and_costs_nothing():
    """A car whose NHC holds (residual mounting of 0.7 deg per axis, estimated by the
    misalignment states): the measured violation is below 0.01 m/s, so the Gauss-Markov states
    take almost nothing from the constraint (a fixed 0.1 m/s would: docs/filter.md); forward
    and smoothed are no worse (0.543 -> 0.474 m, 0.046 -> 0.038 m)."""
    from bench_nhc_mounting import mounted_car

    rng = np.random.default_rng(100)
    mu = np.random.default_rng(10_100).standard_normal(3) * np.radians(0.7)
    truth = mounted_car(mu, duration=200.0, seed_heading=rng.uniform(0, 2 * np.pi))
    est, white, meas = _two_runs(truth, rng)
    assert max(est.std) < 0.01, est
    assert meas[0] < white[0] and meas[1] < white[1], (white, meas)


def test_relinearized_second_pass_of_a_car_driving_off_with_a_heading_error():
    """A car levelled at rest with its heading 10 deg off (sigma 10 deg: no gyrocompass) loses
    GNSS as it drives off: the first pass's smoother linearizes the first outage about that
    heading and keeps 0.15 m of in-outage RMS there; the second pass, started from the smoothed
    start state and parameters (insgnss.job.processes.relinearized_start), brings it to the
    level of the other outages (below half)."""
    from bench_nhc_mounting import mounted_car  # noqa: F401  (the bench path, as above)

    from insgnss.attitude import rotvec_to_dcm
    from insgnss.job.initialization import Initialization
    from insgnss.job.processes import relinearized_start

    rng = np.random.default_rng(100)
    truth = car_truth(120.0, 50.0, heading0=rng.uniform(0, 2 * np.pi), start_at_rest=True)
    t = truth.index.to_numpy()
    still = truth["stationary"].to_numpy() > 0.5
    t_move = t[np.flatnonzero(~still)[0]]
    outages = [(t_move - 1.0 + 45 * k, t_move + 14.0 + 45 * k) for k in range(2)]
    imu, init, gnss, tn, cfg = car_outage_setup(truth, rng, outages, smoother=True)
    init.C = rotvec_to_dcm(np.array([0.0, 0.0, np.radians(10.0)])) @ init.C
    cfg.initial_att_std = (0.005, 0.005, np.radians(10.0))
    moving = np.interp(tn, t, still.astype(float)) < 0.5
    ts = t[still][::25]
    ini, pars, rms = Initialization(state=init, method="sim", heading_source="sim"), None, []
    for _ in range(2):
        cfg.initial_parameters = pars
        res = run_filter(imu, ini.state, [*gnss, _nhc(tn[moving]), Zupt(ts, std=0.02), Zaru(ts)],
                         cfg)
        rms.append(outage_rms(res.smoothed, truth, outages[:1]))
        ini, pars = relinearized_start(ini, res.smoothed)
        cfg.gyro_bias = tuple(ini.gyro_bias)
    assert rms[0] > 0.08, rms  # the linearization error the second pass removes
    assert rms[1] < 0.5 * rms[0], rms


def test_initial_parameters_set_the_nominal_of_parameter_states():
    """FilterConfig.initial_parameters: nominal start values by state label (extras included);
    labels the layout does not hold are ignored. BodyVelocity(misalignment_initial=...): the
    misalignment's own initial nominal."""
    rng = np.random.default_rng(1)
    truth = car_truth(10.0, 50.0)
    imu, init, gnss, tn, cfg = car_outage_setup(truth, rng, [])
    cfg.initial_parameters = {"gyro_bias_z": 1e-3, "nhc_misalignment_z": 0.01, "nope": 5.0}
    res = run_filter(imu, init, [*gnss, _nhc(tn)], cfg)
    row = res.forward.iloc[0]
    assert row["gyro_bias_z"] == pytest.approx(1e-3, abs=1e-5)
    assert row["nhc_misalignment_z"] == pytest.approx(0.01, abs=1e-4)
    nhc = BodyVelocity(tn, 0.0, axes=(0, 2), std=0.1, misalignment_state="mis",
                       misalignment_initial=(0.0, 0.0, -0.02))
    cfg.initial_parameters = None
    assert run_filter(imu, init, [*gnss, nhc], cfg).forward["mis_z"].iloc[0] == \
        pytest.approx(-0.02, abs=1e-4)


def test_measured_violation_reaches_the_job_and_the_summary():
    """aiding.nhc_violation_from_data: the measured sigmas and correlation time become
    aiding.nhc_std and aiding.nhc_correlation_time of the next pass and go to
    preprocessing.nhc_violation; a measurement without a correlation time keeps the job's."""
    from insgnss.config import load_job_dict
    from insgnss.job.processes import _with_measured_violation
    from insgnss.job.tuning import Tuned

    rng = np.random.default_rng(2)
    truth = car_truth(80.0, 50.0)
    imu, init, gnss, tn, cfg = car_outage_setup(truth, rng, [], smoother=True)
    res = run_filter(imu, init, [*gnss, _nhc(tn)], cfg)
    job = load_job_dict({"job": {"platform": "car"},
                         "aiding": {"nhc_violation_from_data": True}})
    ctx = SimpleNamespace(preprocessing={})
    tuned = _with_measured_violation(ctx, Tuned(job, None, None, []), res.smoothed)
    info = ctx.preprocessing["nhc_violation"]
    assert info["applied"] and info["tau_s"] > 0
    assert tuned.job["aiding"]["nhc_correlation_time"] == pytest.approx(info["tau_s"])
    assert tuned.job["aiding"]["nhc_std"] == pytest.approx(info["std_m_s"])
    assert job["aiding"]["nhc_correlation_time"] == 0.0  # the job itself is unchanged
    flat = res.smoothed.copy()
    flat[["vel_e", "vel_n", "vel_u"]] = 0.0  # standing: nothing to measure
    ctx = SimpleNamespace(preprocessing={})
    with pytest.warns(Warning):
        same = _with_measured_violation(ctx, Tuned(job, None, None, []), flat)
    assert same.job is job and not ctx.preprocessing["nhc_violation"]["applied"]


def test_passes_over_the_smoother_need_the_smoother():
    """Both mechanisms read the first pass's smoothed solution: without the smoother the job
    stops before any computation and names the key, instead of silently running one pass."""
    import tomllib
    from pathlib import Path

    from insgnss.config import load_job_dict
    from insgnss.errors import ConfigError

    path = Path(__file__).resolve().parents[1] / "scenarios" / "drive_0708.toml"
    for section, key, value in (("aiding", "nhc_violation_from_data", True),
                                ("filter", "smoother_passes", 2)):
        data = tomllib.loads(path.read_text())
        data.setdefault("filter", {})["smoother"] = False
        data.setdefault(section, {})[key] = value
        with pytest.raises(ConfigError, match="filter.smoother = true") as err:
            load_job_dict(data, path)
        assert f"{section}.{key}" in str(err.value)
