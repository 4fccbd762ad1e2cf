"""What the filter engine stores: the smoother's nodes, the applied updates and the innovation log.

Nodes
-----
A *node* is a time at which the engine keeps the error-state covariance: every filter epoch.
Node ``k`` holds

- ``t[k]``: its time;
- ``Phi[k]``: the error transition from node ``k-1`` to ``k`` (``Phi[0] = I``; kept only
  for the smoother, its only reader);
- ``Pp[k] = P(k|k-1)``: the predicted covariance the updates at ``k`` saw (after a gate
  recovery: the inflated one);
- ``Pf[k] = P(k|k)``: the covariance after the updates;
- ``fb[k]``: the error estimate fed back into (removed from) the nominal at ``k`` (zero
  without update);
- ``par[k]``: the process model's nominal parameters after the feedback (biases, scale
  factors, extra states), for the output tables.

Updates
-------
For each node, the rows ``r0[k] .. r1[k]-1`` of the update arrays describe the (stacked)
update applied there: ``H`` (m, n), the gain ``K`` stored transposed (m, n), ``G = S^-1 H``
(m, n) and ``s = S^-1 z`` (m). With ``Pp``, ``Pf``, ``Phi`` and ``fb`` this is everything the
Rauch-Tung-Striebel form, the modified Bryson-Frazier form (:mod:`.smoother`) and an EM
estimate of the noise parameters need (``R = S - H Pp H^T``).

``H`` is kept compact, by its non-zeros (a ZUPT row selects one velocity state, a ZARU row a
gyro bias and the three attitude states, a GNSS position row three position states): row
``r`` has the columns ``H_col[H_ptr[r]:H_ptr[r+1]]`` (increasing) and the values
``H_val[H_ptr[r]:H_ptr[r+1]]``; :func:`dense_rows` gives the rows as a dense (m, n) array.
``K``, ``G`` and ``s`` are dense (``G`` is written only by updates that keep it: the Python
path, and the compiled path when the smoothed covariances are run).

High-rate samples
-----------------
In a segment run by the compiled high-rate path (:mod:`.highrate`) every IMU sample is a
smoother step, stored compactly (what the backward pass needs, no covariance): the samples
``seg0[k] .. seg1[k]-1`` lie between nodes ``k-1`` and ``k``; sample ``i`` has its time
``hr_t``, IMU row ``hr_row``, ``F dt`` of its interval at the structural non-zeros of the
process model (``hr_F``, ``Phi = I + F dt``), ``Qd`` at its pattern entries (``hr_Q``), the
feedback ``hr_fb`` and its update rows ``hr_r0 .. hr_r1-1``; where a gate recovery inflated
its predicted covariance, that ``P(i|i-1)`` is ``hr_Pp[hr_ppi[i]]``. The covariance of the samples is
written into the forward table by the compiled path; node ``k``'s ``Phi`` and ``Pp`` then refer
to the last high-rate sample before it.

Innovation log
--------------
One record per measurement evaluated (accepted or not): time, type, label, dof, NIS,
threshold, accepted, recovered, the innovation and the square roots of the diagonal of ``S``.
The label names the row of a model that gives many measurements at one epoch (``row_label``:
the satellite of a pseudorange or Doppler); it is empty otherwise.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..aot import entry
from ..jit import njit

__all__ = ["NodeStore", "InnovationLog", "Table", "dense_rows", "innovation_tables",
           "select_rows", "solution_table"]


def dense_rows(H_ptr, H_col, H_val, r0: int, r1: int, n: int) -> np.ndarray:
    """The update rows ``r0 .. r1-1`` of a compact ``H`` (module docstring, "Updates") as a
    dense (r1 - r0, n) array; ``FilterResult.updates`` holds ``H_ptr``, ``H_col``, ``H_val``:
    ``dense_rows(u["H_ptr"], u["H_col"], u["H_val"], r0, r1, n)``."""
    out = np.zeros((r1 - r0, n))
    for r in range(r0, r1):
        a, b = int(H_ptr[r]), int(H_ptr[r + 1])
        out[r - r0, H_col[a:b]] = H_val[a:b]
    return out


@entry
@njit(cache=True)
def _append_rows(H, K, G, s, r, H_ptr, H_col, H_val, K_out, G_out, s_out):
    """Write update rows ``r .. r+m-1``: the non-zeros of ``H`` row by row, columns
    ascending (the CSR order; a zero, also -0.0, is left out as by ``np.nonzero``), ``K^T``,
    ``G`` and ``s``. One compiled call instead of the nonzero / gather / bincount / cumsum and
    three slice copies of an update (their Python overhead, at every epoch)."""
    m, n = H.shape
    nz = H_ptr[r]
    for i in range(m):
        for j in range(n):
            v = H[i, j]
            if v != 0.0:
                H_col[nz] = j
                H_val[nz] = v
                nz += 1
        H_ptr[r + i + 1] = nz
        for j in range(n):
            K_out[r + i, j] = K[j, i]
            G_out[r + i, j] = G[i, j]
        s_out[r + i] = s[i]


class NodeStore:
    """Preallocated node arrays (capacity ``cap``), the high-rate samples (capacity
    ``cap_hr``; F and Qd at ``nnz`` and ``nq`` pattern entries) and growable update rows.

    ``allocate(shape, dtype)`` makes the large arrays (covariances, transitions, update
    rows, high-rate samples; default :func:`numpy.empty`): a job passes
    :class:`insgnss.io.spill.SpillAllocator`, which maps them to a file beyond a memory
    limit (``[filter] store_memory_mb``). ``transitions=False`` (a run without the smoother,
    the only reader of ``Phi``): no ``Phi`` is kept (``None``), a third less to write per node."""

    def __init__(self, cap: int, n: int, n_par: int, cap_hr: int = 0, nnz: int = 0,
                 nq: int = 0, rows: int = 64, allocate=None, transitions: bool = True):
        self.n = n
        self._allocate = alloc = np.empty if allocate is None else allocate
        self.t = np.empty(cap)
        self.Pf = alloc((cap, n, n), float)
        self.Pp = alloc((cap, n, n), float)
        self.Phi = alloc((cap, n, n), float) if transitions else None
        self.fb = alloc((cap, n), float)
        self.fb[:] = 0.0
        self.par = alloc((cap, n_par), float)
        self.r0 = np.zeros(cap, np.int64)  # update rows of node k: r0[k] .. r1[k]-1
        self.r1 = np.zeros(cap, np.int64)
        self.seg0 = np.zeros(cap, np.int64)  # high-rate samples before node k: seg0 .. seg1-1
        self.seg1 = np.zeros(cap, np.int64)
        self.count = 0  # nodes written
        self.hr_t = np.empty(cap_hr)
        self.hr_row = np.empty(cap_hr, np.int64)
        self.hr_F = alloc((cap_hr, nnz), float)
        self.hr_Q = alloc((cap_hr, nq), float)
        self.hr_fb = alloc((cap_hr, n), float)
        self.hr_r0 = np.zeros(cap_hr, np.int64)
        self.hr_r1 = np.zeros(cap_hr, np.int64)
        self.hr_ppi = np.full(cap_hr, -1, np.int64)  # gate recovery: index into hr_Pp
        self.hr_Pp = np.empty((0, n, n))
        self.hr_count = 0
        self._alloc_rows(max(rows, 8))
        self.n_rows = 0

    def _alloc_rows(self, cap, cap_nz=None):
        """Room for ``cap`` update rows and ``cap_nz`` non-zeros of ``H`` (default: the present
        room for them, at least 8 per row)."""
        n = self.n
        old = getattr(self, "K", None)
        if cap_nz is None:
            cap_nz = max(8 * cap, self.H_col.shape[0] if old is not None else 0)
        alloc = self._allocate
        K, G, s = alloc((cap, n), float), alloc((cap, n), float), alloc((cap,), float)
        H_ptr = np.zeros(cap + 1, np.int64)
        if old is not None:
            r = self.n_rows
            K[:r], G[:r], s[:r] = self.K[:r], self.G[:r], self.s[:r]
            H_ptr[:r + 1] = self.H_ptr[:r + 1]
        self.K, self.G, self.s, self.H_ptr = K, G, s, H_ptr
        self._alloc_nz(cap_nz)

    def _alloc_nz(self, cap_nz):
        """Room for ``cap_nz`` non-zeros of ``H`` (columns int32, values float)."""
        old = getattr(self, "H_col", None)
        alloc = self._allocate
        H_col, H_val = alloc((cap_nz,), np.int32), alloc((cap_nz,), float)
        if old is not None:
            nz = int(self.H_ptr[self.n_rows])
            H_col[:nz], H_val[:nz] = self.H_col[:nz], self.H_val[:nz]
        self.H_col, self.H_val = H_col, H_val

    def reserve_rows(self, extra: int, extra_nz: int | None = None) -> None:
        """Make room for ``extra`` more update rows with ``extra_nz`` non-zeros of ``H`` in all
        (default: every row full, ``extra * n``)."""
        need = self.n_rows + extra
        if need > self.K.shape[0]:
            self._alloc_rows(max(need, self.K.shape[0] + self.K.shape[0] // 2))
        need_nz = int(self.H_ptr[self.n_rows]) + (extra * self.n if extra_nz is None
                                                  else extra_nz)
        if need_nz > self.H_col.shape[0]:
            self._alloc_nz(max(need_nz, self.H_col.shape[0] + self.H_col.shape[0] // 2))

    def add_hr_predicted(self, h: int, Pp) -> None:
        """Keep ``P(i|i-1)`` of high-rate sample ``h`` (inflated by a gate recovery)."""
        self.hr_ppi[h] = self.hr_Pp.shape[0]
        self.hr_Pp = np.concatenate([self.hr_Pp, np.asarray(Pp, float)[None]])

    def open(self, k: int) -> None:
        """Start node ``k``: its update rows follow."""
        self.r0[k] = self.n_rows

    def add_update(self, H, K, G, s) -> None:
        """Append the rows of one (stacked) update to the node being written."""
        m = H.shape[0]
        H = np.asarray(H, float)
        self.reserve_rows(m, int(np.count_nonzero(H)))
        r = self.n_rows
        _append_rows(H, np.asarray(K, float), np.asarray(G, float), np.asarray(s, float), r,
                     self.H_ptr, self.H_col, self.H_val, self.K, self.G, self.s)
        self.n_rows = r + m

    def close(self, k: int, t: float, Phi, Pp, Pf, fb, par) -> None:
        """Write node ``k``."""
        self.t[k] = t
        if self.Phi is not None:
            self.Phi[k] = Phi
        self.Pp[k] = Pp
        self.Pf[k] = Pf
        if fb is None:
            self.fb[k] = 0.0
        else:
            self.fb[k] = fb
        self.par[k] = par
        self.r1[k] = self.n_rows
        self.seg1[k] = self.hr_count
        if k + 1 < self.seg0.size:
            self.seg0[k + 1] = self.hr_count
        self.count = k + 1


class InnovationLog:
    """Innovation records of both update paths, in processing order."""

    def __init__(self, names: list[str]):
        self.names = list(names)
        self.labels = [""]  # label id -> label (0: none)
        self._label_id = {"": 0}
        self._rows: list = []  # Python path: (time, tid, dof, nis, thr, accepted, recovered, z, S,
        #                                      label id)
        self._chunks: list = []  # flushed blocks (dicts of arrays)

    def add(self, time, tid, nis, thr, accepted, recovered, z, S, label: str = "") -> None:
        lid = self._label_id.get(label)
        if lid is None:
            lid = self._label_id[label] = len(self.labels)
            self.labels.append(label)
        self._rows.append((time, tid, z.size, nis, thr, accepted, recovered, z, S, lid))

    def _flush(self) -> None:
        if not self._rows:
            return
        rows = self._rows
        dof = np.array([r[2] for r in rows], np.int64)
        m = int(dof.max())
        innov = np.full((len(rows), m), np.nan)
        std = np.full((len(rows), m), np.nan)
        for d in np.unique(dof).tolist():  # the rows of each size at once
            if d == 0:
                continue
            idx = np.flatnonzero(dof == d)
            innov[idx, :d] = np.array([rows[i][7] for i in idx.tolist()], float).reshape(-1, d)
            S = np.array([rows[i][8] for i in idx.tolist()], float).reshape(-1, d, d)
            dg = np.diagonal(S, axis1=1, axis2=2)
            std[idx, :d] = np.where(dg >= 0, np.sqrt(np.abs(dg)), np.nan)
        self._chunks.append({
            "time": np.array([r[0] for r in rows], float),
            "tid": np.array([r[1] for r in rows], np.int64),
            "dof": dof,
            "nis": np.array([r[3] for r in rows], float),
            "threshold": np.array([r[4] for r in rows], float),
            "accepted": np.array([r[5] for r in rows], bool),
            "recovered": np.array([r[6] for r in rows], bool),
            "lid": np.array([r[9] for r in rows], np.int64),
            "innov": innov, "innov_std": std})
        self._rows = []

    def add_block(self, block: dict) -> None:
        """Append a block of records from the compiled path (the keys of the flushed ones;
        without ``lid`` the records have no label)."""
        self._flush()
        if block["time"].size:
            if "lid" not in block:
                block = dict(block, lid=np.zeros(block["time"].size, np.int64))
            self._chunks.append(block)

    def columns(self) -> dict:
        """All records as arrays (``innov`` / ``innov_std`` padded with NaN)."""
        self._flush()
        keys = ("time", "tid", "dof", "nis", "threshold", "accepted", "recovered", "lid")
        if not self._chunks:
            out = {k: np.empty(0) for k in keys}
            out["innov"] = out["innov_std"] = np.empty((0, 0))
            return out
        if len(self._chunks) == 1:
            return dict(self._chunks[0])
        out = {k: np.concatenate([c[k] for c in self._chunks]) for k in keys}
        m = max(c["innov"].shape[1] for c in self._chunks)
        for k in ("innov", "innov_std"):
            parts = []
            for c in self._chunks:
                a = c[k]
                if a.shape[1] < m:
                    a = np.hstack([a, np.full((a.shape[0], m - a.shape[1]), np.nan)])
                parts.append(a)
            out[k] = np.concatenate(parts)
        return out


def innovation_tables(log: InnovationLog | None, c: dict | None = None
                      ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Innovation table (``time type label dof nis threshold accepted recovered innov_k
    innov_std_k``) and its rejected rows (``c``: :meth:`InnovationLog.columns` with the
    ``names`` and ``labels`` lists, or None to take them from ``log``)."""
    if c is None:
        c = dict(log.columns(), names=list(log.names), labels=list(log.labels))
    m = c["innov"].shape[1]
    names = np.array(list(c["names"]) + [""], dtype=object)
    labels = np.array(c["labels"], dtype=object)
    cols = {"time": c["time"], "type": names[c["tid"].astype(np.int64)] if c["tid"].size
            else np.empty(0, object),
            "label": labels[c["lid"].astype(np.int64)] if c["lid"].size else np.empty(0, object),
            "dof": c["dof"].astype(np.int64), "nis": c["nis"], "threshold": c["threshold"],
            "accepted": c["accepted"].astype(bool), "recovered": c["recovered"].astype(bool)}
    for k in range(m):
        cols[f"innov_{k}"] = c["innov"][:, k]
    for k in range(m):
        cols[f"innov_std_{k}"] = c["innov_std"][:, k]
    innovations = pd.DataFrame(cols)
    acc = cols["accepted"]
    rejected = (innovations.iloc[np.flatnonzero(~acc)].reset_index(drop=True) if not acc.all()
                else innovations.iloc[:0])
    return innovations, rejected


