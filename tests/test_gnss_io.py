"""Bad input to the raw GNSS readers: missing, empty, garbage, corrupted and truncated files."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import shared_data
from hypothesis import given, settings
from hypothesis import strategies as st

from insgnss.errors import InputFormatError, InsgnssWarning
from insgnss.gnss import read_rinex_nav, read_rinex_obs, read_ubx


def test_missing_and_empty_files(tmp_path):
    with pytest.raises(InputFormatError, match="not found"):
        read_ubx(tmp_path / "none.ubx")
    (tmp_path / "empty.ubx").write_bytes(b"")
    with pytest.raises(InputFormatError, match="no UBX-RXM-RAWX") as e:
        read_ubx(tmp_path / "empty.ubx")
    assert e.value.file.endswith("empty.ubx")
    (tmp_path / "text.ubx").write_bytes(b"$GNGGA,hello\r\n" * 100)
    with pytest.raises(InputFormatError, match="no UBX-RXM-RAWX"):
        read_ubx(tmp_path / "text.ubx")
    with pytest.raises(InputFormatError, match="not found"):
        read_rinex_obs(tmp_path / "none.obs")
    (tmp_path / "bad.nav").write_text("this is not RINEX\n")
    with pytest.raises(InputFormatError, match="RINEX"):
        read_rinex_nav(tmp_path / "bad.nav")


def test_corrupted_ubx_message_is_skipped_with_a_warning(tmp_path):
    src = shared_data("gnss-imu-rtklibexplorer", "walk_0827", "gnss_1730.ubx")
    data = bytearray(src.read_bytes()[:200_000])
    k = data.index(b"\xb5\x62\x02\x15", 1000)  # a RAWX message
    data[k + 40] ^= 0xFF  # flip a payload byte: checksum error
    (tmp_path / "bad.ubx").write_bytes(bytes(data))
    good = read_ubx_prefix(src, len(data), tmp_path)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        d = read_ubx(tmp_path / "bad.ubx")
    assert any(issubclass(x.category, InsgnssWarning) for x in w)
    assert d.observations.attrs["bad_messages"] >= 1
    assert len(d.epochs) == len(good.epochs) - 1


def read_ubx_prefix(src, n, tmp_path):
    (tmp_path / "good.ubx").write_bytes(src.read_bytes()[:n])
    return read_ubx(tmp_path / "good.ubx")


def ubx_message(cls: int, mid: int, payload: bytes) -> bytes:
    """A UBX frame with its Fletcher checksum."""
    body = bytes([cls, mid]) + len(payload).to_bytes(2, "little") + payload
    a = b = 0
    for x in body:
        a = (a + x) & 0xFF
        b = (b + a) & 0xFF
    return b"\xb5\x62" + body + bytes([a, b])


def synthetic_stream(n_epochs: int = 3) -> bytes:
    """RAWX epochs (GPS L1 + Galileo E1), an SFRBX and a NAV-PVT per epoch, plus NMEA noise."""
    out = b""
    for k in range(n_epochs):
        meas = b""
        for g, sv, pr in ((0, 10, 2.1e7), (2, 7, 2.3e7)):
            meas += (np.array([pr + k], "<f8").tobytes() + np.array([1.1e8], "<f8").tobytes()
                     + np.array([-500.0], "<f4").tobytes()
                     + bytes([g, sv, 0, 0]) + (5000).to_bytes(2, "little")
                     + bytes([45, 3, 1, 5, 7, 0]))
        head = (np.array([408600.0 + k], "<f8").tobytes() + (2381).to_bytes(2, "little")
                + bytes([18, 2, 1, 1, 0, 0]))
        out += ubx_message(0x02, 0x15, head + meas)
        out += ubx_message(0x02, 0x13, bytes([0, 10, 0, 0, 10, 1, 2, 0]) + bytes(40))
        pvt = bytearray(92)
        pvt[0:4] = int((408582.0 + k) * 1000).to_bytes(4, "little")
        pvt[4:6] = (2025).to_bytes(2, "little")
        pvt[6:11] = bytes([8, 28, 17, 30, 0 + k])
        pvt[20], pvt[21], pvt[23] = 3, 1, 20
        out += ubx_message(0x01, 0x07, bytes(pvt)) + b"$GNGGA,garbage*00\r\n"
    return out


def test_synthetic_stream_reads():
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "s.ubx"
        p.write_bytes(synthetic_stream())
        u = read_ubx(p)
    assert len(u.epochs) == 3 and len(u.observations) == 6 and len(u.subframes) == 3
    assert list(u.observations["sat"][:2]) == ["G10", "E07"]
    assert u.observations["pr"].iloc[2] == 2.1e7 + 1
    assert len(u.nav_pvt) == 3
    assert u.nav_pvt.index[0] == pytest.approx(2381 * 604800.0 + 408582.0)


@settings(max_examples=300, deadline=None, database=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from(["flip", "truncate", "insert", "random"]))
def test_fuzz_read_ubx(seed, kind):
    import random
    import tempfile
    from pathlib import Path

    r = random.Random(seed)
    data = bytearray(synthetic_stream())
    if kind == "flip":
        for _ in range(r.randint(1, 5)):
            data[r.randrange(len(data))] = r.randrange(256)
    elif kind == "truncate":
        data = data[:r.randrange(len(data))]
    elif kind == "insert":
        k = r.randrange(len(data))
        data[k:k] = bytes(r.randrange(256) for _ in range(r.randint(1, 40)))
    else:
        data = bytearray(r.randbytes(r.randint(0, 600)))
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "f.ubx"
        p.write_bytes(bytes(data))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", InsgnssWarning)
            try:
                u = read_ubx(p)
            except InputFormatError:
                return
    assert len(u.epochs) >= 1
    assert set(u.observations.columns) >= {"sat", "pr", "doppler", "cn0"}
