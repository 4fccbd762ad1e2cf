"""Fuzzing every reader (issue 8): random bytes, truncated files, shuffled rows, mutated cells,
moved/duplicated/deleted lines and random declared options give a clean InsgnssError or a valid
table -- never another exception or a hang.

Each Hypothesis example draws one damage recipe and one set of options and applies them to every
reader's own seed files, so every reader sees ``EXAMPLES`` (2,000) different inputs while the
Hypothesis engine overhead is paid once per example; the files are tiny, and the module runs in
about 20-30 s of CPU."""

from __future__ import annotations

import random
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from io_helpers import (
    T0_GPS,
    gga,
    gst,
    imu_csv_text,
    imu_rows,
    kfgins_imu_text,
    pos_text,
    raw_imu_text,
    rmc,
    tag_bytes,
    trajectory,
    vtg,
)
from test_io_tracks import traj

from insgnss.errors import InsgnssError
from insgnss.imu import ACCEL_COLS, DTHETA_COLS, DV_COLS, GYRO_COLS
from insgnss.io import (
    TimeTag,
    read_imu_csv,
    read_kfgins_gnss,
    read_kfgins_imu,
    read_kfgins_nav,
    read_nmea,
    read_reference,
    read_rtklib_pos,
    read_rtklib_tag,
    read_rtklibexplorer_imu,
    write_kfgins_nav,
    write_trajectory_csv,
)

EXAMPLES = 2000
FUZZ = settings(max_examples=EXAMPLES, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                                       HealthCheck.data_too_large, HealthCheck.filter_too_much])
ALPHABET = list(b"0123456789-+.,eE naNiIf\n\r\t/:x%$*#_") + [0, 255, 0xC3]


KINDS = ("valid", "bytes", "truncate", "shuffle", "mutate", "lines")


@st.composite
def damage(draw) -> tuple:
    """A damage recipe: its kind and either random bytes or a random seed."""
    kind = draw(st.sampled_from(KINDS))
    if kind == "bytes":
        return kind, draw(st.binary(max_size=300))
    return kind, draw(st.integers(0, 2**32 - 1))


def apply(recipe: tuple, seeds: list[bytes], salt: int) -> bytes:
    """Apply a damage recipe to one of ``seeds`` (``salt`` decorrelates the readers)."""
    kind, arg = recipe
    if kind == "bytes":
        return arg
    r = random.Random(arg * 1009 + salt)
    seed = seeds[r.randrange(len(seeds))]
    if kind == "valid":
        return seed
    if kind == "truncate":
        return seed[: r.randint(0, len(seed))]
    lines = seed.split(b"\n")
    if kind == "shuffle":
        r.shuffle(lines)
        return b"\n".join(lines)
    if kind == "lines":
        i, j = r.randrange(len(lines)), r.randrange(len(lines))
        op = r.choice(("delete", "duplicate", "swap", "move"))
        if op == "delete":
            del lines[i]
        elif op == "duplicate":
            lines.insert(i, lines[i])
        elif op == "swap":
            lines[i], lines[j] = lines[j], lines[i]
        else:
            lines.insert(j, lines.pop(i))
        return b"\n".join(lines)
    data = bytearray(seed)
    for _ in range(r.randint(1, 4)):
        data[r.randrange(len(data))] = r.choice(ALPHABET)
    return bytes(data)


def call(reader, path, data: bytes):
    path.write_bytes(data)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return reader(path)
        except InsgnssError as e:
            assert str(e)  # formats without raising
            return None


def check_time(df: pd.DataFrame):
    t = np.asarray(df.index, float)
    assert len(t) >= 1 and np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)
    rows = df.attrs["source_rows"]
    assert len(rows) == len(df) and np.all(np.diff(rows) > 0)


def check_imu(df):
    if df is None:
        return
    assert list(df.columns) in (GYRO_COLS + ACCEL_COLS, DTHETA_COLS + DV_COLS)
    assert np.all(np.isfinite(df.to_numpy())) and len(df) >= 2
    check_time(df)