class Table:
    """An IMU-rate output table held as arrays (``time`` (N,), ``values`` (N, C), ``columns``):
    the DataFrame is built on the first call of :meth:`frame`, so callers that read the arrays
    (the foot-mounted INS, its threshold selection, the job's writers and evaluation) never pay
    for it.

    ``values`` may lie on a memory-mapped file (:mod:`insgnss.io.spill`, beyond ``[filter]
    store_memory_mb``): :meth:`take` and :meth:`blocks` then read it block by block and give
    each block's pages back after use, so a whole-log table is never resident at once."""

    def __init__(self, time: np.ndarray, values: np.ndarray, columns: list[str]):
        self.time, self.values, self.columns = time, values, list(columns)
        self._frame: pd.DataFrame | None = None

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def frame(self) -> pd.DataFrame:
        if self._frame is None:
            self._frame = pd.DataFrame(self.values, index=pd.Index(self.time, name="time"),
                                       columns=self.columns, copy=False)
        return self._frame

    def blocks(self, start: int = 0, stop: int | None = None):
        """Row ranges ``(i, j)`` of about :data:`insgnss.io.spill.BLOCK_BYTES` (those holding a
        row of ``start .. stop-1``: :func:`insgnss.io.spill.blocks`); the pages of a mapped
        block are given back when the next one is asked for."""
        from ..io.spill import blocks, release

        for i, j in blocks(len(self), self.values[:1].nbytes or 8, start=start, stop=stop):
            yield i, j
            release(self.values, i, j)

    def take(self, rows: np.ndarray | None = None, columns=None) -> pd.DataFrame:
        """The rows ``rows`` (sorted row numbers; None: all) and ``columns`` (names; None:
        all) as a DataFrame in memory, read block by block (:meth:`blocks`); the table's own
        frame when it has been built and everything is asked for."""
        cols = self.columns if columns is None else [c for c in self.columns if c in columns]
        if rows is None and columns is None and self._frame is not None:
            return self._frame
        idx = [self.columns.index(c) for c in cols]
        full = idx == list(range(len(self.columns)))
        rows = None if rows is None else np.asarray(rows, np.int64)
        out = np.empty((len(self) if rows is None else rows.size, len(idx)))
        # the blocks the rows lie in only: a few rows of a long log visit one or two
        span = (0, None) if rows is None else \
            ((int(rows[0]), int(rows[-1]) + 1) if rows.size else (0, 0))
        for i, j in self.blocks(*span):
            a, b = (i, j) if rows is None else np.searchsorted(rows, (i, j))
            if b > a:
                out[a:b] = self._gather(i, j, None if rows is None else rows[a:b], idx, full)
        t = self.time.copy() if rows is None else self.time[rows]
        return pd.DataFrame(out, index=pd.Index(t, name="time"), columns=cols, copy=False)

    def _gather(self, i: int, j: int, r, idx: list[int], full: bool) -> np.ndarray:
        """Rows ``r`` (sorted, within ``i .. j-1``; None: all of them) of block ``(i, j)`` at
        the columns ``idx`` (``full``: all): only the asked columns are gathered."""
        if r is None:
            return self.values[i:j] if full else self.values[i:j][:, idx]
        return self.values[r] if full else self.values[np.ix_(r, idx)]


