"""Job values (issue 12, items 3, 7, 8): every value of a job is range-checked when the job is
loaded, and a key the run would not read is an error, so that no setting is silently ignored
and no value reaches the computation that can loop, exhaust memory or give a misleading error.
"""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from insgnss.config import (
    REMOVED_KEYS,
    SCHEMA,
    check_job_against_data,
    iter_schema,
    load_job,
    load_job_dict,
)
from insgnss.errors import ConfigError

REPO = Path(__file__).resolve().parents[1]
INF, NAN = float("inf"), float("nan")
IMU = {"path": "imu.csv"}
GNSS = {"path": "gnss.pos"}


def _inputs(**tables):
    return {"inputs": {"imu": dict(IMU), **tables}}


#: (job dict, the dotted key the error must name)
BAD_VALUES = [
    # item 3: periodic outages that loop forever / exhaust memory today
    ({"outages": {"periodic": {"start": 10.0, "length": 1e-7, "gap": 0.0}}},
     "outages.periodic.gap"),
    ({"outages": {"periodic": {"start": 10.0, "length": 0.0, "gap": 5.0}}},
     "outages.periodic.length"),
    ({"outages": {"periodic": {"start": 10.0, "length": -5.0, "gap": 5.0}}},
     "outages.periodic.length"),
    ({"outages": {"periodic": {"start": NAN, "length": 5.0, "gap": 5.0}}},
     "outages.periodic.start"),
    ({"outages": {"periodic": {"start": 1.0, "length": 5.0, "gap": 5.0,
                               "stop_before_end": -1.0}}}, "outages.periodic.stop_before_end"),
    # windows: exactly two numbers, start < end
    ({"outages": {"windows": [[1.0, 2.0, 3.0]]}}, "outages.windows"),
    ({"outages": {"windows": [[20.0, 10.0]]}}, "outages.windows"),
    ({"outages": {"windows": [[10.0, 10.0]]}}, "outages.windows"),
    ({"outages": {"windows": [[1.0, "2"]]}}, "outages.windows"),
    ({"outages": {"windows": [5.0, 6.0]}}, "outages.windows"),
    ({"outages": {"windows": [[0.0, INF]]}}, "outages.windows"),
    ({"aiding": {"zupt": True, "static_intervals": [[5.0, 1.0]]}}, "aiding.static_intervals"),
    # standard deviations > 0, vectors of the right length
    ({"aiding": {"nhc": True, "nhc_std": [0.1]}}, "aiding.nhc_std"),
    ({"aiding": {"nhc": True, "nhc_std": [0.1, -0.1]}}, "aiding.nhc_std"),
    ({"aiding": {"nhc": True, "nhc_std": [0.1, 0.0]}}, "aiding.nhc_std"),
    ({"aiding": {"gnss_min_std": -0.01}}, "aiding.gnss_min_std"),
    ({"aiding": {"zupt": True, "zupt_std": 0.0}}, "aiding.zupt_std"),
    ({"aiding": {"gnss_position_std": -1.0}}, "aiding.gnss_position_std"),
    ({"aiding": {"gnss_std_scale": 0.0}}, "aiding.gnss_std_scale"),
    ({"aiding": {"q_scale": {"1": -1.0}}}, "aiding.q_scale"),
    ({"aiding": {"q_scale": {"fix": 1.0}}}, "aiding.q_scale"),
    ({"aiding": {"q_scale": {"9": 1.0}}}, "aiding.q_scale"),
    ({"aiding": {"nhc": True, "nhc_interval": 0.0}}, "aiding.nhc_interval"),
    ({"aiding": {"zupt": True, "zupt_interval": -0.1}}, "aiding.zupt_interval"),
    ({"aiding": {"zupt": True, "zupt_max_speed": -1.0}}, "aiding.zupt_max_speed"),
    ({"aiding": {"zupt": True, "detector": {"method": "amv", "window": -1.0}}}, "aiding.detector"),
    ({"aiding": {"zupt": True, "detector": {"method": "amv", "window": "wide"}}},
     "aiding.detector"),
    ({"aiding": {"zupt": True, "detector": {"windw": 1.0}}}, "aiding.detector"),
    # lever arms: three finite numbers
    (_inputs(gnss={**GNSS, "lever_arm": ["0", "0", "0"]}), "inputs.gnss.lever_arm"),
    (_inputs(gnss={**GNSS, "lever_arm": [INF, 0.0, 0.0]}), "inputs.gnss.lever_arm"),
    (_inputs(gnss={**GNSS, "lever_arm": [0.0, 0.0]}), "inputs.gnss.lever_arm"),
    (_inputs(gnss={**GNSS, "lever_arm": [0.0, 0.0, True]}), "inputs.gnss.lever_arm"),
    # every number finite
    ({"inputs": {"imu": {**IMU, "time_offset": NAN}}}, "inputs.imu.time_offset"),
    (_inputs(gnss={**GNSS, "time_offset": -INF}), "inputs.gnss.time_offset"),
    ({"filter": {"propagation_interval": INF}}, "filter.propagation_interval"),
    ({"initialization": {"start_time": NAN}}, "initialization.start_time"),
    # probabilities in [0, 1) (0: off)
    ({"filter": {"gate_probability": 1.0}}, "filter.gate_probability"),
    ({"filter": {"gate_probability": -0.1}}, "filter.gate_probability"),
    # intervals, durations, bounds
    ({"filter": {"epoch_interval": 0.0}}, "filter.epoch_interval"),
    ({"filter": {"propagation_interval": -0.1}}, "filter.propagation_interval"),
    ({"filter": {"nis_bound": 0.0}}, "filter.nis_bound"),
    ({"filter": {"nis_window": -1.0}}, "filter.nis_window"),
    ({"filter": {"gate_recovery": -1.0}}, "filter.gate_recovery"),
    ({"initialization": {"static_duration": -1.0}}, "initialization.static_duration"),
    ({"initialization": {"position_std": 0.0}}, "initialization.position_std"),
    ({"initialization": {"method": "given", "roll_deg": 0.0, "pitch_deg": 95.0,
                         "heading_deg": 0.0}}, "initialization.pitch_deg"),
    ({"initialization": {"method": "given", "roll_deg": 0.0, "pitch_deg": 0.0,
                         "heading_deg": 0.0, "attitude_std_deg": [1.0, 1.0, 0.0]}},
     "initialization.attitude_std_deg"),
    ({"evaluation": {"settle_time": -1.0}}, "evaluation.settle_time"),
    ({"inputs": {"imu": {**IMU, "max_gap": -1.0}}}, "inputs.imu.max_gap"),
    ({"inputs": {"imu": {**IMU, "rate_hz": 0.0}}}, "inputs.imu.rate_hz"),
    ({"inputs": {"imu": {**IMU, "mounting_deg": [0.0, 0.0]}}}, "inputs.imu.mounting_deg"),
    ({"filter": {"imu_model": {"gyro_arw_deg_sqrt_h": -1.0}}}, "filter.imu_model.gyro_arw_deg_sqrt_h"),
    ({"filter": {"imu_model": {"bias_correlation_time_s": 0.0}}},
     "filter.imu_model.bias_correlation_time_s"),
    # the initial sigma of an estimated state (found by bench_extremes: a singular P0 stopped
    # the filter at its first epoch and the evaluation of the empty solution crashed)
    ({"filter": {"scale_factors": True, "imu_model": {"gyro_scale_ppm": 0.0}}},
     "filter.imu_model.gyro_scale_ppm"),
    ({"filter": {"imu_model": {"accel_bias_mg": 0.0}}}, "filter.imu_model.accel_bias_mg"),
    ({"filter": {"process_model": "riss", "riss": {"window": 0.0}}}, "filter.riss.window"),
    ({"inputs": {"control_points": {"path": "cp.csv", "std": 0.0}}}, "inputs.control_points.std"),
    # names and strings
    ({"filter": {"imu_grade": "bogus"}}, "filter.imu_grade"),
    ({"filter": {"frame": "ned"}}, "filter.frame"),
    ({"outputs": {"formats": ["CSV"]}}, "outputs.formats"),
    ({"outputs": {"dir": ""}}, "outputs.dir"),
    (_inputs(reference={"path": "ref.pos", "q": [0]}), "inputs.reference.q"),
    (_inputs(reference={"path": "ref.pos", "q": [1.5]}), "inputs.reference.q"),
    ({"inputs": {"imu": {**IMU, "axis_map": "x,x,z"}}}, "inputs.imu.axis_map"),
    ({"inputs": {"imu": {**IMU, "gyro_unit": "rpm"}}}, "inputs.imu.gyro_unit"),
    ({"inputs": {"imu": {**IMU, "time_unit": "min"}}}, "inputs.imu.time_unit"),
    ({"inputs": {"imu": {**IMU, "columns": {"gyro_q": "gx"}}}}, "inputs.imu.columns"),
    ({"inputs": {"imu": {**IMU, "delimiter": ""}}}, "inputs.imu.delimiter"),
    (_inputs(gnss={"path": "g.nmea", "format": "nmea", "date": "2024-13-40"}), "inputs.gnss.date"),
    ({"inputs": {"imu": {"path": ""}}}, "inputs.imu.path"),
]


