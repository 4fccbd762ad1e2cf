"""Test helpers for RISS: an analytic land-vehicle drive (no side slip, no vertical body velocity)
with turns, slopes below 10 % and a varying roll, and its exact IMU by inverse mechanization."""

from __future__ import annotations

import numpy as np
import pandas as pd

from insgnss.mechanization.inverse import integrate_position, inverse_mechanize
from insgnss.mechanization.strapdown import NavState

LAT0 = np.radians(51.08)
LON0 = np.radians(-114.13)
H0 = 1100.0

#: (start [s], duration [s], heading change [rad]) of the turns
TURNS = [(20.0, 8.0, np.pi / 2), (70.0, 10.0, -np.pi / 2), (120.0, 6.0, np.pi / 2),
         (180.0, 20.0, np.pi), (260.0, 8.0, -np.pi / 2), (330.0, 12.0, -np.pi / 2),
         (400.0, 30.0, 2 * np.pi / 3), (470.0, 8.0, np.pi / 2), (540.0, 15.0, -np.pi)]


def _bump_integral(t, t0, T, total):
    """Integral of a raised-cosine rate bump of area ``total`` on [t0, t0+T] (and the rate)."""
    x = np.clip(t - t0, 0.0, T)
    val = total / T * (x - T / (2 * np.pi) * np.sin(2 * np.pi * x / T))
    inside = (t > t0) & (t < t0 + T)
    rate = np.where(inside, total / T * (1 - np.cos(2 * np.pi * (t - t0) / T)), 0.0)
    return val, rate


def land_vehicle_drive(duration=600.0, rate=100.0, heading0=0.3, speed_scale=1.0):
    """Truth table (NAV_COLS) and odometer speed [m/s] of a land-vehicle drive.

    Speed 3-19 m/s, nine turns (rates up to 0.4 rad/s), slopes up to 9 % (pitch < 0.09 rad),
    roll up to 0.05 rad. Position by :func:`integrate_position` (consistent with the forward
    mechanization), so ``inverse_mechanize`` gives its exact IMU.
    """
    t = np.arange(int(round(duration * rate)) + 1) / rate
    speed = speed_scale * (11.0 + 6.0 * np.sin(2 * np.pi * t / 97.0) - 2.0 * np.cos(2 * np.pi * t / 31.0))
    heading = np.full_like(t, heading0)
    for t0, T, ang in TURNS:
        if t0 + T <= duration:
            val, _ = _bump_integral(t, t0, T, ang)
            heading += val
    pitch = 0.055 * np.sin(2 * np.pi * t / 170.0) + 0.03 * np.sin(2 * np.pi * t / 53.0 + 1.0)
    roll = 0.035 * np.sin(2 * np.pi * t / 41.0 + 0.3) + 0.015 * np.sin(2 * np.pi * t / 13.0)
    vel = np.column_stack([speed * np.sin(heading) * np.cos(pitch),
                           speed * np.cos(heading) * np.cos(pitch), speed * np.sin(pitch)])
    pos = integrate_position(t, vel, LAT0, LON0, H0)
    truth = pd.DataFrame({"lat": pos[:, 0], "lon": pos[:, 1], "height": pos[:, 2],
                          "vel_e": vel[:, 0], "vel_n": vel[:, 1], "vel_u": vel[:, 2],
                          "roll": roll, "pitch": pitch, "heading": np.mod(heading, 2 * np.pi)},
                         index=pd.Index(t, name="time"))
    return truth, speed


def perfect_drive(duration=600.0, rate=100.0):
    """(truth, imu increments, odometer DataFrame, initial NavState) of :func:`land_vehicle_drive`."""
    truth, speed = land_vehicle_drive(duration, rate)
    imu = inverse_mechanize(truth)
    odo = pd.DataFrame({"speed": speed}, index=truth.index)
    return truth, imu, odo, initial_state(truth)


def initial_state(truth: pd.DataFrame, k: int = 0) -> NavState:
    r = truth.iloc[k]
    return NavState.from_euler(r.lat, r.lon, r.height, (r.vel_e, r.vel_n, r.vel_u), r.roll,
                               r.pitch, r.heading, time=float(truth.index[k]))


def enu_error(est: pd.DataFrame, ref: pd.DataFrame) -> np.ndarray:
    """(N, 3) ENU position error [m] of ``est`` against ``ref`` (local radii)."""
    from insgnss.earth import radii

    lat = ref["lat"].to_numpy()
    M, N = radii(lat)
    h = ref["height"].to_numpy()
    dn = (est["lat"].to_numpy() - lat) * (M + h)
    de = (est["lon"].to_numpy() - ref["lon"].to_numpy()) * (N + h) * np.cos(lat)
    du = est["height"].to_numpy() - h
    return np.column_stack([de, dn, du])
