#!/usr/bin/env python3
"""Reader/writer for the PyShoe Vicon foot-mounted dataset (``.mat`` layout of that dataset only).

Layout (see ``shared/data/pyshoe-vicon/README.md``): ``ts`` (1xN) time [s], ``imu`` (Nx6) =
``[ax ay az]`` specific force [m/s^2] then ``[wx wy wz]`` [rad/s] in the sensor frame, ``gt``
(Nx3) Vicon foot position [m] (z up, arbitrary origin and yaw).

Sensor frame: at rest the accelerometer reads about (-2.8, 0.4, -9.4) m/s^2, so the sensor z
axis points roughly down; the sensor is a forward-right-down unit (VectorNav VN-100 on the shoe).
The declared axis map to insgnss' body frame (right-forward-up) is

    body = AXIS_MAP @ sensor,   AXIS_MAP = [[0, 1, 0], [1, 0, 0], [0, 0, -1]]

(x_body = y_sensor, y_body = x_sensor, z_body = -z_sensor; det = +1, a proper rotation, the
same permutation as RFU <-> FRD). Which way the sensor x axis points on the shoe does not
matter for ZUPT navigation: heading is unobservable and the scorer aligns yaw.

Truth frame: the Vicon ``gt`` has z up (the foot rises in the swings) but its (x, y, z) triad is
the mirror image of the IMU's world: a trajectory navigated in a right-handed frame matches it
only after a reflection (PyShoe navigates in a z-down frame and compares its (x, y) with the
Vicon's directly, which is the same reflection). The declared truth map to a right-handed
local-level frame (z up) swaps x and y::

    truth = TRUTH_MAP @ gt,   TRUTH_MAP = [[0, 1, 0], [1, 0, 0], [0, 0, 1]]   (det = -1)

so insgnss' east/north/up solutions compare with the converted truth up to a yaw rotation, and
the scorer's own frame is obtained back by the same swap (``x = north, y = east``).

Conversions:

- ``to_insgnss(mat) -> (imu, truth)``: IMU rate table (``gyro_* accel_*``, body RFU) and a truth
  table with columns ``x y z`` [m] (right-handed, z up: ``TRUTH_MAP @ gt``), both indexed by
  time [s];
- ``write_trial(mat, out_dir)``: ``imu.csv`` and ``truth.csv`` as native insgnss tables;
- ``from_insgnss(imu, truth) -> dict``: the ``.mat`` keys ``ts imu gt`` back (sensor frame);
  ``write_mat(imu_csv, truth_csv, path)`` writes them with scipy;
- ``solution_xyz(traj) -> DataFrame``: a trajectory with ``east north up`` (or ``lat lon height``)
  as the scorer's ``x y z`` columns (metres from the start, ENU).

Usage::

    convert.py TRIAL.mat OUT_DIR          # -> OUT_DIR/imu.csv, OUT_DIR/truth.csv
    convert.py --back OUT_DIR TRIAL.mat   # native CSVs -> .mat (ts, imu, gt)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.io as sio

from insgnss import earth
from insgnss.errors import InputFormatError
from insgnss.imu import ACCEL_COLS, GYRO_COLS, rates_table
from insgnss.io.native import atomic_write, read_table, write_table

AXIS_MAP = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
TRUTH_MAP = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
#: the lab (University of Toronto, STARS Lab); approximate, used only for normal gravity
TORONTO = (np.radians(43.66), np.radians(-79.40), 100.0)
TRUTH_COLS = ["x", "y", "z"]


def load_mat(path: str | Path) -> dict:
    """Read one trial and check its keys and shapes."""
    path = Path(path)
    try:
        d = sio.loadmat(path)
    except Exception as exc:  # scipy raises several types for a bad file
        raise InputFormatError(f"cannot read as MATLAB .mat: {exc}", file=path) from None
    for key in ("ts", "imu", "gt"):
        if key not in d:
            raise InputFormatError(f"missing key {key!r}", file=path, expected="ts, imu, gt",
                                   found=sorted(k for k in d if not k.startswith("__")))
    ts = np.asarray(d["ts"], float).ravel()
    imu = np.asarray(d["imu"], float)
    gt = np.asarray(d["gt"], float)
    if imu.shape != (ts.size, 6) or gt.shape != (ts.size, 3):
        raise InputFormatError("inconsistent shapes", file=path, expected=f"imu ({ts.size}, 6), "
                               f"gt ({ts.size}, 3)", found=f"imu {imu.shape}, gt {gt.shape}")
    if not np.all(np.diff(ts) > 0):
        raise InputFormatError("time stamps not strictly increasing", file=path, column="ts")
    return {"ts": ts, "imu": imu, "gt": gt, "raw": d}


def to_insgnss(mat: dict | str | Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """IMU rate table in body RFU and the Vicon truth table (``x y z``) of one trial."""
    d = load_mat(mat) if not isinstance(mat, dict) else mat
    acc = d["imu"][:, :3] @ AXIS_MAP.T
    gyro = d["imu"][:, 3:] @ AXIS_MAP.T
    imu = rates_table(d["ts"], gyro, acc)
    truth = pd.DataFrame(d["gt"] @ TRUTH_MAP.T, index=pd.Index(d["ts"], name="time"),
                         columns=TRUTH_COLS)
    return imu, truth


def from_insgnss(imu: pd.DataFrame, truth: pd.DataFrame) -> dict:
    """The ``ts``, ``imu`` (sensor frame, ``[a w]``) and ``gt`` arrays of the .mat layout."""
    acc = imu[ACCEL_COLS].to_numpy(float) @ AXIS_MAP  # AXIS_MAP is orthogonal: inverse = T
    gyro = imu[GYRO_COLS].to_numpy(float) @ AXIS_MAP
    return {"ts": np.asarray(imu.index, float)[None, :], "imu": np.column_stack([acc, gyro]),
            "gt": truth[TRUTH_COLS].to_numpy(float) @ TRUTH_MAP}  # TRUTH_MAP is its own inverse


def write_trial(mat: str | Path, out_dir: str | Path) -> tuple[Path, Path]:
    """Convert one trial into ``out_dir/imu.csv`` and ``out_dir/truth.csv``."""
    imu, truth = to_insgnss(mat)
    out = Path(out_dir)
    return (write_table(imu, out / "imu.csv"),
            write_table(truth, out / "truth.csv"))


def write_mat(imu_csv: str | Path, truth_csv: str | Path, path: str | Path) -> Path:
    """Native IMU and truth CSVs back to the dataset's .mat layout (keys ts, imu, gt)."""
    d = from_insgnss(read_table(imu_csv, GYRO_COLS + ACCEL_COLS), read_table(truth_csv, TRUTH_COLS))
    return atomic_write(path, lambda p: sio.savemat(p, d))


def solution_xyz(traj: pd.DataFrame, origin: tuple[float, float, float] | None = None) -> pd.DataFrame:
    """``x y z`` = east, north, up [m] from the first sample, in the frame of the converted
    truth (see ``TRUTH_MAP``; the scorer's frame is ``x = north, y = east``)."""
    if {"east", "north", "up"} <= set(traj.columns):
        xyz = traj[["east", "north", "up"]].to_numpy(float)
    else:
        lat, lon, h = (traj[c].to_numpy(float) for c in ("lat", "lon", "height"))
        o = origin or (lat[0], lon[0], h[0])
        xyz = np.column_stack(earth.geodetic_to_enu(lat, lon, h, *o))
    xyz = xyz - xyz[0]
    return pd.DataFrame(xyz, columns=TRUTH_COLS)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--back", action="store_true", help="convert native CSVs back to .mat")
    p.add_argument("src")
    p.add_argument("dst")
    a = p.parse_args(argv)
    if a.back:
        path = write_mat(Path(a.src) / "imu.csv", Path(a.src) / "truth.csv", a.dst)
        print(path)
    else:
        for path in write_trial(a.src, a.dst):
            print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