class RowSegments:
    """The node of every IMU-rate row (``seg``: ``e >= 0``, or ``-1 - i`` for high-rate
    sample ``i``) and its post-feedback flag (``post``), held compactly and exactly.

    Rows of one node are consecutive and so are a high-rate segment's samples (whose values
    fall by one per row), so ``seg`` is a few runs of ``k = seg[j]`` (a node) or
    ``k = seg[j] + j`` (high-rate rows); ``post`` is true at one row per node at most. Kept
    as the runs' first rows and keys and the rows where ``post`` is true: about 24 bytes per
    node instead of 5 bytes per IMU row (36 MiB at 10 h / 200 Hz, which the smoothed table's
    assembly would otherwise keep after the run). :meth:`rows` gives back exactly the
    arrays' values."""

    def __init__(self, seg: np.ndarray, post: np.ndarray, n_rows: int):
        from ..io.spill import blocks

        self.dtype = seg.dtype
        starts, keys, hrs, posts = [], [], [], []
        prev = None
        for i, j in blocks(n_rows, 16, 1 << 20):
            s = seg[i:j].astype(np.int64)
            hr = s < 0
            k = np.where(hr, s + np.arange(i, j), s)
            new = np.empty(j - i, bool)
            new[0] = prev is None or (k[0], hr[0]) != prev
            new[1:] = (k[1:] != k[:-1]) | (hr[1:] != hr[:-1])
            at = np.flatnonzero(new)
            starts.append(at + i)
            keys.append(k[at])
            hrs.append(hr[at])
            posts.append(np.flatnonzero(post[i:j]) + i)
            prev = (k[-1], hr[-1])

        def cat(parts, dt):
            return np.concatenate(parts) if parts else np.zeros(0, dt)

        self.starts, self.keys = cat(starts, np.int64), cat(keys, np.int64)
        self.hr, self.post_rows = cat(hrs, bool), cat(posts, np.int64)

    def edges(self, i: int, j: int) -> np.ndarray:
        """The rows of ``i .. j-1`` where a run starts or ends: each run is constant or moves
        by one per row, so the nodes and high-rate samples of the rows between lie within
        those of these rows."""
        a, b = np.searchsorted(self.starts, (i + 1, j))
        s = self.starts[a:b]
        return np.unique(np.concatenate([[i, j - 1], s, s - 1]))

    def rows(self, rows) -> tuple[np.ndarray, np.ndarray]:
        """``(seg[rows], post[rows])`` for a slice or sorted row numbers."""
        if isinstance(rows, slice):
            rows = np.arange(rows.start, rows.stop)
        rows = np.asarray(rows, np.int64)
        r = np.searchsorted(self.starts, rows, side="right") - 1
        seg = np.where(self.hr[r], self.keys[r] - rows, self.keys[r]).astype(self.dtype)
        if not self.post_rows.size:
            return seg, np.zeros(rows.size, bool)
        p = np.minimum(np.searchsorted(self.post_rows, rows), self.post_rows.size - 1)
        return seg, self.post_rows[p] == rows


