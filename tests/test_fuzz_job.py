"""Fuzzing the job loader's *values* (issue 12): 2,000 random jobs whose keys are drawn from
the schema and whose values from the edges of every range (0, negative, tiny, huge, NaN, inf,
wrong lengths, wrong types, unknown names). Every outcome is a clean InsgnssError naming a key
or a valid job that passes a cheap dry check: the checks against a 100 Hz IMU, the outage
windows of a 300 s GNSS log, the filter settings and the IMU error model. Load-only, so it
runs in seconds; marked ``fuzz``."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from insgnss.config import _NUM, check_job_against_data, iter_schema, load_job_dict
from insgnss.errors import ConfigError, InsgnssError

pytestmark = pytest.mark.fuzz

EXAMPLES = 2000
FUZZ = settings(max_examples=EXAMPLES, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
KEYS = list(iter_schema())
EDGE_NUMBERS = [0, 0.0, -0.0, 1, -1, 1e-300, 5e-324, 1e-9, 1e-7, 1e-3, 0.01, 0.5, 0.9999,
                1.0, 2.0, 90.0, 1e9, 1e300, -1e300, 2 ** 62, -(2 ** 62), float("nan"),
                float("inf"), float("-inf")]
numbers = st.one_of(st.sampled_from(EDGE_NUMBERS), st.floats(allow_nan=True),
                    st.integers(-10 ** 6, 10 ** 6))
scalars = st.one_of(numbers, st.booleans(), st.text(max_size=8),
                    st.sampled_from(["", "csv", "x,y,z", "y,x,-z", "2024-01-02", "tactical"]))
vectors = st.lists(st.one_of(numbers, numbers, st.booleans(), st.text(max_size=3)), max_size=4)
windows = st.lists(st.one_of(st.lists(numbers, min_size=0, max_size=3), numbers), max_size=3)
tables = st.dictionaries(st.sampled_from(["1", "2", "5", "9", "method", "window", "threshold",
                                          "time", "gyro_x", "bogus", "smooth"]),
                         st.one_of(scalars, st.sampled_from(["amv", "shoe", "gx"])), max_size=3)


STRINGS = st.one_of(st.sampled_from(["rad/s", "deg/s", "deg", "g", "m/s^2", "s", "ms", "us",
                                      "y,x,-z", "x,y,z", "x,x,z", "-y,x,z", "tactical", "MEMS",
                                      "navigation", "2024-01-02", "2024-13-40", "out", "imu.csv",
                                      ",", ";", " ", ""]), st.text(max_size=8))


def value_for(spec):
    """Mostly values of the right type (the value rules are the target), sometimes not."""
    kind = spec["type"]
    if spec["choices"] and kind is list:
        right = st.lists(st.sampled_from(spec["choices"] + ["CSV", ""]), max_size=3)
    elif spec["choices"]:
        right = st.sampled_from(spec["choices"])
    elif kind is _NUM:
        right = numbers
    elif kind is bool:
        right = st.booleans()
    elif kind is list:
        right = st.one_of(vectors, windows)
    elif kind is dict:
        right = tables
    else:
        right = STRINGS
    return st.tuples(st.integers(0, 9), right, scalars).map(lambda x: x[2] if x[0] == 0 else x[1])


@st.composite
def jobs(draw):
    data: dict = {}
    for key, spec in draw(st.lists(st.sampled_from(KEYS), min_size=1, max_size=5,
                                   unique_by=lambda k: k[0])):
        d = data
        parts = key.split(".")
        for p in parts[:-1]:
            d = d.setdefault(p, {})
        d[parts[-1]] = draw(value_for(spec))
    if draw(st.booleans()):  # a recorded job, or a simulated one
        data.setdefault("inputs", {}).setdefault("imu", {}).setdefault("path", "imu.csv")
    else:
        data["scenario"] = {"imu_rate": draw(st.sampled_from([100.0, 0.0, -1.0, "x", 1e9]))}
        data["trajectory"] = {}
    return data


def dry_check(job) -> None:
    """What a run does with the settings before it reads any data."""
    from insgnss.filter.engine import FilterConfig
    from insgnss.job.inputs import imu_model
    from insgnss.pipeline import outage_windows

    check_job_against_data(job, imu_interval=0.01)
    t = np.arange(1000.0, 1300.0, 1.0)
    gnss = pd.DataFrame({"lat": np.zeros(t.size)}, index=pd.Index(t, name="time"))
    wins = outage_windows(job, gnss)
    assert len(wins) <= 2 * t.size * 100  # bounded: windows are at least one IMU interval
    f = job["filter"]
    FilterConfig(imu_model=imu_model(job, None), bias_model=f["bias_model"],
                 propagation_interval=f["propagation_interval"],
                 epoch_interval=f["epoch_interval"], discretization=f["discretization"],
                 gate_probability=f["gate_probability"] or None,
                 gate_recovery=f["gate_recovery"] or None, nis_window=f["nis_window"] or None,
                 nis_bound=f["nis_bound"]).validate()


OUTCOMES = {"error": 0, "valid": 0}


@FUZZ
@given(jobs())
def test_job_values_fuzz(data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            job = load_job_dict(data, "fuzz.toml")
            dry_check(job)
        except InsgnssError as exc:
            assert exc.file == "fuzz.toml" or isinstance(exc, ConfigError), exc
            assert exc.column is not None, f"error names no key: {exc}"
            OUTCOMES["error"] += 1
            return
    OUTCOMES["valid"] += 1


def test_fuzz_reached_both_outcomes():
    """Run after the fuzz test: a fuzzer that only ever hits one outcome tests little."""
    if not sum(OUTCOMES.values()):
        pytest.skip("run together with test_job_values_fuzz")
    assert OUTCOMES["error"] > 100 and OUTCOMES["valid"] > 50, OUTCOMES
