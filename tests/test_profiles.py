"""Platform profiles (insgnss/data/profiles.toml): resolution schema < profile < job file, the
profiles' own validation, the tuned-noise-value rule, and the repository jobs that follow it."""

import tomllib
from pathlib import Path

import pytest

from insgnss import profiles
from insgnss.config import SIMULATION_TABLES, load_job_dict, platform_profile
from insgnss.errors import ConfigError

REPO = Path(__file__).resolve().parents[1]


def test_every_platform_is_a_valid_set_of_job_keys():
    assert set(profiles.platforms()) >= {"car", "pedestrian", "foot", "aircraft", "generic"}
    for name in profiles.platforms():
        platform_profile(name)  # raises ConfigError naming the profiles file on a bad key
        assert profiles.description(name)
        # the sensor's noise (IMU, GNSS) never comes from a platform: from the grade, the data
        # or the self-tuning; a profile holds only the platform's own sigmas (its constraints)
        keys = profiles.tuned_noise_keys(profiles.profile(name))
        assert not any(k.startswith("filter.imu_model") or "gnss" in k or "q_scale" in k
                       for k in keys), (name, keys)


def test_resolution_order():
    generic = load_job_dict({})
    car = load_job_dict({"job": {"platform": "car"}})
    assert generic.platform == "generic" and not generic["aiding"]["nhc"]
    assert car["aiding"]["nhc"] and car["aiding"]["zupt"] and car["filter"]["noise_from_static"]
    assert car["initialization"]["min_speed"] == 3.0
    assert car.from_profile["aiding.nhc"] is True
    # a job key overrides its profile's; the rest of the profile stays
    own = load_job_dict({"job": {"platform": "car"}, "aiding": {"nhc": False}})
    assert not own["aiding"]["nhc"] and own["aiding"]["zupt"]
    assert own.explicit["aiding.nhc"] is False and "aiding.nhc" not in own.from_profile
    ped = load_job_dict({"job": {"platform": "pedestrian"}})
    assert not ped["aiding"]["nhc"] and ped["aiding"]["gnss_velocity"]
    assert ped["initialization"]["min_speed"] < 1.0
    assert not ped["inputs"]["imu"]["estimate_time_offset"]
    assert ped["initialization"]["course_heading_std_deg"] > car["initialization"][
        "course_heading_std_deg"]
    # the foot profile selects the foot-mounted process through the PRESETS table
    from insgnss.job.processes import process_name

    assert process_name(load_job_dict({"job": {"platform": "foot"}})) == "foot"


def test_unknown_platform_is_named():
    with pytest.raises(ConfigError) as exc:
        load_job_dict({"job": {"platform": "bicycle"}}, "job.toml")
    assert exc.value.column == "job.platform"


@pytest.mark.parametrize("key,value,tuned", [
    ("aiding.nhc_std", [0.1, 0.1], True),
    ("aiding.gnss_min_std", 0.03, True),
    ("aiding.q_scale", {"1": 1.0, "2": 10.0}, True),
    ("aiding.zupt_std", 0.02, True),
    ("filter.imu_model.accel_bias_instability_ug", 2000.0, True),
    ("initialization.position_std", 2.0, True),
    ("foot.sigma_zupt", 0.01, True),
    ("foot.accel_psd", 0.01, True),
    ("foot.gyro_bias_rw", 1e-5, True),
    ("aiding.detector.sigma_a", 0.001, True),
    ("aiding.gnss_velocity_std_scale", 0.5, True),
    ("filter.noise_from_static", True, False),   # a switch, not a value
    ("inputs.imu.gap_noise", True, False),
    ("filter.imu_grade", "consumer", False),     # the sensor class describes the data
    ("inputs.gnss.lever_arm", [0.0, 0.5, 1.0], False),
    ("inputs.imu.mounting_deg", [180.0, 0.0, -90.0], False),
    ("outages.periodic.length", 15.0, False),
    ("aiding.nhc_interval", 0.25, False),
])
def test_tuned_noise_value_rule(key, value, tuned):
    assert profiles.is_tuned_noise_key(key, value) is tuned
    table: dict = {}
    d = table
    *path, last = key.split(".")
    for p in path:
        d = d.setdefault(p, {})
    d[last] = value
    assert (key in profiles.tuned_noise_keys(table)) is tuned


@pytest.mark.parametrize("name", ["drive_0708.toml", "walk_0827.toml"])
def test_real_data_jobs_carry_no_tuned_value(name):
    data = tomllib.loads((REPO / "scenarios" / name).read_text())
    data = {k: v for k, v in data.items() if k not in SIMULATION_TABLES}
    assert profiles.tuned_noise_keys(data) == {}
    assert data["job"]["platform"] in profiles.platforms()


def test_docs_generalization_lists_the_profiles():
    doc = (REPO / "docs" / "generalization.md").read_text()
    for line in profiles.markdown().splitlines():
        if line.startswith("| `"):
            assert line in doc, f"docs/generalization.md lacks {line}"


def test_bench_generalize_fails_on_a_tuned_value(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_generalize",
                                                  REPO / "bench" / "bench_generalize.py")
    bench = importlib.util.module_from_spec(spec)
    import sys

    sys.modules["bench_generalize"] = bench  # its dataclasses look their module up
    spec.loader.exec_module(bench)
    assert bench.check_jobs(bench.ROWS) == []  # the protocol's own jobs are clean
    job = tmp_path / "scenarios" / "tuned.toml"
    job.parent.mkdir()
    job.write_text('[job]\nplatform = "car"\n[aiding]\nnhc = true\nnhc_std = [0.05, 0.05]\n'
                   '[filter.imu_model]\naccel_bias_instability_ug = 2000.0\n')
    bench.REPO = tmp_path
    row = bench.Row("tuned", "report", "car", lambda: {}, job)
    bad = bench.check_jobs([row])
    assert len(bad) == 2 and "aiding.nhc_std" in bad[0] and "accel_bias_instability_ug" in bad[1]