def check_position(df, std=True):
    if df is None:
        return
    check_time(df)
    llh = df[["lat", "lon", "height"]].to_numpy()
    assert np.all(np.isfinite(llh)) and np.all(np.abs(llh[:, 0]) <= np.pi / 2 + 1e-12)
    if std and "east_std" in df.columns:
        s = df[["east_std", "north_std", "up_std"]].to_numpy()
        assert np.all(np.isfinite(s)) and np.all(s >= 0)


# ------------------------------------------------------------------------------ seeds

def _b(text: str) -> bytes:
    return text.encode()


t_, w_, f_ = imu_rows(25)
IMU_SEEDS = [_b(imu_csv_text(t_, w_, f_, fmt="%.6f")),
             _b(imu_csv_text(t_, np.degrees(w_), f_ / 9.80665, fmt="%.6f"))]
tp, lat, lon, h, vel = trajectory(6)
POS_SEEDS = [_b(pos_text(tp, lat, lon, h, vel=vel)), _b(pos_text(tp, lat, lon, h, time_format="week")),
             _b(pos_text(tp, lat, lon, h, pos="ecef", vel=vel)), _b(pos_text(tp, lat, lon, h, pos="dms"))]
TAG_SEEDS = [tag_bytes(T0_GPS, np.arange(0, 120, 15)), tag_bytes(T0_GPS, np.arange(0, 60, 15), fpos_size=8)]
_ms = 1000 + 10 * np.arange(30)
RAW_SEEDS = [_b(raw_imu_text(_ms, np.tile([0.1, 0.0, 1.0], (30, 1)), np.zeros((30, 3))))]
RAW_TAG = tag_bytes(T0_GPS, np.linspace(0, 270, 10))  # matches the 28 kept rows (270 ms)
_tk = 1000.0 + 0.01 * np.arange(1, 21)
KF_IMU_SEEDS = [_b(kfgins_imu_text(_tk, np.full((20, 3), 1e-5), np.tile([0, 0, -0.098], (20, 1))))]
_g7 = "\n".join(f"{357000 + i:.3f} {30.44 + 1e-6 * i:.9f} 114.47 20.0 0.01 0.01 0.02" for i in range(5))
KF_GNSS_SEEDS = [_b(_g7), _b("\n".join(r + " 1 2 -0.5 0.01 0.02 0.03" for r in _g7.split("\n")))]
TOD = 19 * 3600 + 34 * 60.0
_nav_df = traj(6)
with tempfile.TemporaryDirectory() as _d:
    NAV_SEEDS = [write_kfgins_nav(_nav_df, Path(_d) / "a.nav").read_bytes()]
    CSV_SEEDS = [write_trajectory_csv(_nav_df, Path(_d) / "a.csv").read_bytes()]
NMEA_SEEDS = [_b("\n".join(
    s for k in range(4) for s in (rmc(TOD + k, "080725", 40.1, -105.1, 5.0, 30.0),
                                  gga(TOD + k, 40.1 + 1e-5 * k, -105.1, 1600.0),
                                  gst(TOD + k, 0.01, 0.01, 0.02), vtg(30.0, 9.26))))]


UNITS = [None, "rad/s", "deg/s", "rad", "deg", "m/s^2", "g", "m/s", "s", "ms", "us", "rpm", "", 3, "G"]


@st.composite
def options(draw) -> dict:
    """Declared options: mostly valid (so that the damaged file content is what gets tested),
    one time in four drawn from valid and invalid values alike."""
    anything = draw(st.integers(0, 3)) == 0

    def pick(valid, invalid=()):
        return draw(st.sampled_from(list(valid) + (list(invalid) if anything else [])))

    si = pick([True, False]) if not anything else False
    return {
        "gyro_unit": ("rad/s" if si else "deg/s") if not anything else pick(UNITS),
        "accel_unit": ("m/s^2" if si else "g") if not anything else pick(UNITS),
        "time_unit": pick(["s"], UNITS),
        "rate_hz": pick([None, 100.0], [50.0, -1.0, "x", 0.0]),
        "duplicates": pick(["drop", "error"], ["keep"]),
        "time_base": pick(["gps", "sow", "unix_gpst"], ["utc"]),
        "week": pick([None, 2174], [-1, 1.5]),
        "rpy": pick([(180, 0, 180), (180, -6.79, 185.35)], [(1, 2), "x", (np.nan, 0, 0)]),
        "offset": pick([0.0, -0.125], ["a", float("inf")]),
        "bad_lines": pick(["skip", "error"], ["keep"]),
        "date": pick([None, "2025-07-08"], ["bad"]),
    }


