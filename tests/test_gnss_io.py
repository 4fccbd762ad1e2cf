"""Bad input to the raw GNSS readers: missing, empty, garbage, corrupted and truncated files."""

from __future__ import annotations

import warnings

import pytest
from conftest import shared_data

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