class AssembledTable(Table):
    """A :class:`Table` whose rows are formed when they are read: ``assemble(index, out,
    columns=None)`` writes the rows ``index`` (a slice or sorted row numbers) into ``out``
    (rows, columns): every column, or at least the column numbers ``columns`` when they are
    given (:meth:`take` of a few columns; the process model may then form only those).

    :meth:`take` forms only the rows asked for, block by block (:data:`insgnss.io.spill.
    BLOCK_BYTES` of rows at a time, ``release(i, j)`` called after each block so that mapped
    inputs give their pages back), without ever holding the whole table: the smoothed
    IMU-rate table of a 1 h / 200 Hz log (720,000 x 43 values, 236 MiB written to a mapped
    file) is read by the evaluation at the reference epochs and by the writers at the output
    rate only. :attr:`values` (and :meth:`frame`) form the whole table on first use, in an
    array of ``allocate``, and keep it."""

    def __init__(self, time: np.ndarray, columns: list[str], assemble, *, allocate=np.empty,
                 release=None):
        self.time, self.columns = time, list(columns)
        self._frame: pd.DataFrame | None = None
        self._assemble, self._allocate = assemble, allocate
        self._release = release or (lambda i, j: None)
        self._values: np.ndarray | None = None

    @property
    def values(self) -> np.ndarray:
        if self._values is None:
            from ..io.spill import release

            out = self._allocate((len(self), len(self.columns)), float)
            for i, j in self._row_blocks():
                self._assemble(slice(i, j), out[i:j])
                self._release(i, j)
                release(out, i, j)
            self._values = out
        return self._values

    def _row_blocks(self, start: int = 0, stop: int | None = None):
        from ..io.spill import blocks

        return blocks(len(self), 8 * max(len(self.columns), 1), start=start, stop=stop)

    def blocks(self, start: int = 0, stop: int | None = None):
        if self._values is not None:
            yield from super().blocks(start, stop)
        else:
            yield from self._row_blocks(start, stop)

    def _gather(self, i: int, j: int, r, idx: list[int], full: bool) -> np.ndarray:
        if self._values is not None:
            return super()._gather(i, j, r, idx, full)
        if r is None:
            sel = slice(i, j)
        else:  # consecutive rows (the evaluation's): a slice, no gathered copies of the inputs
            sel = slice(int(r[0]), int(r[-1]) + 1) if r[-1] - r[0] + 1 == r.size else r
        block = np.empty((j - i if r is None else r.size, len(self.columns)))
        self._assemble(sel, block, None if full else idx)  # the model may form only those
        self._release(i, j)
        return block if full else block[:, idx]


