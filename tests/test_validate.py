"""Shared validation helpers: locations, policies, records, unit heuristics."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from insgnss.errors import (
    ConfigError,
    DataGapError,
    InputFormatError,
    InsgnssError,
    InsgnssWarning,
    InvalidValueError,
    RateMismatchError,
    TimeOrderError,
    UnitError,
)
from insgnss.validate import (
    GapPolicy,
    apply_gap_policy,
    check_finite,
    check_gnss_in_imu_span,
    check_imu_units,
    check_rate,
    check_span,
    check_time_order,
    ensure_not_input,
    find_gaps,
    parse_numeric,
    read_text,
    split_lines,
    split_segments,
)

G0 = 9.80665


def rows_of(tmp_path, text, **kw):
    p = tmp_path / "f.txt"
    p.write_text(text)
    return split_lines(read_text(p), p, **kw)


def test_split_lines_numbers_as_an_editor(tmp_path):
    text = "# comment\nh1,h2\n\n1,2\n# mid\n3,4\n"
    r = rows_of(tmp_path, text, header=True)
    assert r.header == "h1,h2" and r.header_line == 2
    assert r.lines == ["1,2", "3,4"]
    assert r.line_no.tolist() == [4, 6]
    assert [c[0] for c in r.comments] == [1, 5]


def test_crlf_and_bom(tmp_path):
    p = tmp_path / "f.csv"
    p.write_bytes("\ufeffa,b\r\n1,2\r\n3,4\r\n".encode())
    r = split_lines(read_text(p), p, header=True)
    assert r.header == "a,b"
    assert parse_numeric(r, ["a", "b"]).tolist() == [[1, 2], [3, 4]]


@pytest.mark.parametrize("data, row, found", [
    (b"", 1, "no data"), (b"  \n\n", 1, "no data"), (b"a,b\n1,\x002\n", 2, "a NUL byte"),
    (b"a,b\n1,2\n\xff\xfe\n", 3, "byte 0xff"),
])
def test_read_text_rejects(tmp_path, data, row, found):
    p = tmp_path / "x.csv"
    p.write_bytes(data)
    with pytest.raises(InputFormatError) as e:
        read_text(p)
    assert e.value.row == row and e.value.found == found and e.value.file == str(p)


def test_read_text_missing_file(tmp_path):
    with pytest.raises(InputFormatError, match="file not found"):
        read_text(tmp_path / "nope.csv")


def test_header_only_file(tmp_path):
    with pytest.raises(InputFormatError, match="no data rows") as e:
        rows_of(tmp_path, "a,b\n", header=True)
    assert e.value.row == 2


@pytest.mark.parametrize("text, row, column, found", [
    ("a,b,c\n1,2,3\n4,x,6\n", 3, "b", "'x'"),
    ("a,b,c\n1,2,3\n4,5\n", 3, None, "2 fields"),
    ("a,b,c\n1,2,3\n4,5,6,7\n", 3, None, "4 fields"),
    ("a,b,c\n1,,3\n", 2, "b", "''"),
    ("a,b,c\n1,2,1_0\n", 2, "c", "'1_0'"),
])
def test_parse_numeric_locates_the_cell(tmp_path, text, row, column, found):
    r = rows_of(tmp_path, text, header=True)
    with pytest.raises(InputFormatError) as e:
        parse_numeric(r, ["a", "b", "c"])
    assert (e.value.row, e.value.column, e.value.found) == (row, column, found)


def test_parse_numeric_usecols_checks_total_count(tmp_path):
    r = rows_of(tmp_path, "1 x 3\n4 y 6\n7 z\n")
    with pytest.raises(InputFormatError) as e:
        parse_numeric(r, ["a", "c"], delimiter=None, usecols=[0, 2], ncols=3)
    assert e.value.row == 3 and e.value.found == "2 fields"
    r = rows_of(tmp_path, "1 x 3\n4 y 6\n")
    assert parse_numeric(r, ["a", "c"], delimiter=None, usecols=[0, 2], ncols=3).tolist() == \
        [[1, 3], [4, 6]]


def test_check_finite_first_bad_cell():
    v = np.array([[1.0, 2.0], [3.0, np.inf], [np.nan, 1.0]])
    with pytest.raises(InvalidValueError) as e:
        check_finite(v, ["a", "b"], np.array([5, 7, 9]), "f")
    assert (e.value.row, e.value.column, e.value.found) == (7, "b", "inf")


def test_time_order_backwards_and_duplicates():
    rows = np.array([2, 3, 4, 5, 6])
    with pytest.raises(TimeOrderError) as e:
        check_time_order(np.array([0.0, 1.0, 2.0, 1.5, 3.0]), rows, "f")
    assert e.value.row == 5 and e.value.column == "time" and "row 4" in e.value.expected
    t = np.array([0.0, 1.0, 1.0, 2.0, 2.0])
    with pytest.warns(InsgnssWarning, match="duplicated"):
        keep, dropped = check_time_order(t, rows, "f")
    assert keep.tolist() == [True, True, False, True, False]
    assert dropped == [{"row": 4, "time": 1.0}, {"row": 6, "time": 2.0}]
    with pytest.raises(TimeOrderError, match="duplicated") as e:
        check_time_order(t, rows, "f", duplicates="error")
    assert e.value.row == 4
    with pytest.raises(ConfigError):
        check_time_order(t, rows, "f", duplicates="keep")


def test_rate_check():
    t = np.arange(100) * 0.01
    rows = np.arange(100) + 2
    assert check_rate(t, rows, "f", None) == pytest.approx(0.01)
    assert check_rate(t, rows, "f", 100.0) == pytest.approx(0.01)
    assert check_rate(t, rows, "f", 98.0) == pytest.approx(1 / 98.0)  # within 5 %
    with pytest.raises(RateMismatchError) as e:
        check_rate(t, rows, "f", 200.0)
    assert e.value.row == 3 and "100 Hz" in e.value.found
    with pytest.raises(ConfigError):
        check_rate(t, rows, "f", -5)


def test_gaps_policies():
    t = np.concatenate([np.arange(10) * 0.01, 0.09 + 0.5 + np.arange(10) * 0.01,
                        1.0 + 2.0 + np.arange(5) * 0.01])
    rows = np.arange(t.size) + 2
    gaps = find_gaps(t, rows, 0.01)
    assert [g["row"] for g in gaps] == [12, 22]
    assert gaps[0]["duration"] == pytest.approx(0.5) and gaps[0]["missing"] == 49
    with pytest.raises(DataGapError) as e:
        apply_gap_policy(gaps, GapPolicy(), "f", t[0], t[-1])
    assert e.value.row == 22 and e.value.column == "time"
    with pytest.warns(InsgnssWarning) as w:
        rec, segs = apply_gap_policy(gaps, GapPolicy(long="split"), "f", t[0], t[-1])
    assert "1 gap(s) bridged" in str(w[0].message) and "2 segments" in str(w[1].message)
    assert [g["action"] for g in rec] == ["bridged", "split"]
    assert len(segs) == 2 and segs[0] == (t[0], t[19]) and segs[1] == (t[20], t[-1])
    with pytest.warns(InsgnssWarning):
        rec, segs = apply_gap_policy(gaps, GapPolicy(long="bridge"), "f", t[0], t[-1])
    assert [g["action"] for g in rec] == ["bridged", "bridged"] and len(segs) == 1
    # 1.5 nominal intervals is the threshold
    assert find_gaps(np.array([0, 0.01, 0.0249, 0.035]), np.arange(4), 0.01) == []
    assert len(find_gaps(np.array([0, 0.01, 0.0251, 0.035]), np.arange(4), 0.01)) == 1


def test_split_segments():
    df = pd.DataFrame({"a": np.arange(6.0)}, index=[0.0, 1.0, 2.0, 10.0, 11.0, 12.0])
    df.attrs["segments"] = [(0.0, 2.0), (10.0, 12.0)]
    parts = split_segments(df)
    assert [p.index.tolist() for p in parts] == [[0.0, 1.0, 2.0], [10.0, 11.0, 12.0]]


@pytest.mark.parametrize("bad", [dict(long="stop"), dict(factor=1.0), dict(max_bridge=-1)])
def test_gap_policy_rejects(bad):
    with pytest.raises(ConfigError):
        GapPolicy(**bad)


def _still_imu(n=400, seed=1):
    rng = np.random.default_rng(seed)
    gyro = rng.normal(0, 0.003, (n, 3)) + [0.0, 0.0, 0.05]
    accel = np.array([0.1, 0.2, G0]) + rng.normal(0, 0.03, (n, 3))
    return gyro, accel


def test_unit_checks_accept_plausible_data():
    gyro, accel = _still_imu()
    rows = np.arange(len(gyro)) + 2
    kw = dict(gyro_names=["gx", "gy", "gz"], accel_names=["ax", "ay", "az"], gyro_unit="rad/s",
              accel_unit="m/s^2")
    check_imu_units(gyro, accel, rows, "f", **kw)
    # a fast spin with large accelerations (foot swing) is not "still": accepted
    gyro2 = gyro.copy()
    gyro2[::2] += 6.0
    accel2 = accel.copy()
    accel2[::2] += 8.0
    check_imu_units(gyro2, accel2, rows, "f", **kw)


def test_unit_checks_reject_g_and_deg_s():
    gyro, accel = _still_imu()
    rows = np.arange(len(gyro)) + 2
    kw = dict(gyro_names=["gx", "gy", "gz"], accel_names=["ax", "ay", "az"], gyro_unit="rad/s",
              accel_unit="m/s^2")
    with pytest.raises(UnitError, match="look like g") as e:
        check_imu_units(gyro, accel / G0, rows, "f", **kw)
    assert e.value.row == 2 and e.value.column == "az"
    with pytest.raises(UnitError, match="deg/s declared as rad/s") as e:
        check_imu_units(np.degrees(gyro), accel, rows, "f", **kw)
    assert e.value.column == "gz"
    big = gyro.copy()
    big[7, 1] = 150.0
    with pytest.raises(UnitError) as e:
        check_imu_units(big, accel, rows, "f", **kw)
    assert (e.value.row, e.value.column) == (9, "gy")


def test_span_policies():
    t = np.array([5.0, 10.0, 11.0, 12.0, 30.0])
    rows = np.array([3, 4, 5, 6, 7])
    with pytest.warns(InsgnssWarning, match="outside"):
        keep, rec = check_span(t, rows, "g.pos", 9.0, 20.0)
    assert keep.tolist() == [False, True, True, True, False]
    assert [r["row"] for r in rec] == [3, 7]
    with pytest.raises(TimeOrderError) as e:
        check_span(t, rows, "g.pos", 9.0, 20.0, policy="error")
    assert e.value.row == 3
    with pytest.raises(TimeOrderError, match="no epoch inside") as e:
        check_span(t, rows, "g.pos", 100.0, 200.0)
    assert e.value.row == 3 and e.value.file == "g.pos"


def test_check_gnss_in_imu_span_trims_and_keeps_rows():
    imu = pd.DataFrame({"a": np.zeros(3)}, index=[10.0, 11.0, 12.0])
    gnss = pd.DataFrame({"lat": np.zeros(4)}, index=[9.0, 10.5, 11.5, 13.0])
    gnss.attrs.update(source="g.pos", source_rows=np.array([4, 5, 6, 7]), time_column="GPST")
    with pytest.warns(InsgnssWarning):
        out = check_gnss_in_imu_span(gnss, imu)
    assert out.index.tolist() == [10.5, 11.5]
    assert out.attrs["source_rows"].tolist() == [5, 6]
    assert [r["row"] for r in out.attrs["outside_imu_span"]] == [4, 7]
    with pytest.raises(TimeOrderError) as e:
        check_gnss_in_imu_span(gnss, imu, policy="error")
    assert (e.value.file, e.value.row, e.value.column) == ("g.pos", 4, "GPST")


def test_ensure_not_input(tmp_path):
    a = tmp_path / "in.csv"
    a.write_text("x")
    with pytest.raises(ConfigError, match="input") as e:
        ensure_not_input(tmp_path / "." / "in.csv", [None, a])
    assert e.value.file.endswith("in.csv")
    link = tmp_path / "link.csv"
    link.symlink_to(a)
    with pytest.raises(ConfigError):
        ensure_not_input(link, [a])
    assert ensure_not_input(tmp_path / "out.csv", [a]) == tmp_path / "out.csv"


def test_error_hierarchy():
    for cls in (InputFormatError, InvalidValueError, TimeOrderError, DataGapError, UnitError,
                RateMismatchError, ConfigError):
        assert issubclass(cls, InsgnssError)
    w = InsgnssWarning("gap bridged", file="a.csv", row=3, column="time", found="0.5 s")
    assert str(w) == "a.csv, row 3, column 'time': gap bridged, found 0.5 s"
    assert issubclass(InsgnssWarning, UserWarning)


def test_timestamp_jitter_is_not_a_gap():
    """A logger stamping with a millisecond counter (the rtklibexplorer walk: 6, 7, 8 and 9 ms
    intervals, 9 ms being 1.5 median intervals) has no gap; a lost sample in it still is one."""
    rng = np.random.default_rng(3)
    d = rng.choice([6e-3, 7e-3, 8e-3, 9e-3], size=5000, p=[0.68, 0.11, 0.17, 0.04])
    d[2000] = 18e-3  # one lost sample (two intervals of 9 ms)
    t = np.concatenate([[0.0], np.cumsum(d)])
    gaps = find_gaps(t, np.arange(t.size) + 1, float(np.median(d)))
    assert [g["row"] for g in gaps] == [2002]
    assert gaps[0]["missing"] == 2  # from the 6.6 ms mean interval, not the 6 ms median
    # a declared 6 ms rate: the same
    assert len(find_gaps(t, np.arange(t.size) + 1, 6e-3)) == 1
    # a clean clock keeps the 1.5-interval rule
    t2 = np.arange(1000) * 0.01
    t2[500:] += 0.006
    assert len(find_gaps(t2, np.arange(t2.size), 0.01)) == 1
    t2[500:] -= 0.002
    assert find_gaps(t2, np.arange(t2.size), 0.01) == []
