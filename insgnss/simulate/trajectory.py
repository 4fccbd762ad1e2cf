"""Trajectory generator: self-consistent truth (position, ENU velocity, attitude) at the IMU rate.

Model
-----
A trajectory is built from a few smooth kinematic *channels* evaluated in closed form on the
sample grid (vectorised with numpy; the only Python loop runs over segments or strides, never
over samples):

- vehicle profiles (``"land"``, ``"aircraft"``): horizontal ground speed ``v_h(t)``, course /
  heading ``psi(t)`` (clockwise from north) and vertical velocity ``v_u(t)``. The ENU velocity is
  ``(v_h sin psi, v_h cos psi, v_u)``;
- the foot-mounted pedestrian profile: a stance/swing cycle per stride (see below);
- timed waypoints: a C2 cubic spline of latitude, longitude and height through the waypoint
  positions at their times (scipy ``CubicSpline``) gives the path, differentiated analytically;
  a quintic time law in the first / last interval starts / ends the motion smoothly at rest
  without changing any waypoint time (see :func:`_waypoint_channels`).

Every change of a channel inside a segment follows a *smooth step*: its rate is a trapezoid with
raised-cosine ramps of fraction ``ramp`` at both ends (``0 < ramp <= 0.5``), so rates start and
end at zero and channels, rates and therefore attitude (including the bank of a coordinated turn)
are continuous at segment boundaries. The plateau rate is the commanded acceleration / turn rate
/ vertical rate; the step duration is ``change / (rate (1 - ramp))``.

Position is *not* integrated analytically: it is obtained from the ENU velocity by
:func:`insgnss.mechanization.inverse.integrate_position`, the exact trapezoidal rule of the forward
mechanization, so ``mechanize(inverse_mechanize(truth))`` reproduces the truth to rounding and the
discrete derivative ``(p_k - p_{k-1}) / dt`` (in metres, with the radii at the mid-interval point
of the step's rule) equals ``(v_k + v_{k-1}) / 2`` to rounding.

Attitude (vehicle models)
-------------------------
- land vehicle: heading = course, pitch = ``atan2(v_u, v_h)`` (road grade), roll
  ``= -k a_lat`` with the lateral acceleration ``a_lat = v_h dpsi/dt`` and a body-roll gain ``k``
  (default 0: a rigid car that stays level; a real car rolls outwards, ~0.5 deg per m/s^2);
- aircraft: heading = course, pitch = flight-path angle, roll = coordinated-turn bank
  ``atan(v_h dpsi/dt / g)`` (no sideslip, no angle of attack);
- ``coordinated_turn`` segments apply the coordinated bank for any vehicle.

Pedestrian (foot-mounted IMU)
-----------------------------
Each stride of the instrumented foot is a stance phase (foot flat on the ground: velocity exactly
zero and attitude constant) followed by a swing phase of duration ``T_s`` in which, with
``u = (t - t_swing) / T_s``,

- the foot moves forward by the stride length ``L`` along the heading with
  ``s(u) = L (u - sin(2 pi u) / (2 pi))`` (speed ``L/T_s (1 - cos 2 pi u)``, zero at both ends);
- it lifts by the clearance ``H`` with ``h(u) = H sin^2(pi u)`` (plus a smooth step of the stride's
  share of a height change, e.g. stairs);
- it pitches ``p(u) = sin^2(pi u) (c - b cos(pi u))`` with ``b, c`` chosen so that
  ``p(1/4) = -toe_off_pitch`` (heel lifted, toes down) and ``p(3/4) = +heel_strike_pitch`` (toes
  up before heel strike), the usual shape of sagittal foot pitch in gait (Perry 1992; Skog et al.
  2010, foot-mounted INS data);
- the heading turns by the stride's share of the segment's turn angle with a smooth step.

References
----------
- Groves, *Principles of GNSS, Inertial and Multisensor Integrated Navigation Systems*, 2nd ed.,
  2013, section 2.4 (kinematics) and appendix on coordinated turns.
- Stevens, Lewis, Johnson, *Aircraft Control and Simulation*, 3rd ed., 2016 (coordinated turn
  ``tan(phi) = v omega / g``).
- gnss-ins-sim (Aceinna) motion definition files, for the segment vocabulary.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.interpolate import CubicSpline

from ..attitude import euler_to_dcm
from ..earth import check_latitude, enu_to_geodetic, normal_gravity, radii
from ..errors import ConfigError
from ..mechanization.core import FRAME_WANDER, frame_id
from ..mechanization.inverse import integrate_position
from ..mechanization.strapdown import NAV_COLS
from ..mechanization.wander import integrate_position_wander, wander_table
from ..trajectory_tools import vne_to_rpy

VEHICLES = ("land", "aircraft", "pedestrian")
DEFAULT_RAMP = 0.25

#: keys accepted by each segment type (besides ``type``); ``ramp`` is allowed where a channel moves
SEGMENT_KEYS: dict[str, set[str]] = {
    "static": {"duration"},
    "hold": {"duration"},
    "accelerate": {"speed", "acceleration", "duration", "ramp"},
    "decelerate": {"speed", "acceleration", "duration", "ramp"},
    "turn": {"angle", "rate", "duration", "ramp"},
    "coordinated_turn": {"angle", "bank", "duration", "ramp"},
    "climb": {"height_change", "rate", "duration", "ramp"},
    "descend": {"height_change", "rate", "duration", "ramp"},
    # pedestrian
    "stand": {"duration"},
    "walk": {"steps", "stride_length", "stride_time", "stance_fraction", "clearance",
             "toe_off_pitch", "heel_strike_pitch", "turn", "height_change"},
}
PEDESTRIAN_SEGMENTS = {"stand", "walk", "static"}
WAYPOINT_KEYS = {"time", "east", "north", "up", "lat", "lon", "height"}
#: walk defaults (SI, radians): adult walking at ~1.3 m/s (stride 1.4 m in 1.1 s, stance 60 %)
WALK_DEFAULTS = {"stride_length": 1.4, "stride_time": 1.1, "stance_fraction": 0.6,
                 "clearance": 0.12, "toe_off_pitch": np.radians(35.0),
                 "heel_strike_pitch": np.radians(20.0), "turn": 0.0, "height_change": 0.0}
#: segment keys holding angles (degrees in scenario files, radians in :func:`generate`)
ANGLE_KEYS: dict[str, set[str]] = {
    "turn": {"angle", "rate"},
    "coordinated_turn": {"angle", "bank"},
    "walk": {"turn", "toe_off_pitch", "heel_strike_pitch"},
}


@dataclass
class Trajectory:
    """Generated truth.

    Attributes
    ----------
    truth : DataFrame
        Indexed by time [s]; columns :data:`NAV_COLS` (rad, m, m/s) and ``stationary`` (1.0 where
        the body is at rest: zero velocity and constant attitude, e.g. static segments and
        pedestrian stance phases; 0.0 elsewhere).
    vehicle : str
    segments : list of dict
        The segment table actually run (type, start, stop [s relative to the start]).
    """

    truth: pd.DataFrame
    vehicle: str
    segments: list[dict] = field(default_factory=list)

    @property
    def stationary(self) -> np.ndarray:
        return self.truth["stationary"].to_numpy() > 0.5


# --- smooth step ------------------------------------------------------------------------------
def smooth_step(u, ramp: float = DEFAULT_RAMP) -> tuple[np.ndarray, np.ndarray]:
    """Smooth step ``S(u)`` from 0 to 1 on ``u in [0, 1]`` and its derivative ``dS/du``.

    The derivative is a trapezoid with raised-cosine ramps of width ``ramp`` (fraction of the
    interval, ``0 < ramp <= 0.5``), normalised to unit integral: it is zero at both ends and
    continuous, so a channel driven by it has continuous rate.
    """
    if not 0.0 < ramp <= 0.5:
        raise ValueError(f"ramp must be in (0, 0.5]; got {ramp}")
    u = np.clip(np.asarray(u, float), 0.0, 1.0)
    r = ramp
    k = np.pi / r
    up = u < r
    down = u > 1.0 - r
    w = 1.0 - u
    g = np.where(up, 0.5 * (1.0 - np.cos(k * u)), np.where(down, 0.5 * (1.0 - np.cos(k * w)), 1.0))
    G = np.where(
        up,
        0.5 * (u - np.sin(k * u) / k),
        np.where(down, (1.0 - r) - 0.5 * (w - np.sin(k * w) / k), 0.5 * r + (u - r)),
    )
    return G / (1.0 - r), g / (1.0 - r)


def _plateau_duration(change: float, rate: float, ramp: float) -> float:
    """Duration of a smooth step of size ``change`` whose plateau rate is ``rate``."""
    return abs(change) / (abs(rate) * (1.0 - ramp))


# --- helpers ------------------------------------------------------------------------------------
def _num(seg: dict, key: str, where: str, default=None, positive: bool = False) -> float:
    if key not in seg:
        if default is None:
            raise ConfigError(f"missing '{key}'", column=f"{where}.{key}")
        return float(default)
    val = seg[key]
    if isinstance(val, bool) or not isinstance(val, int | float):
        raise ConfigError("not a number", column=f"{where}.{key}", found=repr(val))
    if not np.isfinite(val) or (positive and val <= 0):
        raise ConfigError("must be a finite" + (" positive" if positive else "") + " number",
                          column=f"{where}.{key}", found=val)
    return float(val)


def _check_keys(seg: dict, allowed: set[str], where: str) -> None:
    for key in seg:
        if key != "type" and key not in allowed:
            raise ConfigError(f"unknown key '{key}'", column=f"{where}.{key}",
                              expected=sorted(allowed))


def _time_grid(duration: float, rate: float, start_time: float) -> np.ndarray:
    n = int(np.floor(duration * rate + 1e-9)) + 1
    return start_time + np.arange(n) / rate


def _step_duration(seg: dict, where: str, change: float, rate_key: str, ramp: float) -> float:
    """Duration from ``duration`` or from the plateau rate ``rate_key`` (one of them)."""
    has_d, has_r = "duration" in seg, rate_key in seg
    if has_d == has_r:
        raise ConfigError(f"give exactly one of 'duration' and '{rate_key}'", column=where)
    if has_d:
        return _num(seg, "duration", where, positive=True)
    return _plateau_duration(change, _num(seg, rate_key, where, positive=True), ramp)


# --- vehicle profiles (segments) ----------------------------------------------------------------
def _plan_vehicle_segments(segments: Sequence[dict], speed0: float, g: float) -> list[dict]:
    """Validate segments and compute their durations and channel changes."""
    plan = []
    v = speed0
    t = 0.0
    for i, seg in enumerate(segments):
        where = f"trajectory.segments[{i}]"
        if not isinstance(seg, dict) or "type" not in seg:
            raise ConfigError("each segment needs a 'type'", column=where, expected=sorted(SEGMENT_KEYS))
        kind = seg["type"]
        if kind not in SEGMENT_KEYS or kind in ("stand", "walk"):
            raise ConfigError(f"unknown segment type {kind!r}", column=f"{where}.type",
                              expected=sorted(set(SEGMENT_KEYS) - {"stand", "walk"}))
        _check_keys(seg, SEGMENT_KEYS[kind], where)
        ramp = _num(seg, "ramp", where, default=DEFAULT_RAMP)
        if not 0.0 < ramp <= 0.5:
            raise ConfigError("ramp must be in (0, 0.5]", column=f"{where}.ramp", found=ramp)
        p = {"type": kind, "ramp": ramp, "v0": v, "v1": v, "dpsi": 0.0, "dh": 0.0,
             "coordinated": False}
        if kind in ("static", "hold"):
            p["duration"] = _num(seg, "duration", where, positive=True)
            if kind == "static" and v != 0.0:
                raise ConfigError(f"'static' needs zero speed but the speed is {v} m/s here; "
                                  "decelerate to 0 first", column=where)
        elif kind in ("accelerate", "decelerate"):
            target = _num(seg, "speed", where)
            if target < 0:
                raise ConfigError("speed must be >= 0", column=f"{where}.speed", found=target)
            dv = target - v
            if dv == 0.0 or (kind == "accelerate") != (dv > 0):
                raise ConfigError(f"{kind} from {v} m/s to {target} m/s", column=f"{where}.speed",
                                  expected="a higher speed" if kind == "accelerate" else "a lower speed")
            p["duration"] = _step_duration(seg, where, dv, "acceleration", ramp)
            p["v1"] = target
            v = target
        elif kind == "turn":
            dpsi = _num(seg, "angle", where)
            p["duration"] = _step_duration(seg, where, dpsi, "rate", ramp)
            p["dpsi"] = dpsi
        elif kind == "coordinated_turn":
            if v <= 0.0:
                raise ConfigError("a coordinated turn needs a non-zero speed", column=where)
            dpsi = _num(seg, "angle", where)
            if "bank" in seg:
                bank = _num(seg, "bank", where, positive=True)
                if bank >= np.pi / 2:
                    raise ConfigError("bank must be below 90 deg", column=f"{where}.bank")
                seg = {**seg, "bank": g * np.tan(bank) / v}  # plateau turn rate [rad/s]
            p["duration"] = _step_duration(seg, where, dpsi, "bank", ramp)
            p["dpsi"] = dpsi
            p["coordinated"] = True
        else:  # climb / descend
            dh = _num(seg, "height_change", where, positive=True)
            if v <= 0.0:
                raise ConfigError(f"'{kind}' needs a non-zero horizontal speed", column=where)
            p["dh"] = dh if kind == "climb" else -dh
            p["duration"] = _step_duration(seg, where, dh, "rate", ramp)
        p["start"] = t
        t += p["duration"]
        p["stop"] = t
        plan.append(p)
    return plan


def _vehicle_channels(tr: np.ndarray, plan: list[dict], speed0: float, heading0: float):
    """Evaluate v_h, psi, dpsi/dt, v_u and the coordinated-turn mask on relative times ``tr``."""
    n = tr.size
    vh = np.full(n, speed0)
    psi = np.full(n, heading0)
    psid = np.zeros(n)
    vu = np.zeros(n)
    coord = np.zeros(n, bool)
    h0 = heading0
    for p in plan:
        i0, i1 = np.searchsorted(tr, [p["start"], p["stop"]], side="left")
        if p is plan[-1]:
            i1 = n
        sl = slice(i0, i1)
        T = p["duration"]
        u = (tr[sl] - p["start"]) / T
        S, dS = smooth_step(u, p["ramp"])
        vh[sl] = p["v0"] + (p["v1"] - p["v0"]) * S
        psi[sl] = h0 + p["dpsi"] * S
        psid[sl] = p["dpsi"] * dS / T
        vu[sl] = p["dh"] * dS / T
        coord[sl] = p["coordinated"]
        h0 += p["dpsi"]
    return vh, psi, psid, vu, coord


def _vehicle_attitude(vehicle, vel, psid, coord, roll_gain, g):
    """Roll and pitch of the vehicle models: pitch along the velocity, coordinated-turn bank
    (:func:`insgnss.trajectory_tools.vne_to_rpy` with the analytic turn rate) for aircraft and
    ``coordinated_turn`` segments, body roll ``-k a_lat`` for land vehicles."""
    roll_c, pitch, _ = vne_to_rpy(vel, g=g, turn_rate=psid)
    if vehicle == "aircraft":
        return roll_c, pitch
    a_lat = np.hypot(vel[:, 0], vel[:, 1]) * psid
    return np.where(coord, roll_c, -roll_gain * a_lat), pitch


# --- pedestrian ---------------------------------------------------------------------------------
def _pedestrian(tr: np.ndarray, segments: Sequence[dict], heading0: float):
    """Foot-mounted IMU channels on relative times ``tr``: velocity ENU (N,3), roll, pitch,
    heading, swing mask and the plan."""
    plan = []
    strides = []  # (t_swing_start, T_swing, L, H, dpsi, dh, b, c, psi_start)
    t = 0.0
    psi = heading0
    for i, seg in enumerate(segments):
        where = f"trajectory.segments[{i}]"
        if not isinstance(seg, dict) or "type" not in seg:
            raise ConfigError("each segment needs a 'type'", column=where, expected=["stand", "walk"])
        kind = seg["type"]
        if kind not in PEDESTRIAN_SEGMENTS:
            raise ConfigError(f"segment type {kind!r} is not available for a pedestrian",
                              column=f"{where}.type", expected=["stand", "walk"])
        _check_keys(seg, SEGMENT_KEYS[kind], where)
        if kind in ("stand", "static"):
            d = _num(seg, "duration", where, positive=True)
            plan.append({"type": kind, "start": t, "stop": t + d, "duration": d})
            t += d
            continue
        steps = seg.get("steps")
        if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
            raise ConfigError("'steps' must be a positive integer", column=f"{where}.steps",
                              found=steps)
        q = {k: _num(seg, k, where, default=v) for k, v in WALK_DEFAULTS.items()}
        for k in ("stride_length", "stride_time", "clearance"):
            if q[k] <= 0:
                raise ConfigError("must be positive", column=f"{where}.{k}", found=q[k])
        if not 0.0 < q["stance_fraction"] < 1.0:
            raise ConfigError("must be in (0, 1)", column=f"{where}.stance_fraction",
                              found=q["stance_fraction"])
        t_st = q["stride_time"] * q["stance_fraction"]
        t_sw = q["stride_time"] - t_st
        a1, a2 = q["toe_off_pitch"], q["heel_strike_pitch"]
        # p(1/4) = -a1, p(3/4) = a2 with p = sin^2(pi u) (c - b cos(pi u))
        c = a2 - a1
        b = np.sqrt(2.0) * (a2 + a1)
        dpsi = q["turn"] / steps
        dh = q["height_change"] / steps
        start = t
        for _ in range(steps):
            strides.append((t + t_st, t_sw, q["stride_length"], q["clearance"], dpsi, dh, b, c, psi))
            psi += dpsi
            t += q["stride_time"]
        plan.append({"type": "walk", "start": start, "stop": t, "duration": t - start,
                     "steps": steps, **q})
    n = tr.size
    vel = np.zeros((n, 3))
    pitch = np.zeros(n)
    head = np.full(n, psi)  # after the last stride
    swing = np.zeros(n, bool)
    if strides:
        S = np.array(strides)
        # heading before each stride's swing = psi_start; during swing smooth step
        k = np.searchsorted(S[:, 0], tr, side="right") - 1  # last swing that started
        before_first = k < 0
        kk = np.where(before_first, 0, k)
        t0, Ts, L, H, dpsi, dh, b, c, psi0 = S[kk].T
        u = (tr - t0) / Ts
        inside = (~before_first) & (u >= 0.0) & (u < 1.0)
        ui = np.where(inside, u, 0.0)
        Sst, dSst = smooth_step(ui, 0.5)
        heading = np.where(inside, psi0 + dpsi * Sst, np.where(before_first, heading0, psi0 + dpsi))
        speed = np.where(inside, L / Ts * (1.0 - np.cos(2.0 * np.pi * ui)), 0.0)
        vu = np.where(inside, H * np.pi / Ts * np.sin(2.0 * np.pi * ui) + dh * dSst / Ts, 0.0)
        s2 = np.sin(np.pi * ui) ** 2
        pitch = np.where(inside, s2 * (c - b * np.cos(np.pi * ui)), 0.0)
        vel[:, 0] = speed * np.sin(heading)
        vel[:, 1] = speed * np.cos(heading)
        vel[:, 2] = vu
        head = heading
        swing = inside
    roll = np.zeros(n)
    return vel, roll, pitch, head, swing, plan


# --- waypoints ----------------------------------------------------------------------------------
def _waypoint_positions(waypoints: Sequence[dict], lat0, lon0, h0):
    times, lat, lon, h = [], [], [], []
    for i, wp in enumerate(waypoints):
        where = f"trajectory.waypoints[{i}]"
        if not isinstance(wp, dict):
            raise ConfigError("a waypoint is a table {time=..., east=..., north=..., up=...}",
                              column=where)
        _check_keys(wp, WAYPOINT_KEYS, where)
        times.append(_num(wp, "time", where))
        geo = {"lat", "lon"} & set(wp)
        enu = {"east", "north"} & set(wp)
        if geo and enu:
            raise ConfigError("give either east/north/up or lat/lon/height", column=where)
        if geo:
            la, lo = np.radians(_num(wp, "lat", where)), np.radians(_num(wp, "lon", where))
            hh = _num(wp, "height", where, default=h0)
        else:
            e, nn = _num(wp, "east", where, default=0.0), _num(wp, "north", where, default=0.0)
            la, lo, hh = enu_to_geodetic(e, nn, _num(wp, "up", where, default=0.0), lat0, lon0, h0)
        lat.append(float(la))
        lon.append(float(lo))
        h.append(float(hh))
    times = np.array(times)
    if times.size < 2:
        raise ConfigError("need at least two waypoints", column="trajectory.waypoints")
    if np.any(np.diff(times) <= 0):
        raise ConfigError("waypoint times must increase", column="trajectory.waypoints",
                          found=times.tolist())
    return times, np.array(lat), np.array(lon), np.array(h)


def _time_warp(tr, times, start_at_rest, end_at_rest):
    """Time law ``w(t)`` (and ``dw/dt``) with ``w(t_k) = t_k`` at every waypoint that brings the
    vehicle smoothly to rest at the first / last waypoint (see :func:`_waypoint_channels`)."""
    w = tr.copy()
    dw = np.ones_like(tr)
    t0, t1, tn1, tn = times[0], times[1], times[-2], times[-1]
    if times.size == 2 and start_at_rest and end_at_rest:
        d = tn - t0
        u = (tr - t0) / d
        w = t0 + d * (10 * u**3 - 15 * u**4 + 6 * u**5)
        dw = 30 * u**2 * (1 - u) ** 2
        return w, dw
    if start_at_rest:
        d = t1 - t0
        m = tr < t1
        u = (tr[m] - t0) / d
        w[m] = t0 + d * (6 * u**3 - 8 * u**4 + 3 * u**5)
        dw[m] = 18 * u**2 - 32 * u**3 + 15 * u**4
    if end_at_rest:
        d = tn - tn1
        m = tr > tn1
        u = (tn - tr[m]) / d
        w[m] = tn - d * (6 * u**3 - 8 * u**4 + 3 * u**5)
        dw[m] = 18 * u**2 - 32 * u**3 + 15 * u**4
    return w, dw


def _waypoint_channels(tr, times, lat, lon, h, start_at_rest, end_at_rest, heading0):
    """Waypoint trajectory: a C2 cubic spline ``p(s)`` of lat, lon, h through the waypoints at
    their times gives the *path* (direction, grade, curvature); the vehicle moves along it with
    the time law ``s = w(t)``, ``w(t_k) = t_k``, which is the identity except in the first / last
    interval when starting / ending at rest: there ``w = t0 + d phi((t - t0)/d)`` with the
    quintic ``phi(u) = 6u^3 - 8u^4 + 3u^5`` (``phi(0) = phi'(0) = phi''(0) = 0``, ``phi(1) = 1``,
    ``phi'(1) = 1``, ``phi''(1) = 0``; ``10u^3 - 15u^4 + 6u^5`` when one interval does both).
    The velocity ``p'(w) dw/dt`` is then exactly zero at rest, while heading and pitch follow the
    path tangent ``p'`` and the turn rate ``(dpsi/ds) dw/dt`` goes to zero with the speed, as for a
    real vehicle (a clamped spline instead would start on a cusp with a jump of the turn rate).
    """
    free = "not-a-knot" if times.size >= 4 else (2, 0.0)
    splines = [CubicSpline(times, x, bc_type=(free, free)) for x in (lat, lon, h)]
    w, dw = _time_warp(tr, times, start_at_rest, end_at_rest)
    la, lo, hh = (s(w) for s in splines)
    dla, dlo, dhh = (s(w, 1) for s in splines)
    d2la, d2lo = (s(w, 2) for s in splines[:2])
    M, N = radii(la)
    cl = np.cos(la)
    # path tangent and its derivative (per unit of s), metres; the small terms from dM/ds,
    # dN/ds and d(cos lat)/ds are neglected in the curvature: they only affect the roll of the
    # vehicle model, not the consistency of the truth
    pe = dlo * (N + hh) * cl
    pn = dla * (M + hh)
    pu = dhh
    qe = d2lo * (N + hh) * cl
    qn = d2la * (M + hh)
    ph = np.hypot(pe, pn)
    ok = ph > 1e-12
    heading = np.where(ok, np.arctan2(pe, pn), heading0)
    pitch = np.arctan2(pu, ph)
    psi_s = np.where(ok, (qe * pn - qn * pe) / np.where(ok, ph, 1.0) ** 2, 0.0)
    vel = np.column_stack([pe, pn, pu]) * dw[:, None]
    return vel, ph * dw, np.unwrap(heading), pitch, psi_s * dw


# --- public API ---------------------------------------------------------------------------------
def generate(
    *,
    rate: float,
    lat: float,
    lon: float,
    height: float = 0.0,
    heading: float = 0.0,
    speed: float = 0.0,
    vehicle: str = "land",
    segments: Sequence[dict] | None = None,
    waypoints: Sequence[dict] | None = None,
    start_at_rest: bool = False,
    end_at_rest: bool = False,
    roll_gain: float = 0.0,
    duration: float | None = None,
    start_time: float = 0.0,
    frame: str = "enu",
    wander_angle: float = 0.0,
) -> Trajectory:
    """Generate a truth trajectory at the IMU rate.

    Parameters
    ----------
    rate : float
        Sample rate [Hz].
    lat, lon, height : float
        Start position [rad, rad, m].
    heading : float
        Initial heading [rad, clockwise from north].
    speed : float
        Initial horizontal speed [m/s] (segment mode).
    vehicle : {"land", "aircraft", "pedestrian"}
    segments : list of dict, optional
        Segment tables in SI units and **radians** (the scenario loader converts the degrees of
        the file, see :data:`ANGLE_KEYS`). Types and keys: ``static(duration)``,
        ``hold(duration)``, ``accelerate/decelerate(speed, acceleration | duration, ramp)``,
        ``turn(angle, rate | duration, ramp)`` (angle positive to the right / clockwise),
        ``coordinated_turn(angle, bank | duration, ramp)``, ``climb/descend(height_change, rate |
        duration, ramp)`` (rate = plateau vertical speed); pedestrian: ``stand(duration)``,
        ``walk(steps, stride_length, stride_time, stance_fraction, clearance, toe_off_pitch,
        heel_strike_pitch, turn, height_change)`` (defaults in :data:`WALK_DEFAULTS`).
    waypoints : list of dict, optional
        ``{time, east, north, up}`` [s, m relative to the start position] or
        ``{time, lat, lon, height}`` [s, deg, deg, m] (waypoint tables come straight from the
        scenario file). Times are relative to ``start_time``; the first must be 0. The
        trajectory passes through every waypoint at its time (to the mm level of the
        trapezoidal position integration).
    start_at_rest, end_at_rest : bool
        Waypoint mode: start / end at rest at the first / last waypoint (smooth quintic time
        law in the first / last interval; the waypoint times are kept).
    roll_gain : float
        Land vehicle body roll per lateral acceleration [rad per m/s^2].
    duration : float, optional
        Total duration [s]; defaults to the segments' (or waypoints') total. A longer duration
        continues the final state (constant velocity); a shorter one truncates.
    start_time : float
        Time stamp of the first sample [s].
    frame : {"enu", "wander"}
        ``"wander"`` (vehicle segments only) builds the route in the wander-azimuth frame
        (:mod:`insgnss.mechanization.wander`): the course channel is the heading relative to
        the wander frame, which does not turn about the vertical relative to the Earth, so a
        segment without turns flies a geodesic, also straight over a pole; position is
        integrated as ``C_w^e`` by the wander step's own rule
        (:func:`~insgnss.mechanization.wander.integrate_position_wander`), and the truth gains
        a ``wander_angle`` column. The ENU generator cannot pass a pole (``1/cos(lat)``).
    wander_angle : float
        Initial wander angle [rad] (``frame="wander"``); the initial heading is true heading.

    Returns
    -------
    Trajectory
    """
    if vehicle not in VEHICLES:
        raise ConfigError(f"unknown vehicle {vehicle!r}", column="trajectory.vehicle",
                          expected=list(VEHICLES))
    if (segments is None) == (waypoints is None):
        raise ConfigError("give exactly one of 'segments' and 'waypoints'", column="trajectory")
    if not rate > 0:
        raise ConfigError("rate must be positive", column="scenario.imu_rate", found=rate)
    check_latitude(lat, "trajectory.lat")
    wander = frame_id(frame) == FRAME_WANDER
    if wander and (waypoints is not None or vehicle == "pedestrian"):
        raise ConfigError("frame 'wander' is available for vehicle segment profiles only",
                          column="trajectory.frame")
    g = normal_gravity(lat, height)
    seg_table: list[dict] = []
    if waypoints is not None:
        times, wlat, wlon, wh = _waypoint_positions(waypoints, lat, lon, height)
        if times[0] != 0.0:
            raise ConfigError("the first waypoint's time must be 0 (the trajectory start)",
                              column="trajectory.waypoints[0].time", found=times[0])
        total = float(times[-1]) if duration is None else float(duration)
        t = _time_grid(total, rate, start_time)
        tr = np.clip(t - start_time, 0.0, times[-1])
        vel, vh, psi, pitch_wp, psid = _waypoint_channels(tr, times, wlat, wlon, wh,
                                                          start_at_rest, end_at_rest, heading)
        vu = vel[:, 2]
        after = (t - start_time) > times[-1]
        if np.any(after):  # continue with the final velocity
            vel[after] = vel[~after][-1]
            psid[after] = 0.0
        coord = np.zeros(t.size, bool)
        roll, _ = _vehicle_attitude(vehicle if vehicle != "pedestrian" else "land",
                                    vel, psid, coord, roll_gain, g)
        pitch = pitch_wp
        lat0, lon0, h0 = wlat[0], wlon[0], wh[0]
        stationary = np.all(vel == 0.0, axis=1) & (psid == 0.0)
        seg_table = [{"type": "waypoints", "start": 0.0, "stop": float(times[-1]),
                      "times": times.tolist()}]
    elif vehicle == "pedestrian":
        tr_probe = np.zeros(1)
        _, _, _, _, _, plan = _pedestrian(tr_probe, segments, heading)
        total = plan[-1]["stop"] if duration is None else float(duration)
        t = _time_grid(total, rate, start_time)
        vel, roll, pitch, psi, swing, plan = _pedestrian(t - start_time, segments, heading)
        stationary = ~swing
        lat0, lon0, h0 = lat, lon, height
        seg_table = plan
    else:
        plan = _plan_vehicle_segments(segments, speed, g)
        if not plan:
            raise ConfigError("no segments", column="trajectory.segments")
        total = plan[-1]["stop"] if duration is None else float(duration)
        t = _time_grid(total, rate, start_time)
        # course from north (ENU) or from the wander frame's y axis (A_w = A + alpha)
        psi0 = heading + wander_angle if wander else heading
        vh, psi, psid, vu, coord = _vehicle_channels(t - start_time, plan, speed, psi0)
        vel = np.empty((t.size, 3))
        np.multiply(vh, np.sin(psi), out=vel[:, 0])
        np.multiply(vh, np.cos(psi), out=vel[:, 1])
        vel[:, 2] = vu
        roll, pitch = _vehicle_attitude(vehicle, vel, psid, coord, roll_gain, g)
        stationary = (vh == 0.0) & (vu == 0.0) & (psid == 0.0)
        lat0, lon0, h0 = lat, lon, height
        seg_table = [{k: p[k] for k in ("type", "start", "stop", "duration")} for p in plan]
    if wander:
        Cne, hw = integrate_position_wander(t, vel, lat0, lon0, h0, wander_angle)
        truth = wander_table(t, Cne, hw, vel, euler_to_dcm(roll, pitch, psi))
        truth["stationary"] = stationary.astype(float)
        return Trajectory(truth=truth, vehicle=vehicle, segments=seg_table)
    pos = integrate_position(t, vel, lat0, lon0, h0)
    heading_out = np.mod(psi, 2.0 * np.pi)
    data = np.empty((t.size, 10))
    data[:, 0:3] = pos
    data[:, 3:6] = vel
    data[:, 6] = roll
    data[:, 7] = pitch
    data[:, 8] = heading_out
    data[:, 9] = stationary
    truth = pd.DataFrame(data, index=pd.Index(t, name="time"), columns=NAV_COLS + ["stationary"])
    return Trajectory(truth=truth, vehicle=vehicle, segments=seg_table)