def solution_table(result, name: str):
    """The ``forward`` or ``smoothed`` table of a filter result as it is held: a
    :class:`Table` (arrays, possibly memory-mapped) where the result keeps one
    (``FilterResult.forward_table``), else its DataFrame (or None)."""
    tab = getattr(result, f"{name}_table", None)
    return tab if tab is not None else getattr(result, name, None)


def select_rows(table, rows_of, columns=None) -> pd.DataFrame | None:
    """A DataFrame of the rows ``rows_of(times)`` (sorted row numbers, or None for all) of a
    solution table (:func:`solution_table`) and its ``columns`` (None: all). A :class:`Table`
    is read in blocks into memory; every row of a memory-mapped table gives its frame on the
    mapping instead of a copy (a DataFrame is sliced as it is)."""
    if table is None:
        return None
    if isinstance(table, Table):
        rows = rows_of(table.time)
        if rows is None and columns is None:
            return table.frame()
        return table.take(rows, columns)
    rows = rows_of(table.index.to_numpy(float))
    df = table if rows is None else \
        _take_mapped(table, rows) if _on_mapping(table) else table.iloc[rows]
    return df if columns is None else df[[c for c in df.columns if c in columns]]


def _on_mapping(df: pd.DataFrame) -> bool:
    """Whether the columns of ``df`` lie on a memory-mapped file (a long reader's table,
    :func:`insgnss.job.inputs.input_allocator`)."""
    from ..io.spill import is_mapped

    return bool(df.shape[1]) and bool(len(df)) and is_mapped(df.iloc[:, 0].to_numpy())


def _take_mapped(df: pd.DataFrame, rows: np.ndarray) -> pd.DataFrame:
    """``df.iloc[rows]`` (sorted rows) of a DataFrame on a memory-mapped file, a block of rows
    at a time with the block's pages given back after it: taking spread rows reads every page,
    which stayed resident (57 MB for the 1 h / 200 Hz reference the report decimates)."""
    from ..io.spill import blocks, release_frame

    rows = np.asarray(rows, np.int64)
    parts = []
    for i, j in blocks(len(df), 8 * df.shape[1]):
        a, b = np.searchsorted(rows, (i, j))
        if b > a:
            parts.append(df.iloc[rows[a:b]])
        release_frame(df, i, j)
    if len(parts) == 1:
        return parts[0]
    return pd.concat(parts) if parts else df.iloc[rows]
