"""Recovery instead of a stop: the heading re-initialisation of a land vehicle from the GNSS
course (insgnss.filter.heading_reinit), the IMU outlier named in a health message and the
single-sample spike policy (inputs.imu.spike_policy), on the small simulated car and on the real
drive (rtklibexplorer drive_0708)."""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from robustness_helpers import small_job

from insgnss.attitude import euler_to_dcm
from insgnss.earth import geodetic_to_enu
from insgnss.filter import kernels
from insgnss.filter.heading_reinit import (
    CourseTrack,
    HeadingMonitor,
    HeadingReinit,
    forward_heading,
    reset_covariance,
)
from insgnss.pipeline import load_inputs, run_job

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def _h_rms(res, truth_or_ref, t_from: float, table: str = "forward") -> float:
    """Horizontal RMS [m] of a solution against a truth table after ``t_from``."""
    tab = getattr(res.filter, table)
    tab = tab[tab.index > t_from]
    tr = truth_or_ref.reindex(tab.index, method="nearest")
    lat0, lon0, h0 = (float(tr[c].iloc[0]) for c in ("lat", "lon", "height"))
    e, n, _ = geodetic_to_enu(tab.lat.to_numpy(), tab.lon.to_numpy(), tab.height.to_numpy(),
                              lat0, lon0, h0)
    e0, n0, _ = geodetic_to_enu(tr.lat.to_numpy(), tr.lon.to_numpy(), tr.height.to_numpy(),
                                lat0, lon0, h0)
    return float(np.sqrt(np.mean((e - e0) ** 2 + (n - n0) ** 2)))


# --- the pieces -----------------------------------------------------------------------------

def test_heading_feedback_sign_and_covariance_reset():
    """An attitude feedback phi = (0, 0, d) turns the forward-axis heading by +d and keeps
    roll and pitch; the reset zeroes the cross-covariances of heading and horizontal velocity."""
    C = euler_to_dcm(np.radians(3.0), np.radians(-2.0), np.radians(100.0))
    x = np.zeros(15)
    x[8] = np.radians(90.0)
    pos, vel, p = np.array([0.7, 0.1, 100.0]), np.zeros(3), np.zeros(6)
    kernels.apply_feedback(pos, vel, C, p, x)
    assert np.degrees(forward_heading(C)) % 360 == pytest.approx(190.0, abs=1e-9)
    from insgnss.attitude import dcm_to_euler

    r, pt, _ = dcm_to_euler(C)
    assert np.degrees([r, pt]) == pytest.approx([3.0, -2.0], abs=1e-9)
    rng = np.random.default_rng(1)
    A = rng.normal(size=(15, 15))
    P = reset_covariance(A @ A.T, 8, (3, 4), 0.01, 0.04)
    for i, v in ((8, 0.01), (3, 0.04), (4, 0.04)):
        assert P[i, i] == v
        assert np.count_nonzero(P[i]) == 1 and np.count_nonzero(P[:, i]) == 1
    assert np.linalg.eigvalsh(P).min() > 0


def _monitor(course_deg, nis, speed=10.0, dt=1.0):
    n = len(course_deg)
    t = np.arange(n) * dt
    c = np.radians(np.asarray(course_deg, float))
    track = CourseTrack.from_velocity(t, speed * np.sin(c), speed * np.cos(c), 0.1, c,
                                      np.radians(3.0))
    mon = HeadingMonitor(HeadingReinit(track))
    C = euler_to_dcm(0.0, 0.0, 0.0)  # the nominal heading: north
    for k in range(n):
        ev = mon.check(float(t[k]), C)
        if ev is not None:
            return t[k], ev
        mon.note(nis)
    return None, None


