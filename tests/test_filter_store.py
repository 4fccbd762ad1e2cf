"""The node store's update rows: the compact (CSR) H, K^T, G and s of each update, growing."""

from __future__ import annotations

import numpy as np

from insgnss.filter.store import NodeStore, dense_rows


def test_update_rows_round_trip_through_the_compact_h_and_grow():
    rng = np.random.default_rng(3)
    n = 15
    store = NodeStore(4, n, 6, rows=8)  # 8 rows, 64 non-zeros: grows during the loop
    written = []
    for k in range(40):
        m = 1 + k % 4
        H = rng.normal(size=(m, n))
        H[rng.random((m, n)) < 0.6] = 0.0
        H[0, 0] = -0.0  # a negative zero is no entry (as np.nonzero)
        if k == 5:
            H[-1, 3] = np.nan  # a NaN is an entry
        K, G, s = rng.normal(size=(n, m)), rng.normal(size=(m, n)), rng.normal(size=m)
        r0 = store.n_rows
        store.add_update(H, K, G, s)
        written.append((r0, H, K, G, s))
    assert store.n_rows == sum(w[1].shape[0] for w in written)
    assert store.H_ptr[store.n_rows] == sum(np.count_nonzero(w[1]) for w in written)
    for r0, H, K, G, s in written:
        m = H.shape[0]
        np.testing.assert_array_equal(dense_rows(store.H_ptr, store.H_col, store.H_val,
                                                 r0, r0 + m, n), np.where(H == 0.0, 0.0, H))
        np.testing.assert_array_equal(store.K[r0:r0 + m], K.T)
        np.testing.assert_array_equal(store.G[r0:r0 + m], G)
        np.testing.assert_array_equal(store.s[r0:r0 + m], s)
        # columns ascending within each row (the CSR order the smoother reads)
        for r in range(r0, r0 + m):
            cols = store.H_col[store.H_ptr[r]:store.H_ptr[r + 1]]
            assert np.all(np.diff(cols) > 0)
