"""``insgnss.validate.time_slice``: the rows ``table.loc[start:stop]`` selects, without pandas'
label look-up (which keeps a hash table of the whole index: 22 bytes per row)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pandas as pd
import pytest

from insgnss.validate import time_slice


@pytest.mark.parametrize("bounds", [(None, None), (5.0, None), (None, 7.3), (2.0, 7.0),
                                    (2.01, 6.99), (-5.0, 50.0), (8.0, 2.0), (20.0, 30.0),
                                    (np.nextafter(3.0, np.inf), 3.5)])
def test_same_rows_as_loc(bounds):
    t = np.arange(0.0, 10.0, 0.01)
    df = pd.DataFrame({"a": np.arange(t.size)}, index=t)
    a, b = bounds
    got = time_slice(df, a, b)
    pd.testing.assert_frame_equal(got, df.loc[a:b])
    pd.testing.assert_series_equal(time_slice(df["a"], a, b), df["a"].loc[a:b])


def test_no_index_hash_table():
    t = np.arange(720_001) / 200.0
    df = pd.DataFrame({"a": np.zeros(t.size)}, index=t)
    tracemalloc.start()
    try:
        part = time_slice(df, 5.0, 3000.0)
        kept = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    assert len(part) == 599_001 and kept < 1_000_000  # .loc: 16.9 MB kept with the index
