"""Figures a user would put in a report (matplotlib, no global state, Agg-safe).

Every function returns a :class:`matplotlib.figure.Figure`; saving is the caller's business
(:func:`save_figure` writes atomically). Positions are shown as ENU metres about the first
sample, angles in degrees.
"""

from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from .earth import geodetic_to_enu  # noqa: E402
from .io.native import atomic_write  # noqa: E402


def local_enu(traj: pd.DataFrame, origin: tuple[float, float, float] | None = None) -> np.ndarray:
    """(N, 3) ENU coordinates [m] of a trajectory about ``origin`` (default: first sample)."""
    lat, lon, h = (traj[c].to_numpy(float) for c in ("lat", "lon", "height"))
    o = origin if origin is not None else (lat[0], lon[0], h[0])
    return np.column_stack(geodetic_to_enu(lat, lon, h, *o))


def navigation_figure(traj: pd.DataFrame, title: str = "") -> Figure:
    """Four panels: horizontal track, height, ENU velocity, roll/pitch/heading."""
    t = traj.index.to_numpy(float)
    enu = local_enu(traj)
    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5), layout="constrained")
    ax[0, 0].plot(enu[:, 0], enu[:, 1], lw=1.0)
    ax[0, 0].plot(enu[0, 0], enu[0, 1], "go", label="start")
    ax[0, 0].plot(enu[-1, 0], enu[-1, 1], "rs", label="end")
    ax[0, 0].set(xlabel="east [m]", ylabel="north [m]", title="horizontal track")
    ax[0, 0].axis("equal")
    ax[0, 0].legend(loc="best", fontsize=8)
    ax[0, 1].plot(t, traj["height"].to_numpy(float), lw=1.0)
    ax[0, 1].set(xlabel="time [s]", ylabel="ellipsoidal height [m]", title="height")
    for c, lab in zip(("vel_e", "vel_n", "vel_u"), ("east", "north", "up"), strict=True):
        ax[1, 0].plot(t, traj[c].to_numpy(float), lw=1.0, label=lab)
    ax[1, 0].set(xlabel="time [s]", ylabel="velocity [m/s]", title="ENU velocity")
    ax[1, 0].legend(fontsize=8)
    a2 = ax[1, 1].twinx()
    for c in ("roll", "pitch"):
        ax[1, 1].plot(t, np.degrees(traj[c].to_numpy(float)), lw=1.0, label=c)
    a2.plot(t, np.degrees(traj["heading"].to_numpy(float)), "k", lw=0.8, label="heading")
    ax[1, 1].set(xlabel="time [s]", ylabel="roll, pitch [deg]", title="attitude")
    a2.set_ylabel("heading [deg]")
    ax[1, 1].legend(loc="upper left", fontsize=8)
    a2.legend(loc="upper right", fontsize=8)
    for a in ax.flat:
        a.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    return fig


def save_figure(fig: Figure, path: str | os.PathLike, dpi: int = 150) -> None:
    """Save a figure atomically (format from the file extension) and close it."""
    fmt = os.path.splitext(str(path))[1].lstrip(".") or "png"
    atomic_write(path, lambda p: fig.savefig(p, dpi=dpi, format=fmt))
    plt.close(fig)
