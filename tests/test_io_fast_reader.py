"""The fast reader (:func:`insgnss.validate.read_rows`, pyarrow) against the validating path.

A clean file must give exactly the tables the validating path gives (same floats, same line
numbers, same attrs); any damaged file must give exactly the same error (type and message:
file, line, column, expected, found) or the same table, whichever path parses it. Each
comparison runs a reader twice: as is, and with the fast path switched off. Every test runs
twice: with the file read whole, and read and parsed in small line-aligned blocks (the path of
a file larger than ``validate.READ_BLOCK``).
"""

from __future__ import annotations

import random
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from io_helpers import imu_csv_text, imu_rows, raw_imu_text, tag_bytes
from test_io_tracks import traj

import insgnss.validate as validate
from insgnss.errors import InsgnssError
from insgnss.io import read_imu_csv, read_rtklibexplorer_imu, read_trajectory_csv
from insgnss.io.tracks import write_trajectory_csv


@pytest.fixture(autouse=True, params=["whole", "blocks"])
def read_block(request, monkeypatch):
    """Files read whole (the default block is far above these files) or in 700-byte blocks."""
    if request.param == "blocks":
        monkeypatch.setattr(validate, "READ_BLOCK", 700)
    return request.param


@pytest.fixture
def slow(monkeypatch):
    """A context switch: ``with slow(): ...`` reads through the validating path only."""
    import contextlib

    @contextlib.contextmanager
    def off():
        with monkeypatch.context() as m:
            m.setattr(validate, "_clean_rows", lambda *a, **k: None)
            yield

    return off


def outcome(read, path):
    """What a reader gives: ('error', type, message) or ('table', frame, attrs, warnings)."""
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        try:
            df = read(path)
        except InsgnssError as e:
            return ("error", type(e).__name__, str(e))
    attrs = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in df.attrs.items()}
    return ("table", df, attrs, [str(x.message) for x in w])


def same(a, b) -> None:
    assert a[0] == b[0], (a, b)
    if a[0] == "error":
        assert a == b
        return
    pd.testing.assert_frame_equal(a[1], b[1], check_exact=True)
    assert a[2] == b[2]
    assert a[3] == b[3]


def test_clean_native_file_takes_the_fast_path_and_matches(tmp_path, slow):
    p = tmp_path / "t.csv"
    df = traj(200)
    df.loc[df.index[3], "roll"] = np.nan  # a NaN in a column that may have one
    write_trajectory_csv(df, p)
    text = p.read_text()
    # comments and blank lines before the header count for the line numbers
    p.write_text("# insgnss trajectory\n\n# units: rad, m\n" + text.replace(",nan,", ",,", 1))
    rows = validate.read_rows(p, comment=("#",), header=True)
    assert rows.table is not None and rows.table_empty
    assert rows.header_line == 4 and rows.line_no[0] == 5 and rows.line_no[-1] == 204
    fast = outcome(read_trajectory_csv, p)
    with slow():
        ref = outcome(read_trajectory_csv, p)
    same(fast, ref)
    assert fast[0] == "table" and np.isnan(fast[1]["roll"].iloc[3])
    assert fast[2]["source_rows"][:2] == [5, 6]


def test_floats_round_correctly_like_numpy(tmp_path, slow):
    """17 significant digits, subnormals, huge exponents, signs: identical bits."""
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.normal(0, 1, 300) * 10.0 ** rng.integers(-300, 300, 300),
                        [5e-324, -2.2250738585072014e-308, 1.7976931348623157e308, -0.0]])
    t = np.arange(x.size, dtype=float)
    lines = ["time,lat,lon,height"] + [f"{a!r},{b:.17g},{b:.17e},{c}" for a, b, c in
                                       zip(t.tolist(), x.tolist(), (x[::-1] * 1e-300).tolist(),
                                           strict=True)]
    p = tmp_path / "f.csv"
    p.write_text("\n".join(lines) + "\n")
    rows = validate.read_rows(p, comment=("#",), header=True)
    assert rows.table is not None
    with slow():
        ref = validate.parse_numeric(validate.read_rows(p, comment=("#",), header=True),
                                     ["time", "lat", "lon", "height"], empty_nan=True)
    got = validate.parse_numeric(rows, ["time", "lat", "lon", "height"], empty_nan=True)
    assert got.tobytes() == ref.tobytes()


def test_what_the_fast_path_leaves_to_the_validating_path(tmp_path):
    """Files the fast path does not parse (it returns a TextRows without a table)."""
    good = "time,a,b\n0,1,2\n1,3,4\n"
    cases = {
        "comment in the data": good + "# note\n2,5,6\n",
        "blank line in the data": good + "\n2,5,6\n",
        "blank line at the end": good + "\n\n",
        "lone CR": good.replace("\n", "\r"),
        "nan(...)": good + "2,nan(1),6\n",
        "quoted": good + '2,"5",6\n',
        "whitespace line": good + "   \n2,5,6\n",
        "one column": "time\n0\n1\n",
    }
    for what, text in cases.items():
        p = tmp_path / "x.csv"
        p.write_text(text)
        try:
            rows = validate.read_rows(p, comment=("#",), header=True)
        except InsgnssError:
            continue
        assert rows.table is None, what
    p.write_text(good.replace("\n", "\r\n"))  # Windows line ends are clean
    assert validate.read_rows(p, comment=("#",), header=True).table is not None