def test_monitor_trigger_and_the_reversing_car():
    # 90 deg off, large innovations: re-initialised after 3 s (4 samples at 1 Hz)
    t, ev = _monitor([90.0] * 10, nis=50.0)
    assert t == 3.0 and np.degrees(ev.d) == pytest.approx(90.0)
    assert ev.record["new_heading_deg"] == pytest.approx(90.0)
    assert ev.record["heading_std_deg"] == pytest.approx(np.degrees(np.hypot(0.01, np.radians(3))))
    # a car reversing with a correct heading: the course is 180 deg off, the innovations are
    # consistent: no reset
    assert _monitor([180.0] * 20, nis=0.8)[0] is None
    # disagreement within the angle (side slip), or only 2 s of it: no reset
    assert _monitor([25.0] * 20, nis=50.0)[0] is None
    assert _monitor([90.0, 90.0, 90.0, 0.0] * 5, nis=50.0)[0] is None
    # too slow for the course to count
    assert _monitor([90.0] * 20, nis=50.0, speed=3.0)[0] is None


# --- the small simulated car ----------------------------------------------------------------

@pytest.fixture(scope="module")
def car_runs():
    """The small car (true heading 30 deg) started with its heading 0, +90 and +180 deg off,
    with and without the re-initialisation."""
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for off in (0.0, 90.0, 180.0):
            for on in (False, True):
                job = small_job(initialization=f"heading_deg = {30.0 + off}",
                                aiding=f"heading_reinit = {str(on).lower()}\nnhc = true")
                out[off, on] = run_job(job, progress=False)
    return out


def test_car_recovers_from_a_wrong_heading(car_runs):
    nominal = car_runs[0.0, True]
    assert nominal.summary["heading_reinitialisations"] == []  # no reset on a right heading
    truth = nominal.inputs.truth
    ref = _h_rms(nominal, truth, 60.0)  # measured 0.27 m
    assert ref < 0.4
    for off in (90.0, 180.0):
        res = car_runs[off, True]
        s = res.summary
        assert s["complete"]
        (ev,) = s["heading_reinitialisations"]
        # after the 20 s stand, 3 s of disagreement above 5 m/s
        assert 24.0 < ev["time"] < 32.0
        assert ev["old_heading_deg"] == pytest.approx(30.0 + off, abs=15.0)
        assert ev["new_heading_deg"] == pytest.approx(30.0, abs=3.0)
        assert "GNSS course" in ev["reason"]
        # after 60 s: within 2.5 x the nominal run (measured 0.55 and 0.58 m against 0.27 m);
        # without the reset 3.9 m (90 deg: partly recovered by the gate) and 20.8 m (180 deg)
        late = _h_rms(res, truth, 60.0)
        assert late < 2.5 * ref
        assert _h_rms(car_runs[off, False], truth, 60.0) > 3.0
        # the smoother treats the reset as a boundary: after it as good (0.28-0.30 m)
        assert _h_rms(res, truth, 60.0, "smoothed") < 2.0 * _h_rms(nominal, truth, 60.0,
                                                                     "smoothed")
        h = res.filter.forward["heading"]
        tr = truth["heading"].reindex(h.index, method="nearest")
        dh = np.degrees(np.angle(np.exp(1j * (h - tr).to_numpy())))
        assert np.abs(dh[h.index > ev["time"] + 20.0]).max() < 1.0  # measured 0.15 deg


def test_reinit_in_printed_summary_and_report(car_runs, capsys):
    from insgnss.commands.process import print_summary
    from insgnss.report import summary_html
    from insgnss.report_data import build_report_data

    res = car_runs[180.0, True]
    print_summary(res)
    out = capsys.readouterr().out
    assert "heading re-initialised at t = " in out and "-> 30." in out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        html = summary_html(res, build_report_data(res))
    assert "Heading re-initialisations" in html and "GNSS course" in html


# --- IMU outliers ---------------------------------------------------------------------------

def _spiked(job, t_spike: float, axis: str, value_deg_s: float = 5000.0):
    base = load_inputs(job)
    imu = base.imu.copy()
    k = imu.index.get_indexer([imu.index[0] + t_spike], method="nearest")[0]
    col = imu.columns.get_loc(axis)
    dt = float(imu.index[k] - imu.index[k - 1]) if axis.startswith("dtheta") else 1.0
    imu.iloc[k, col] = np.radians(value_deg_s) * dt
    return base, imu, float(imu.index[k])


