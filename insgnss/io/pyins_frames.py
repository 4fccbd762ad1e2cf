"""pyins-style DataFrames <-> insgnss tables, one call each way.

pyins (https://github.com/nmayorov/pyins) holds a trajectory as a DataFrame indexed by time
with ``lat lon alt`` [deg, deg, m], ``VN VE VD`` [m/s] (north-east-down) and ``roll pitch
heading`` [deg] of the forward-right-down body relative to NED (heading = yaw, clockwise
from north), and its standard deviations as ``north east down VN VE VD roll pitch heading``
[m, m/s, deg] (``pyins.sim.TRAJECTORY_COLS``, ``TRAJECTORY_ERROR_COLS``). insgnss tables are
``lat lon height`` [rad, rad, m], ``vel_e vel_n vel_u`` (ENU) and ``roll pitch heading`` [rad]
of the right-forward-up body relative to ENU, with ``*_std`` sigmas (docs/conventions.md).

The three Euler angles coincide numerically between the two conventions
(:func:`insgnss.attitude.euler_from_ned`: the NED/FRD and ENU/RFU frames are swapped by the
same permutation); heading is kept in [0, 360) deg as pyins writes it. Other columns are left
out (``extra=True`` keeps them unchanged). The conversion is exact both ways (a round trip
gives the input back to rounding).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..attitude import euler_from_ned, euler_to_ned
from ..errors import InputFormatError

#: pyins trajectory columns (pyins.sim.TRAJECTORY_COLS)
PYINS_COLS = ["lat", "lon", "alt", "VN", "VE", "VD", "roll", "pitch", "heading"]
#: pyins standard-deviation / error columns (pyins.sim.TRAJECTORY_ERROR_COLS)
PYINS_ERROR_COLS = ["north", "east", "down", "VN", "VE", "VD", "roll", "pitch", "heading"]
#: insgnss navigation columns and their sigmas
NAV = ["lat", "lon", "height", "vel_e", "vel_n", "vel_u", "roll", "pitch", "heading"]
STD = ["east_std", "north_std", "up_std", "vel_e_std", "vel_n_std", "vel_u_std", "roll_std",
       "pitch_std", "heading_std"]


def _need(df: pd.DataFrame, cols, what: str) -> None:
    missing = [c for c in cols if c not in df.columns]
    if missing:
        raise InputFormatError(f"{what} lacks columns", column=missing[0],
                               expected=", ".join(cols), found=", ".join(map(str, df.columns)))


def from_pyins(trajectory: pd.DataFrame, sd: pd.DataFrame | None = None, *,
               extra: bool = False) -> pd.DataFrame:
    """An insgnss trajectory table from a pyins trajectory (and its ``sd`` frame).

    Parameters
    ----------
    trajectory : DataFrame
        ``lat lon alt VN VE VD roll pitch heading`` [deg, m, m/s] indexed by time [s].
    sd : DataFrame, optional
        pyins standard deviations ``north east down VN VE VD roll pitch heading`` at the same
        times; gives the ``*_std`` columns.
    extra : bool
        Keep the other columns of ``trajectory`` unchanged.
    """
    _need(trajectory, PYINS_COLS, "pyins trajectory")
    t = trajectory
    roll, pitch, heading = euler_from_ned(*(np.radians(t[c].to_numpy(float))
                                            for c in ("roll", "pitch", "heading")))
    out = pd.DataFrame({"lat": np.radians(t["lat"].to_numpy(float)),
                        "lon": np.radians(t["lon"].to_numpy(float)),
                        "height": t["alt"].to_numpy(float),
                        "vel_e": t["VE"].to_numpy(float), "vel_n": t["VN"].to_numpy(float),
                        "vel_u": -t["VD"].to_numpy(float),
                        "roll": roll, "pitch": pitch, "heading": heading},
                       index=pd.Index(np.asarray(t.index, float), name="time"))
    if sd is not None:
        _need(sd, PYINS_ERROR_COLS, "pyins sd")
        s = sd.reindex(t.index)
        for ours, theirs, scale in (("east_std", "east", 1.0), ("north_std", "north", 1.0),
                                    ("up_std", "down", 1.0), ("vel_e_std", "VE", 1.0),
                                    ("vel_n_std", "VN", 1.0), ("vel_u_std", "VD", 1.0),
                                    ("roll_std", "roll", np.pi / 180.0),
                                    ("pitch_std", "pitch", np.pi / 180.0),
                                    ("heading_std", "heading", np.pi / 180.0)):
            out[ours] = s[theirs].to_numpy(float) * scale
    if extra:
        for c in t.columns:
            if c not in PYINS_COLS and c not in out.columns:
                out[c] = t[c].to_numpy()
    out.attrs.update({k: v for k, v in t.attrs.items()})
    return out


def to_pyins(trajectory: pd.DataFrame, *, sd: bool = False, extra: bool = False):
    """A pyins trajectory DataFrame from an insgnss table; with ``sd=True`` also the pyins
    ``sd`` frame from the ``*_std`` columns, as ``(trajectory, sd)``. ``extra`` keeps the
    other columns."""
    _need(trajectory, NAV, "insgnss trajectory")
    t = trajectory
    roll, pitch, yaw = euler_to_ned(*(t[c].to_numpy(float) for c in ("roll", "pitch",
                                                                         "heading")))
    idx = pd.Index(np.asarray(t.index, float), name="time")
    out = pd.DataFrame({"lat": np.degrees(t["lat"].to_numpy(float)),
                        "lon": np.degrees(t["lon"].to_numpy(float)),
                        "alt": t["height"].to_numpy(float),
                        "VN": t["vel_n"].to_numpy(float), "VE": t["vel_e"].to_numpy(float),
                        "VD": -t["vel_u"].to_numpy(float),
                        "roll": np.degrees(roll), "pitch": np.degrees(pitch),
                        "heading": np.mod(np.degrees(yaw), 360.0)}, index=idx)
    if extra:
        for c in t.columns:
            if c not in NAV and c not in STD and c not in out.columns:
                out[c] = t[c].to_numpy()
    if not sd:
        return out
    _need(t, STD, "insgnss trajectory (sd=True)")
    deg = 180.0 / np.pi
    s = pd.DataFrame({"north": t["north_std"].to_numpy(float),
                      "east": t["east_std"].to_numpy(float),
                      "down": t["up_std"].to_numpy(float),
                      "VN": t["vel_n_std"].to_numpy(float), "VE": t["vel_e_std"].to_numpy(float),
                      "VD": t["vel_u_std"].to_numpy(float),
                      "roll": t["roll_std"].to_numpy(float) * deg,
                      "pitch": t["pitch_std"].to_numpy(float) * deg,
                      "heading": t["heading_std"].to_numpy(float) * deg}, index=idx)
    return out, s


__all__ = ["PYINS_COLS", "PYINS_ERROR_COLS", "from_pyins", "to_pyins"]
