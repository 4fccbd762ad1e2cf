"""Odometer reader: declared units, speed and distance forms, validation errors with locations."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from insgnss.errors import (
    DataGapError,
    InputFormatError,
    InvalidValueError,
    TimeOrderError,
    UnitError,
)
from insgnss.io.odometer import read_odometer, speed_to_distance, validate_odometer, write_odometer


def _write(tmp_path, text, name="odo.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_speed_units(tmp_path):
    p = _write(tmp_path, "time,speed\n0.0,36\n0.1,72\n0.2,0\n")
    df = read_odometer(p, format="csv", unit="km/h")
    assert list(df.columns) == ["speed"] and df.index.name == "time"
    assert np.allclose(df.speed, [10.0, 20.0, 0.0])
    assert np.allclose(read_odometer(p, format="csv", unit="mph").speed,
                       [36 * 0.44704, 72 * 0.44704, 0.0])
    # a native table is SI by definition (the job file's ``kind`` names the quantity)
    assert np.allclose(read_odometer(p, kind="speed").speed, [36.0, 72.0, 0.0])


def test_distance_forms(tmp_path):
    p = _write(tmp_path, "t, ticks\n0, 0\n0.5, 500\n1.0, 1500\n", "enc.csv")
    df = read_odometer(p, quantity="distance", format="csv", unit="pulses", pulses_per_metre=100.0,
                       time_column="t", value_column="ticks", cumulative=True)
    assert np.allclose(df.distance, [0.0, 5.0, 10.0])
    p2 = _write(tmp_path, "time,distance\n0,0\n1,0.012\n2,0.02\n", "km.csv")
    assert np.allclose(read_odometer(p2, kind="distance", format="csv", unit="km").distance,
                       [0, 12, 20])


def test_round_trip_and_speed_to_distance(tmp_path):
    t = np.arange(0, 5.0, 0.5)
    df = pd.DataFrame({"speed": 3.0 + t}, index=pd.Index(t, name="time"))
    path = write_odometer(df, tmp_path / "o.csv")
    back = read_odometer(path, unit="m/s")
    assert np.allclose(back.speed, df.speed) and np.allclose(back.index, t)
    d = speed_to_distance(df)
    assert d.distance.iloc[0] == 0.0
    assert d.distance.sum() == pytest.approx(np.trapezoid(df.speed, t))


@pytest.mark.parametrize(
    "text, kwargs, exc, row, column",
    [
        ("time,speed\n0,1\n0.1,abc\n", {"unit": "m/s"}, InputFormatError, 3, "speed"),
        ("time,speed\n0,1\n0.1,nan\n", {"unit": "m/s"}, InvalidValueError, 3, "speed"),
        ("time,speed\n0,1\n0.1,2\n0.1,2\n", {"unit": "m/s"}, TimeOrderError, 4, "time"),
        ("time,speed\n0,1\n0.2,2\n0.1,2\n", {"unit": "m/s"}, TimeOrderError, 4, "time"),
        ("time,speed\n0,1\n0.1,2\n5.0,2\n", {"unit": "m/s", "max_gap": 1.0}, DataGapError, 4, "time"),
        # 120 km/h written as m/s: implausible for a land vehicle
        ("time,speed\n0,100\n0.1,120\n", {"unit": "m/s"}, UnitError, 2, "speed"),
        ("time,distance\n0,0\n0.1,50\n", {"quantity": "distance", "unit": "m"}, UnitError, 3,
         "distance"),
        ("time,velocity\n0,1\n", {"unit": "m/s"}, InputFormatError, 1, "speed"),
    ],
)
def test_validation_errors_name_the_place(tmp_path, text, kwargs, exc, row, column):
    p = _write(tmp_path, text)
    with pytest.raises(exc) as info:
        read_odometer(p, **kwargs)
    assert info.value.row == row
    assert info.value.column == column
    assert str(p) in str(info.value)


def test_units_must_be_declared(tmp_path):
    p = _write(tmp_path, "time,speed\n0,1\n1,1\n")
    with pytest.raises(UnitError):
        read_odometer(p, format="csv")
    with pytest.raises(UnitError):
        read_odometer(p, format="csv", unit="furlongs/fortnight")
    with pytest.raises(UnitError):
        read_odometer(p, quantity="distance", format="csv", unit="pulses")
    with pytest.raises(UnitError):
        read_odometer(p, unit="km/h")  # native tables are SI
    with pytest.raises(InputFormatError):
        read_odometer(p, format="xlsx")
    with pytest.raises(InputFormatError):
        read_odometer(p, quantity="speed", kind="distance")
    with pytest.raises(InputFormatError):
        read_odometer(_write(tmp_path, "", "empty.csv"), unit="m/s")
    with pytest.raises(InputFormatError):
        read_odometer(tmp_path / "missing.csv", unit="m/s")


def test_validate_dataframe():
    t = np.arange(3.0)
    with pytest.raises(InputFormatError):
        validate_odometer(pd.DataFrame({"speed": t, "distance": t}, index=t))
    with pytest.raises(InvalidValueError):
        validate_odometer(pd.DataFrame({"speed": [1.0, np.inf, 2.0]}, index=t))
    ok = validate_odometer(pd.DataFrame({"speed": [1, 2, 3]}, index=t))
    assert ok.speed.dtype == float