def test_spike_policy_flags_and_bridges_on_the_simulated_car(quiet):
    out = {}
    for pol in ("off", "flag", "bridge"):
        job = small_job(aiding="nhc = true", **{"inputs.imu": f'spike_policy = "{pol}"'})
        base, imu, ts = _spiked(job, 40.0, "dtheta_x")
        out[pol] = run_job(job, progress=False, inputs=replace(base, imu=imu))
    clean = run_job(small_job(aiding="nhc = true"), progress=False)
    assert "spikes" not in out["off"].summary["imu"]
    for pol in ("flag", "bridge"):
        (sp,) = out[pol].summary["imu"]["spikes"]
        assert sp["time"] == pytest.approx(ts) and sp["sensor"] == "gyro"
        assert sp["value"] == pytest.approx(5000.0, rel=1e-6) and sp["neighbours"] < 1.0
        assert sp["action"] == ("bridged" if pol == "bridge" else "flagged")
    truth = clean.inputs.truth
    ref = _h_rms(clean, truth, 0.0)
    # the 50 deg roll jump ruins the kept sample's runs (measured 70 m); bridged: as clean
    assert _h_rms(out["off"], truth, 0.0) > 20.0 * ref
    assert _h_rms(out["flag"], truth, 0.0) > 20.0 * ref
    assert _h_rms(out["bridge"], truth, 0.0) == pytest.approx(ref, rel=0.05)


def test_spike_detector_leaves_motion_alone():
    """A 90 deg/s step (a turn starting) and a 2 s vibration burst are not spikes; one
    sample 100 times the vibration sigma is."""
    from insgnss.policies import find_spikes

    rng = np.random.default_rng(3)
    x = rng.normal(0.0, 0.01, (2000, 3))
    x[500:, 2] += np.radians(90.0)
    x[1000:1200] += rng.normal(0.0, 0.5, (200, 3))
    assert find_spikes(x).size == 0
    x[1500, 0] += 50.0
    assert list(find_spikes(x)) == [1500]


def test_health_note_names_the_outlier():
    from insgnss.errors import FilterHealthError
    from insgnss.filter.health import imu_outlier_note, with_imu_note

    t = np.arange(0.0, 100.0, 0.01)
    rng = np.random.default_rng(0)
    gyro = rng.normal(0.0, np.radians(2.0), (t.size, 3))
    accel = rng.normal(0.0, 0.5, (t.size, 3))
    gyro[4000, 1] = np.radians(5000.0)
    note = imu_outlier_note(t, gyro, accel, 50.0, 30.0)
    assert "gyro sample at t = 40.000000 s" in note and "5000 deg/s" in note
    assert "accelerometer" not in note
    assert imu_outlier_note(t, gyro, accel, 80.0, 30.0) == ""  # 40 s before: outside window
    exc = with_imu_note(FilterHealthError("runaway NIS at t = 50 s", column="gnss_pos"), t,
                        gyro, accel, 50.0, 30.0)
    assert "runaway NIS" in str(exc) and "spike_policy" in str(exc) and exc.column == "gnss_pos"


# --- the real drive ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def drive():
    from conftest import shared_data

    from insgnss.config import load_job

    shared_data("gnss-imu-rtklibexplorer", "drive_0708")

    def job():
        j = load_job(REPO / "scenarios" / "drive_0708.toml")
        j.settings["filter"]["autotune"] = False  # the same prior model for every run
        return j

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        base = load_inputs(job())
        nominal = run_job(job(), progress=False, inputs=replace(base))
    return job, base, nominal


def _late(res, t_from):
    """Forward horizontal RMS at the reference epochs and mean outage-end error after
    ``t_from``."""
    ev = res.evaluation["forward"]
    er = ev["errors"]
    o = ev["outages"]
    return (float(np.sqrt(np.mean(er.loc[er.index > t_from, "horizontal"] ** 2))),
            float(o.loc[o["start"] > t_from, "end_h_err_m"].mean()))


