"""What the filter engine stores: the smoother's nodes, the applied updates and the innovation log.

Nodes
-----
A *node* is a time at which the engine keeps the error-state covariance. Every filter epoch is a
node; in a segment run by the compiled high-rate path every IMU sample is one. Node ``k`` holds

- ``t[k]``: its time;
- ``Phi[k]``: the error transition from node ``k-1`` to ``k`` (``Phi[0] = I``);
- ``Pp[k] = P(k|k-1)``: the predicted covariance the updates at ``k`` saw (after a gate
  recovery: the inflated one);
- ``Pf[k] = P(k|k)``: the covariance after the updates;
- ``fb[k]``: the error estimate fed back into (removed from) the nominal at ``k`` (zero
  without update);
- ``par[k]``: the process model's nominal parameters after the feedback (biases, scale
  factors, extra states), for the output tables.

Updates
-------
For each node, the rows ``ptr[k] .. ptr[k+1]-1`` of the update arrays describe the (stacked)
update applied there: ``H`` (m, n), the gain ``K`` stored transposed (m, n), ``G = S^-1 H``
(m, n) and ``s = S^-1 z`` (m). With ``Pp``, ``Pf``, ``Phi`` and ``fb`` this is everything the
Rauch-Tung-Striebel form, the modified Bryson-Frazier form (:mod:`.smoother`) and an EM
estimate of the noise parameters need (``R = S - H Pp H^T``).

Innovation log
--------------
One record per measurement evaluated (accepted or not): time, type, dof, NIS, threshold,
accepted, recovered, the innovation and the square roots of the diagonal of ``S``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["NodeStore", "InnovationLog", "innovation_tables"]


class NodeStore:
    """Preallocated node arrays (capacity ``cap``) and growable update rows."""

    def __init__(self, cap: int, n: int, n_par: int, rows: int = 64):
        self.n = n
        self.t = np.empty(cap)
        self.Pf = np.empty((cap, n, n))
        self.Pp = np.empty((cap, n, n))
        self.Phi = np.empty((cap, n, n))
        self.fb = np.zeros((cap, n))
        self.par = np.empty((cap, n_par))
        self.ptr = np.zeros(cap + 1, np.int64)
        self.count = 0  # nodes written
        self._alloc_rows(max(rows, 8))
        self.n_rows = 0

    def _alloc_rows(self, cap):
        n = self.n
        old = getattr(self, "H", None)
        H, K, G, s = np.empty((cap, n)), np.empty((cap, n)), np.empty((cap, n)), np.empty(cap)
        if old is not None:
            r = self.n_rows
            H[:r], K[:r], G[:r], s[:r] = self.H[:r], self.K[:r], self.G[:r], self.s[:r]
        self.H, self.K, self.G, self.s = H, K, G, s

    def reserve_rows(self, extra: int) -> None:
        """Make room for ``extra`` more update rows."""
        need = self.n_rows + extra
        if need > self.H.shape[0]:
            self._alloc_rows(max(need, 2 * self.H.shape[0]))

    def add_update(self, H, K, G, s) -> None:
        """Append the rows of one (stacked) update to the node being written."""
        m = H.shape[0]
        self.reserve_rows(m)
        r = self.n_rows
        self.H[r:r + m] = H
        self.K[r:r + m] = K.T
        self.G[r:r + m] = G
        self.s[r:r + m] = s
        self.n_rows = r + m

    def close(self, k: int, t: float, Phi, Pp, Pf, fb, par) -> None:
        """Write node ``k`` (its update rows were added since the previous node)."""
        self.t[k] = t
        self.Phi[k] = Phi
        self.Pp[k] = Pp
        self.Pf[k] = Pf
        if fb is None:
            self.fb[k] = 0.0
        else:
            self.fb[k] = fb
        self.par[k] = par
        self.ptr[k + 1] = self.n_rows
        self.count = k + 1


class InnovationLog:
    """Innovation records of both update paths, in processing order."""

    def __init__(self, names: list[str]):
        self.names = list(names)
        self._rows: list = []  # Python path: (time, tid, dof, nis, thr, accepted, recovered, z, S)
        self._chunks: list = []  # flushed blocks (dicts of arrays)

    def add(self, time, tid, nis, thr, accepted, recovered, z, S) -> None:
        self._rows.append((time, tid, z.size, nis, thr, accepted, recovered, z, S))

    def _flush(self) -> None:
        if not self._rows:
            return
        rows = self._rows
        m = max(r[2] for r in rows)
        innov = np.full((len(rows), m), np.nan)
        std = np.full((len(rows), m), np.nan)
        for i, r in enumerate(rows):
            d = r[2]
            innov[i, :d] = r[7]
            dg = np.diag(r[8])
            std[i, :d] = np.where(dg >= 0, np.sqrt(np.abs(dg)), np.nan)
        self._chunks.append({
            "time": np.array([r[0] for r in rows], float),
            "tid": np.array([r[1] for r in rows], np.int64),
            "dof": np.array([r[2] for r in rows], np.int64),
            "nis": np.array([r[3] for r in rows], float),
            "threshold": np.array([r[4] for r in rows], float),
            "accepted": np.array([r[5] for r in rows], bool),
            "recovered": np.array([r[6] for r in rows], bool),
            "innov": innov, "innov_std": std})
        self._rows = []

    def add_block(self, block: dict) -> None:
        """Append a block of records from the compiled path (same keys as the flushed ones)."""
        self._flush()
        if block["time"].size:
            self._chunks.append(block)

    def columns(self) -> dict:
        """All records as arrays (``innov`` / ``innov_std`` padded with NaN)."""
        self._flush()
        keys = ("time", "tid", "dof", "nis", "threshold", "accepted", "recovered")
        if not self._chunks:
            out = {k: np.empty(0) for k in keys}
            out["innov"] = out["innov_std"] = np.empty((0, 0))
            return out
        out = {k: np.concatenate([c[k] for c in self._chunks]) for k in keys}
        m = max(c["innov"].shape[1] for c in self._chunks)
        for k in ("innov", "innov_std"):
            out[k] = np.concatenate([np.pad(c[k], ((0, 0), (0, m - c[k].shape[1])),
                                            constant_values=np.nan) for c in self._chunks])
        return out


def innovation_tables(log: InnovationLog) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Innovation table (``time type dof nis threshold accepted recovered innov_k
    innov_std_k``) and its rejected rows."""
    c = log.columns()
    m = c["innov"].shape[1]
    names = np.array(log.names + [""], dtype=object)
    cols = {"time": c["time"], "type": names[c["tid"].astype(np.int64)] if c["tid"].size
            else np.empty(0, object),
            "dof": c["dof"].astype(np.int64), "nis": c["nis"], "threshold": c["threshold"],
            "accepted": c["accepted"].astype(bool), "recovered": c["recovered"].astype(bool)}
    for k in range(m):
        cols[f"innov_{k}"] = c["innov"][:, k]
    for k in range(m):
        cols[f"innov_std_{k}"] = c["innov_std"][:, k]
    innovations = pd.DataFrame(cols)
    rejected = innovations[~innovations["accepted"]].reset_index(drop=True)
    return innovations, rejected