def _mutate(text: str, rng: random.Random) -> str:
    lines = text.split("\n")
    for _ in range(rng.randint(1, 3)):
        k = rng.randrange(len(lines))
        op = rng.randrange(9)
        if op == 0:
            del lines[k]
        elif op == 1:
            lines.insert(k, lines[rng.randrange(len(lines))])
        elif op == 2:
            lines.insert(k, rng.choice(["", "   ", "# comment", "%", ",,", "nan,nan"]))
        elif op == 3 and lines[k]:
            i = rng.randrange(len(lines[k]))
            lines[k] = lines[k][:i] + rng.choice("0123456789-+.,eEnaNiIf \t_x#(") + lines[k][i:]
        elif op == 4 and lines[k]:
            i = rng.randrange(len(lines[k]))
            lines[k] = lines[k][:i] + lines[k][i + 1:]
        elif op == 5:
            cells = lines[k].split(",")
            cells[rng.randrange(len(cells))] = rng.choice(["", " ", "nan", "inf", "-inf", "1e999",
                                                           "abc", "1_0", "0x1", " 2 ", "+.5"])
            lines[k] = ",".join(cells)
        elif op == 6:
            lines[k] = lines[k] + "\r"
        elif op == 7:
            lines[k], lines[-1 - k] = lines[-1 - k], lines[k]
        else:
            lines[k] = lines[k][: len(lines[k]) // 2]
    return "\n".join(lines)


def _compare_mutations(tmp_path, slow, read, text, n, seed, name):
    rng = random.Random(seed)
    p = tmp_path / name
    fast_paths = 0
    for _ in range(n):
        p.write_text(_mutate(text, rng))
        fast = outcome(read, p)
        with slow():
            ref = outcome(read, p)
        same(fast, ref)
        fast_paths += fast[0] == "table"
    return fast_paths


def test_damaged_native_files_give_the_same_error_or_table(tmp_path, slow):
    p = tmp_path / "clean.csv"
    write_trajectory_csv(traj(12), p)
    n_ok = _compare_mutations(tmp_path, slow, read_trajectory_csv, p.read_text(), 400, 7,
                              "t.csv")
    assert n_ok > 20  # some mutations leave a valid (often fast-parsed) file


def test_damaged_imu_csv_files_give_the_same_error_or_table(tmp_path, slow):
    t, gyro, accel = imu_rows(40)
    text = imu_csv_text(t, gyro, accel)

    def read(path):
        return read_imu_csv(path, rate_hz=100.0, duplicates="drop")

    n_ok = _compare_mutations(tmp_path, slow, read, text, 400, 11, "imu.csv")
    assert n_ok > 20


def test_damaged_rtklibexplorer_files_give_the_same_error_or_table(tmp_path, slow):
    n = 200
    ms = 1000 + 10 * np.arange(n)
    rng = np.random.default_rng(2)
    text = raw_imu_text(ms, np.array([0.0, 0.0, 1.0]) + rng.normal(0, 0.01, (n, 3)),
                        rng.normal(0, 0.1, (n, 3)))
    (tmp_path / "imu.csv.tag").write_bytes(tag_bytes(1.4e9, np.linspace(0, 10 * (n - 3), 50)
                                                     .round()))  # first and last lines dropped

    def read(path):
        return read_rtklibexplorer_imu(path, mounting_rpy_deg=(0.0, 0.0, 0.0),
                                       tag_path=Path(path).parent / "imu.csv.tag")

    clean = tmp_path / "clean_imu.csv"
    clean.write_text(text)
    (tmp_path / "clean_imu.csv.tag").write_bytes((tmp_path / "imu.csv.tag").read_bytes())
    assert validate.read_rows(clean, comment=(), trim=True).table is not None
    n_ok = _compare_mutations(tmp_path, slow, read, text, 300, 13, "imu.csv")
    assert n_ok > 20


def test_real_drive_inputs_read_identically(drive_dir, slow):
    from insgnss.io import DRIVE_0708

    imu = sorted(drive_dir.glob("imu*.csv"))[0]

    def read(path):
        return read_rtklibexplorer_imu(path, mounting_rpy_deg=DRIVE_0708["mounting_rpy_deg"])

    assert validate.read_rows(imu, comment=(), trim=True).table is not None
    fast = outcome(read, imu)
    with slow():
        ref = outcome(read, imu)
    same(fast, ref)
    assert fast[0] == "table" and len(fast[1]) > 50_000


@pytest.mark.parametrize("seed", range(6))
def test_file_chunks_are_the_file_cut_at_line_ends(tmp_path, seed):
    """``_file_chunks`` (one reused buffer, read with ``readinto``): the chunks joined are the
    asked byte range, each but the last ends a line, lines longer than the block included."""
    rng = random.Random(seed)
    lines = [b"x" * rng.choice([0, 1, 5, 40, 300, 2000]) for _ in range(400)]
    body = b"\n".join(lines) + (b"\n" if seed % 2 else b"")
    p = tmp_path / "f.bin"
    p.write_bytes(body)
    for block in (1, 7, 64, 700, 1 << 20):
        start, stop = rng.randrange(0, 50), len(body) - rng.randrange(0, 50)
        got = [bytes(buf[a:b]) for buf, a, b in validate._file_chunks(p, start, stop, block)]
        assert b"".join(got) == body[start:stop]
        assert all(c.endswith(b"\n") for c in got[:-1])
        assert all(c for c in got)