def test_drive_heading_180_off_recovers_instead_of_stopping(drive):
    job, base, nominal = drive
    h0 = nominal.summary["initialization"]["heading_deg"]
    t0 = float(nominal.filter.forward.index[0])
    runs = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for off, on in ((180.0, False), (180.0, True), (90.0, True)):
            j = job()
            j.settings["initialization"]["heading_deg"] = (h0 + off) % 360.0
            j.settings["aiding"]["heading_reinit"] = on
            runs[off, on] = run_job(j, progress=False, inputs=replace(base))
    off = runs[180.0, False]  # without: the runaway-NIS stop about 60 s in
    assert not off.summary["complete"] and "runaway NIS" in off.summary["error"]
    res = runs[180.0, True]
    assert res.summary["complete"]
    (ev,) = res.summary["heading_reinitialisations"]  # measured at 55.2 s
    assert 40.0 < ev["time"] - t0 < 60.0
    d_old = (ev["old_heading_deg"] - ev["new_heading_deg"] + 180.0) % 360.0 - 180.0
    assert abs(d_old) > 120.0
    # the new heading is the nominal run's heading at that time (within the course sigma)
    h_nom = np.degrees(nominal.filter.forward["heading"].asof(ev["time"]))
    assert abs((ev["new_heading_deg"] - h_nom + 180.0) % 360.0 - 180.0) < 3 * max(
        ev["heading_std_deg"], 1.0)
    # after the first 60 s: forward RMS 0.539 m against the nominal 0.524 m, outage-end mean
    # 1.98 m against 2.02 m
    rms_n, end_n = _late(nominal, t0 + 60.0)
    rms, end = _late(res, t0 + 60.0)
    assert rms < 1.3 * rms_n and end < 1.3 * end_n
    # 90 deg off: complete and as good after 60 s (re-initialised or recovered by the filter)
    r90 = runs[90.0, True]
    assert r90.summary["complete"]
    rms90, end90 = _late(r90, t0 + 60.0)
    assert rms90 < 1.5 * rms_n and end90 < 1.5 * end_n


def test_drive_gyro_spike_named_in_the_stop_and_bridged(drive):
    """A single 5000 deg/s roll-rate sample during the first outage: the run stops (runaway
    GNSS NIS ~15 s later) and the message names the sample; bridged, the run is the clean one."""
    job, base, nominal = drive
    imu = base.imu.copy()
    t0 = float(imu.index[0])
    k = imu.index.get_indexer([t0 + 45.0], method="nearest")[0]
    imu.iloc[k, imu.columns.get_loc("gyro_x")] = np.radians(5000.0)
    ts = float(imu.index[k])
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for pol in ("off", "bridge"):
            j = job()
            j.settings["inputs"]["imu"]["spike_policy"] = pol
            out[pol] = run_job(j, progress=False, inputs=replace(base, imu=imu))
    s = out["off"].summary
    assert not s["complete"]
    import re

    # in the processed time base: the IMU stamps moved by the estimated IMU-GNSS time offset
    pre = s["preprocessing"]
    dt = pre.get("imu_time_offset_estimated_s", 0.0) + 1e-6 * pre.get("imu_time_drift_ppm", 0.0) \
        * (ts - pre.get("imu_time_offset_reference_s", ts))  # and its drift (preprocess.py)
    t_named = float(re.search(r"gyro sample at t = ([0-9.]+) s", s["error"]).group(1))
    assert t_named == pytest.approx(ts + dt, abs=1e-4) and "5000 deg/s" in s["error"]
    assert "spike_policy" in s["error"]
    s = out["bridge"].summary
    assert s["complete"] and len(s["imu"]["spikes"]) == 1
    rms_n, end_n = _late(nominal, t0)
    rms, end = _late(out["bridge"], t0)
    assert rms == pytest.approx(rms_n, rel=0.02) and end == pytest.approx(end_n, rel=0.02)