@pytest.mark.parametrize("data,key", BAD_VALUES, ids=[k for _, k in BAD_VALUES])
def test_bad_values_are_refused_at_load_naming_the_key(data, key):
    with pytest.raises(ConfigError) as exc:
        load_job_dict(data, "job.toml")
    assert exc.value.column == key, str(exc.value)
    assert "job.toml" in str(exc.value)


def test_extremes_inside_the_documented_ranges_are_accepted():
    job = load_job_dict({
        "filter": {"gate_probability": 0.0, "gate_recovery": 0.0, "nis_window": 0.0,
                   "imu_grade": "MEMS"},
        "aiding": {"gnss_min_std": 0.0, "zupt": True, "zupt_max_speed": 0.0,
                   "nhc": True, "nhc_std": [1e-6, 1e6]},
        "outages": {"windows": [[0.0, 1e-3]], "periodic": {"start": 0.0, "length": 1e-3,
                                                            "gap": 1e-3}},
    })
    assert job["aiding"]["nhc_std"] == [1e-6, 1e6]
    assert job["filter"]["gate_probability"] == 0.0


# --- item 8: a key the run does not read is an error, never silently ignored -------------------
@pytest.mark.parametrize("data,key,words", [
    # a simulation table in a job with recorded inputs: it would be ignored (lever arm!)
    ({**_inputs(gnss=dict(GNSS)), "gnss": {"lever_arm": [0.0, 1.0, 0.0]}}, "gnss",
     "simulation"),
    ({**_inputs(), "scenario": {"seed": 3}}, "scenario", "simulation"),
    # the reverse: recorded-input keys in a simulated job are not read
    ({"scenario": {"seed": 3}, "trajectory": {}, "inputs": {"gnss": {"lever_arm": [1, 0, 0]}}},
     "inputs.gnss.lever_arm", "[gnss] lever_arm"),
    ({"scenario": {"seed": 3}, "trajectory": {}, "inputs": {"gnss": {"path": "g.pos"}}},
     "inputs.gnss.path", "simulat"),
    # keys of another input format
    ({"inputs": {"imu": {**IMU, "format": "rtklibexplorer", "mounting_deg": [0, 0, 0],
                         "mounting_convention": "passive"}}},
     "inputs.imu.mounting_convention", "rtklibexplorer"),
    ({"inputs": {"imu": {**IMU, "format": "kfgins", "gyro_unit": "deg/s"}}},
     "inputs.imu.gyro_unit", "kfgins"),
    ({"inputs": {"imu": {**IMU, "format": "csv", "tag": "imu.tag"}}}, "inputs.imu.tag", "csv"),
    (_inputs(gnss={**GNSS, "date": "2024-01-02"}), "inputs.gnss.date", "nmea"),
    (_inputs(reference={"path": "t.nav", "format": "kfgins_nav", "q": [1]}),
     "inputs.reference.q", "rtklib_pos"),
    # keys of an input that is not given
    ({"inputs": {"imu": dict(IMU), "gnss": {"lever_arm": [0.0, 1.0, 0.0]}}},
     "inputs.gnss.lever_arm", "inputs.gnss.path"),
    ({"inputs": {"imu": dict(IMU), "odometer": {"kind": "distance"}}}, "inputs.odometer.kind",
     "inputs.odometer.path"),
    # settings of a method, a model or an aiding source that is not selected
    ({"initialization": {"method": "static", "roll_deg": 1.0}}, "initialization.roll_deg",
     "method"),
    ({"initialization": {"method": "gnss_velocity", "static_duration": 10.0}},
     "initialization.static_duration", "static"),
    ({"filter": {"riss": {"azimuth": "level"}}}, "filter.riss.azimuth", "riss"),
    ({"aiding": {"nhc_std": [0.2, 0.2]}}, "aiding.nhc_std", "aiding.nhc"),
    ({"aiding": {"gnss_position": False, "gnss_min_std": 0.01}}, "aiding.gnss_min_std",
     "gnss_position"),
    ({"process": {"preset": "foot"}, "aiding": {"zupt": True}}, "aiding.zupt", "foot"),
    ({"evaluation": {"enabled": False, "settle_time": 5.0}}, "evaluation.settle_time",
     "enabled"),
    ({"outages": {"periodic": {"stop_before_end": 10.0}}}, "outages.periodic.stop_before_end",
     "periodic"),
    ({"filter": {"nis_window": 0.0, "nis_bound": 10.0}}, "filter.nis_bound", "nis_window"),
    ({"filter": {"process_model": "riss", "frame": "wander"}}, "filter.frame", "process_model"),
    ({"filter": {"imu_model": {"gyro_scale_ppm": 100.0}}}, "filter.imu_model.gyro_scale_ppm",
     "scale_factors"),
    ({"inputs": {"imu": {**IMU, "estimate_time_offset": True}}},
     "inputs.imu.estimate_time_offset", "GNSS"),
])
def test_keys_the_run_would_not_read_are_errors(data, key, words):
    with pytest.raises(ConfigError) as exc:
        load_job_dict(data, "job.toml")
    assert exc.value.column == key, str(exc.value)
    assert words in str(exc.value)


