"""Readers and frame alignment for the shared foot-mounted datasets (bench scripts only).

- x-io Gait-Tracking (``shared/data/foot-xio-gait``): ``short_walk.csv``, ``long_walk.csv``,
  deg/s and g in the sensor's own axes, about 398 Hz with irregular and duplicated time stamps
  (bridged); loops that end where they start.
- UCR Constrained-ZUPT-FGO (``shared/data/foot-ucr-zupt``): left and right foot at 60 Hz with a
  sample index for time; ``positionGt.csv`` holds the foot positions in a z-down frame, the
  mirror image of east-north-up, so the solution's (north, east) is compared with the
  truth's (x, y) (see its README).
- PyShoe Vicon (``shared/data/pyshoe-vicon``): through ``scenarios/pyshoe/convert.py``.

Frame alignment of a trajectory with a truth that shares no frame with it
(:func:`rigid_fit_2d`): the 2-D rotation and translation minimising the squared distance
(Kabsch/Umeyama without scale), fitted over a stated interval.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
sys.path.insert(0, str(REPO / "scenarios" / "pyshoe"))
import convert  # noqa: E402  (PyShoe .mat reader)

from insgnss.io import read_imu_csv  # noqa: E402
from insgnss.validate import GapPolicy  # noqa: E402

XIO_COLS = {"time": "Time (s)", "gyro_x": "Gyroscope X (deg/s)", "gyro_y": "Gyroscope Y (deg/s)",
            "gyro_z": "Gyroscope Z (deg/s)", "accel_x": "Accelerometer X (g)",
            "accel_y": "Accelerometer Y (g)", "accel_z": "Accelerometer Z (g)"}
UCR_COLS = {"time": "time_index", "gyro_x": "gyro_x", "gyro_y": "gyro_y", "gyro_z": "gyro_z",
            "accel_x": "acc_x", "accel_y": "acc_y", "accel_z": "acc_z"}
UCR_RATE = 60.0
XIO_WALKS = ("short_walk", "long_walk")
#: the x-io author's final displacement (their README) [m]
XIO_AUTHOR = {"short_walk": 0.082, "long_walk": 0.421}
UCR_SIDES = {"left": "imuMeasLeft.csv", "right": "imuMeasRight.csv"}
#: published horizontal RMS [m] on the UCR data (the authors' statistics_report_hor.csv)
UCR_PUBLISHED = {"ekf_zupt": {"right": 1.484, "left": 3.904},
                 "fgo_zupt": {"right": 0.510, "left": 2.169}}
#: approximate sites (normal gravity only; heading is unobservable anyway)
SITES = {"xio": (np.radians(51.45), np.radians(-2.59), 20.0),     # Bristol
         "ucr": (np.radians(33.97), np.radians(-117.33), 300.0),  # Riverside
         "pyshoe": convert.TORONTO}


def read_xio(name: str):
    """IMU table of one x-io walk (bridging its time-stamp gaps)."""
    return read_imu_csv(DATA / "foot-xio-gait" / f"{name}.csv", columns=XIO_COLS,
                        gyro_unit="deg/s", accel_unit="g",
                        gap_policy=GapPolicy(max_bridge=1.0, long="bridge"))


def read_ucr(side: str):
    """IMU table of one UCR foot (time from the sample index at 60 Hz)."""
    return read_imu_csv(DATA / "foot-ucr-zupt" / UCR_SIDES[side], columns=UCR_COLS,
                        time_unit="sample", rate_hz=UCR_RATE)


def ucr_truth(side: str) -> np.ndarray:
    """(N, 3) truth positions of one UCR foot in its z-down frame [m]."""
    import pandas as pd

    gt = pd.read_csv(DATA / "foot-ucr-zupt" / "positionGt.csv")
    return gt[[f"pos_{side}_x", f"pos_{side}_y", f"pos_{side}_z"]].to_numpy()


def rigid_fit_2d(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R and translation c minimising ``sum |R a_k + c - b_k|^2`` (2-D Kabsch)."""
    ma, mb = a.mean(0), b.mean(0)
    U, _, Vt = np.linalg.svd((a - ma).T @ (b - mb))
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    R = Vt.T @ np.diag([1.0, d]) @ U.T
    return R, mb - R @ ma


def fitted_rms(a: np.ndarray, b: np.ndarray, fit: slice = slice(None)) -> float:
    """Horizontal RMS of ``a`` against ``b`` after the rigid fit over the samples ``fit``."""
    R, c = rigid_fit_2d(a[fit], b[fit])
    return float(np.sqrt(np.mean(np.sum((a @ R.T + c - b) ** 2, axis=1))))
