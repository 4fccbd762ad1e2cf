"""Test helpers: analytic/dynamic trajectories for mechanization tests (no hot paths here)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from insgnss.attitude import euler_to_dcm
from insgnss.earth import OMEGA_E, normal_gravity
from insgnss.imu import increments_table
from insgnss.mechanization.inverse import integrate_position
from insgnss.mechanization.strapdown import NavState

LAT45 = np.radians(45.0)
LON7 = np.radians(7.0)


def static_increments(duration, rate, lat=LAT45, h=0.0, roll=0.0, pitch=0.0, heading=0.0,
                      gravity_model="somigliana"):
    """Exact increments of a perfect static IMU: f^b = C_l^b (0,0,g), w^b = C_l^b w_ie^l."""
    n = int(round(duration * rate)) + 1
    t = np.arange(n) / rate
    C = euler_to_dcm(roll, pitch, heading)
    g = normal_gravity(lat, h, gravity_model)
    f = C.T @ np.array([0.0, 0.0, g])
    w = C.T @ np.array([0.0, OMEGA_E * np.cos(lat), OMEGA_E * np.sin(lat)])
    dt = 1.0 / rate
    dth = np.tile(w * dt, (n, 1))
    dv = np.tile(f * dt, (n, 1))
    dth[0] = dv[0] = 0.0
    return increments_table(t, dth, dv), NavState.from_euler(lat, 0.0, h, (0, 0, 0), roll, pitch,
                                                              heading)


def dynamic_trajectory(duration=600.0, rate=100.0, lat0=LAT45, lon0=LON7, h0=100.0):
    """A 10-minute trajectory with speed changes, turns, climbs and banked roll."""
    t = np.arange(int(round(duration * rate)) + 1) / rate
    speed = 10 + 5 * np.sin(2 * np.pi * t / 120)
    heading = 0.5 + 0.8 * np.sin(2 * np.pi * t / 200) + 0.002 * t
    pitch = 0.05 * np.sin(2 * np.pi * t / 90)
    roll = 0.1 * np.sin(2 * np.pi * t / 60)
    vel = np.column_stack([speed * np.sin(heading) * np.cos(pitch),
                           speed * np.cos(heading) * np.cos(pitch), speed * np.sin(pitch)])
    pos = integrate_position(t, vel, lat0, lon0, h0)
    return pd.DataFrame({"lat": pos[:, 0], "lon": pos[:, 1], "height": pos[:, 2],
                         "vel_e": vel[:, 0], "vel_n": vel[:, 1], "vel_u": vel[:, 2],
                         "roll": roll, "pitch": pitch, "heading": np.mod(heading, 2 * np.pi)},
                        index=pd.Index(t, name="time"))


def initial_state(traj: pd.DataFrame) -> NavState:
    r = traj.iloc[0]
    return NavState.from_euler(r.lat, r.lon, r.height, (r.vel_e, r.vel_n, r.vel_u), r.roll,
                               r.pitch, r.heading, time=float(traj.index[0]))


def enu_error(est: pd.DataFrame, ref: pd.DataFrame) -> np.ndarray:
    """(N, 3) ENU position error [m] using the local radii (small differences)."""
    from insgnss.earth import radii

    M, N = radii(ref["lat"].to_numpy())
    h = ref["height"].to_numpy()
    dn = (est["lat"].to_numpy() - ref["lat"].to_numpy()) * (M + h)
    de = (est["lon"].to_numpy() - ref["lon"].to_numpy()) * (N + h) * np.cos(ref["lat"].to_numpy())
    du = est["height"].to_numpy() - h
    return np.column_stack([de, dn, du])