@pytest.mark.parametrize("data,key", [
    ({"outages": {"periodic": {"start": 10.0, "length": 5.0}}}, "outages.periodic.gap"),
    ({"initialization": {"method": "given", "roll_deg": 0.0, "pitch_deg": 0.0}},
     "initialization.heading_deg"),
    ({"inputs": {"imu": {**IMU, "format": "rtklibexplorer"}}}, "inputs.imu.mounting_deg"),
    ({"aiding": {"cupt": True}, **_inputs()}, "inputs.control_points.path"),
    ({"aiding": {"odometer": True}, **_inputs()}, "inputs.odometer.path"),
])
def test_missing_companion_keys_are_found_at_load(data, key):
    with pytest.raises(ConfigError) as exc:
        load_job_dict(data, "job.toml")
    assert exc.value.column == key, str(exc.value)


@pytest.mark.parametrize("key,hint", [("inputs.gnss.use_velocity", "aiding.gnss_velocity"),
                                      ("aiding.nhc_min_speed", "NHC")])
def test_removed_keys_say_what_to_use_instead(key, hint):
    table, _, leaf = key.rpartition(".")
    data: dict = {}
    d = data
    for part in table.split("."):
        d = d.setdefault(part, {})
    d[leaf] = True if leaf == "use_velocity" else 1.0
    if key.startswith("inputs.gnss"):
        data["inputs"]["gnss"]["path"] = "g.pos"
    with pytest.raises(ConfigError) as exc:
        load_job_dict(data, "job.toml")
    assert exc.value.column == key and hint in str(exc.value)
    assert key in REMOVED_KEYS


