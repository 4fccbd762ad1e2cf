"""Strides of a foot-mounted solution: stance positions and the distance walked between them.

A foot-mounted INS corrects its velocity at every stance; the forward (causal) solution therefore
jumps back at each correction, and its raw path length ``sum |p_k - p_{k-1}|`` counts every jump
twice (out and back): on real walks it is 16-19 % too long. The foot does not move during a
stance, so the distance walked is the length of the polygon through one position per stance::

    d = sum_j |pbar_{j+1} - pbar_j|,   pbar_j = mean of p_k over the still run j

(Foxlin 2005; the stride length of gait analysis, Rampp et al. 2015). The mean over the run
averages out the corrections applied inside it. Runs shorter than ``min_samples`` are ignored
(a single still sample in mid-swing is a detector artefact, not a stance).
"""

from __future__ import annotations

import numpy as np


def still_runs(still: np.ndarray) -> np.ndarray:
    """``(start, stop)`` index pairs (stop exclusive) of the runs of True in ``still``."""
    s = np.asarray(still, bool).astype(np.int8)
    d = np.diff(np.concatenate([[0], s, [0]]))
    return np.column_stack([np.flatnonzero(d == 1), np.flatnonzero(d == -1)])


def stance_positions(pos: np.ndarray, still: np.ndarray, min_samples: int = 3) -> np.ndarray:
    """Mean position (M, D) of each still run of at least ``min_samples`` samples."""
    pos = np.asarray(pos, float)
    runs = still_runs(still)
    runs = runs[runs[:, 1] - runs[:, 0] >= min_samples]
    if not runs.size:
        return np.empty((0, pos.shape[1]))
    c = np.vstack([np.zeros((1, pos.shape[1])), np.cumsum(pos, axis=0)])
    return (c[runs[:, 1]] - c[runs[:, 0]]) / (runs[:, 1] - runs[:, 0])[:, None]


def stance_distance(pos: np.ndarray, still: np.ndarray, min_samples: int = 3) -> float:
    """Distance [m] of the polygon through the stance positions (horizontal if ``pos`` is
    (N, 2) east-north, 3-D if (N, 3))."""
    p = stance_positions(pos, still, min_samples)
    if p.shape[0] < 2:
        return 0.0
    return float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))


def path_length(pos: np.ndarray) -> float:
    """Raw path length ``sum |p_k - p_{k-1}|`` [m]."""
    pos = np.asarray(pos, float)
    return float(np.sum(np.linalg.norm(np.diff(pos, axis=0), axis=1))) if len(pos) > 1 else 0.0


def walk_distances(forward: np.ndarray, still: np.ndarray, smoothed: np.ndarray | None = None,
                   min_samples: int = 3) -> dict:
    """Distances walked [m] for a foot-mounted result (horizontal, from east-north arrays
    (N, 2)): the raw path length of the forward solution (which counts every correction jump),
    its stance-to-stance distance (:func:`stance_distance`), the smoothed path length, and the
    number of stances."""
    out = {"forward_path_m": path_length(forward),
           "stance_m": stance_distance(forward, still, min_samples),
           "stances": int(stance_positions(forward, still, min_samples).shape[0])}
    if smoothed is not None:
        out["smoothed_path_m"] = path_length(smoothed)
    return out