def _imu_csv(path, o):
    kw = {k: o[k] for k in ("gyro_unit", "accel_unit", "time_unit") if o[k] is not None}
    return read_imu_csv(path, rate_hz=o["rate_hz"], duplicates=o["duplicates"], **kw)


def _kfgins_gnss(path, o):
    return read_kfgins_gnss(path, week=o["week"])


def _raw(path, o):
    return read_rtklibexplorer_imu(path, mounting_rpy_deg=o["rpy"], time_offset=o["offset"])


def _tag(path, o):
    tag = read_rtklib_tag(path)
    assert isinstance(tag, TimeTag) and np.isfinite(tag.start) and np.all(np.diff(tag.ticks) >= 0)


def _no_check(result):
    return None


# name, seed files, file name, reader(path, options), check(result)
READERS = [
    ("imu_csv", IMU_SEEDS, "imu.csv", _imu_csv, check_imu),
    ("rtklib_pos", POS_SEEDS, "sol.pos", lambda p, o: read_rtklib_pos(p, time_base=o["time_base"]),
     check_position),
    ("rtklib_tag", TAG_SEEDS, "x.tag", _tag, _no_check),
    ("rtklibexplorer", RAW_SEEDS, "raw.csv", _raw, check_imu),
    ("kfgins_imu", KF_IMU_SEEDS, "imu.txt", lambda p, o: read_kfgins_imu(p, week=o["week"]), check_imu),
    ("kfgins_gnss", KF_GNSS_SEEDS, "gnss.txt", _kfgins_gnss, check_position),
    ("kfgins_nav", NAV_SEEDS, "x.nav", lambda p, o: read_kfgins_nav(p), check_position),
    ("nmea", NMEA_SEEDS, "x.nmea",
     lambda p, o: read_nmea(p, bad_lines=o["bad_lines"], date=o["date"]),
     lambda df: check_position(df, std=False)),
    ("native/reference", CSV_SEEDS, "x.csv", lambda p, o: read_reference(p),
     lambda df: check_position(df, std=False)),
]


def test_every_reader_is_fuzzed_and_valid_seeds_read(tmp_path):
    names = {r[0] for r in READERS}
    assert {"imu_csv", "rtklib_pos", "rtklib_tag", "rtklibexplorer", "kfgins_imu", "kfgins_gnss",
            "kfgins_nav", "nmea", "native/reference"} == names
    opts = {"gyro_unit": None, "accel_unit": None, "time_unit": None, "rate_hz": None,
            "duplicates": "drop", "time_base": "gps", "week": None, "rpy": (180, 0, 180),
            "offset": 0.0, "bad_lines": "skip", "date": None}
    (tmp_path / "raw.csv.tag").write_bytes(RAW_TAG)
    for name, seeds, fname, run, check in READERS:
        for k, seed in enumerate(seeds):
            if name == "imu_csv" and k == 1:
                continue  # the deg/s + g seed is valid only with those units declared
            p = tmp_path / fname
            p.write_bytes(seed)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                check(run(p, opts))


@FUZZ
@given(recipe=damage(), tag_recipe=st.one_of(st.just(("valid", 0)), damage()), opts=options())
def test_fuzz_all_readers(tmp_path, recipe, tag_recipe, opts):
    (tmp_path / "raw.csv.tag").write_bytes(apply(tag_recipe, [RAW_TAG], 99))
    for salt, (name, seeds, fname, run, check) in enumerate(READERS):
        data = apply(recipe, seeds, salt)
        p = tmp_path / fname
        try:
            check(call(lambda q, run=run: run(q, opts), p, data))
        except Exception as e:
            raise AssertionError(f"reader {name} failed on {data!r} with {opts}") from e