def test_values_equal_to_the_default_in_a_round_trip_are_not_errors():
    """``Job.to_dict`` gives a dict that loads to the same job (Monte Carlo work units)."""
    job = load_job_dict({"scenario": {"seed": 1}, "trajectory": {},
                         "aiding": {"nhc": True, "nhc_std": [0.2, 0.3]},
                         "outputs": {"report": False}})
    job.settings["outputs"]["progress"] = False  # changed in memory after loading
    again = load_job_dict(job.to_dict())
    assert again.settings == job.settings and again.simulation == job.simulation


# --- checks that need the IMU rate (before the filter) -------------------------------------------
@pytest.mark.parametrize("data,key", [
    ({"outages": {"periodic": {"start": 10.0, "length": 0.005, "gap": 30.0}}},
     "outages.periodic.length"),
    ({"outages": {"periodic": {"start": 10.0, "length": 15.0, "gap": 0.001}}},
     "outages.periodic.gap"),
    ({"outages": {"windows": [[10.0, 10.004]]}}, "outages.windows"),
    ({"filter": {"epoch_interval": 1e-9}}, "filter.epoch_interval"),
    ({"aiding": {"nhc": True, "nhc_interval": 1e-6}}, "aiding.nhc_interval"),
])
def test_intervals_shorter_than_one_imu_interval_are_refused(data, key):
    job = load_job_dict(data, "job.toml")
    with pytest.raises(ConfigError) as exc:
        check_job_against_data(job, imu_interval=0.01)
    assert exc.value.column == key and "IMU interval" in str(exc.value)
    check_job_against_data(load_job_dict({}), imu_interval=0.01)  # defaults pass


def test_simulated_job_is_checked_against_its_imu_rate_at_load():
    with pytest.raises(ConfigError) as exc:
        load_job_dict({"scenario": {"imu_rate": 100.0}, "trajectory": {},
                       "outages": {"periodic": {"start": 10.0, "length": 0.001, "gap": 5.0}}})
    assert exc.value.column == "outages.periodic.length"


def test_periodic_windows_never_loops_on_a_period_that_rounds_to_zero():
    """Item 3: ``length = 1e-7, gap = 0`` looped forever growing memory; the arithmetic itself
    now refuses (in a subprocess with a timeout, so that a regression cannot hang the suite)."""
    code = textwrap.dedent("""
        import resource
        resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))
        from insgnss.outages import periodic_windows
        for length, gap in ((1e-7, 0.0), (1e-7, 1e-7), (0.0, 1.0), (1.0, -1.0)):
            try:
                periodic_windows(0.0, 3600.0, 10.0, length, gap)
            except ValueError as exc:
                print("refused:", exc)
            else:
                print("accepted", length, gap)
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                       cwd=REPO, env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"})
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("refused:") == 4, r.stdout


def test_periodic_windows_and_in_windows_scale_with_many_windows():
    import numpy as np

    from insgnss.outages import in_windows, periodic_windows, window_index

    w = periodic_windows(0.0, 300.0, 0.0, 0.01, 0.01)  # the extreme: one IMU interval each
    assert len(w) == 15000 and w[1] == (0.02, 0.03)
    t = np.arange(0.0, 300.0, 0.005)
    m = in_windows(t, w)
    k = window_index(t, w)
    assert m.sum() == 30000 and np.array_equal(m, k >= 0)
    assert k[1] == 0 and k[2] == -1 and k[4] == 1 and k[-1] == -1


# --- item 7: a non-finite value is named at load, not found after the run ---------------------
def test_infinite_lever_arm_and_nan_offset_are_named_from_a_job_file(tmp_path):
    f = tmp_path / "job.toml"
    f.write_text('[inputs.imu]\npath = "imu.csv"\ntime_offset = nan\n')
    with pytest.raises(ConfigError) as exc:
        load_job(f)
    assert exc.value.column == "inputs.imu.time_offset" and "finite" in str(exc.value)
    f.write_text('[inputs.imu]\npath = "imu.csv"\n[inputs.gnss]\npath = "g.pos"\n'
                 "lever_arm = [inf, 0.0, 0.0]\n")
    with pytest.raises(ConfigError) as exc:
        load_job(f)
    assert exc.value.column == "inputs.gnss.lever_arm" and "finite" in str(exc.value)


# --- item 8: the time base is used; every key is read somewhere --------------------------------
def test_job_time_base_is_checked_against_the_inputs():
    import pandas as pd

    from insgnss.validate import check_time_bases

    imu = pd.DataFrame({"x": [0.0]}, index=[1.0])
    imu.attrs.update(source="imu.csv", time_base="gps")
    gnss = pd.DataFrame({"x": [0.0]}, index=[1.0])
    gnss.attrs.update(source="g.pos", time_base="sow")
    native = pd.DataFrame({"x": [0.0]}, index=[1.0])
    native.attrs.update(source="ref.csv", time_base="unspecified")
    check_time_bases({"imu": imu, "reference": native}, "gps", file="job.toml")
    check_time_bases({"imu": imu, "reference": native}, "unspecified", file="job.toml")
    with pytest.raises(ConfigError) as exc:  # declared gps, GNSS in seconds of week
        check_time_bases({"imu": imu, "gnss": gnss}, "gps", file="job.toml")
    assert exc.value.column == "job.time_base" and "g.pos" in str(exc.value)
    assert "sow" in str(exc.value)
    with pytest.raises(ConfigError) as exc:  # undeclared, but the two inputs disagree
        check_time_bases({"imu": imu, "gnss": gnss}, "unspecified", file="job.toml")
    assert "imu.csv" in str(exc.value) and "g.pos" in str(exc.value)


def test_every_schema_key_is_read_by_the_code():
    """No key that does nothing: each schema key's name is looked up outside the schema (a
    ``["name"]`` subscript, a ``.get("name")``, or a whole-table pass-through listed here)."""
    import re

    config = (REPO / "insgnss" / "config.py").read_text()
    code = "\n".join(p.read_text() for p in (REPO / "insgnss").rglob("*.py")
                     if p.name != "config.py") + config[config.index("class Job"):]
    passed_whole = {"filter.riss": r'\*\*job\["filter"\]\["riss"\]',
                    "filter.imu_model": r'\["imu_model"\]\.items\(\)'}
    dead = []
    for key, _spec in iter_schema():
        table, _, leaf = key.rpartition(".")
        if table in passed_whole and re.search(passed_whole[table], code):
            continue
        if not re.search(rf'\[\s*["\']{re.escape(leaf)}["\']\s*\]|get\(\s*["\']'
                         rf'{re.escape(leaf)}["\']', code):
            dead.append(key)
    assert not dead, f"schema keys that no code reads: {dead}"
    assert set(REMOVED_KEYS).isdisjoint(k for k, _ in iter_schema())


def test_documented_ranges_cover_every_number():
    """Every number and array key carries a value rule (its doc appears in docs/jobs.md)."""
    missing = [k for k, s in iter_schema()
               if s["type"] in ((int, float), list) and s["check"] is None and not s["choices"]]
    assert not missing
    assert all(isinstance(t, dict) for t in SCHEMA.values())


def test_finite_check_accepts_big_integers():
    job = load_job_dict({"initialization": {"start_time": 2 ** 62}})
    assert math.isfinite(job["initialization"]["start_time"])
