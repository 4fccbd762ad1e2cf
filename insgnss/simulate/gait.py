"""Foot gait simulator: a rigid foot that rolls over heel and toe, with heel-strike impact.

Model
-----
The instrumented foot is a rigid body moving in its sagittal plane (pitch ``theta``, positive
toes up, about the body right axis) along the heading ``psi`` (roll zero). Two contact points
on the sole, the heel ``H`` and the toe (metatarsal heads) ``T``, ``foot_length`` apart, and the
sensor ``S`` at ``(sensor_forward, sensor_up)`` from the heel in the foot frame give

    p_S = p_H + f(psi) (y cos(theta) - z sin(theta)) + u (y sin(theta) + z cos(theta))

with ``f = (sin psi, cos psi, 0)`` (forward, ENU), ``u = (0, 0, 1)`` and ``(y, z)`` the
sensor offset. One step moves the foot from ground point ``G_j`` (heel on the floor, foot
flat) to ``G_{j+1} = G_j + L f(psi_{j+1})`` (+ a floor rise for stairs) in four phases
(Perry 1992 gait phases; fractions of the stride time ``T``, heel strike at 0):

1. **heel-off / toe rocker** (``heel_off`` .. ``toe_off``): rotation about the fixed toe
   (where the previous stance left it), ``theta`` -> ``-toe_off_pitch`` by a quintic with zero
   rate and acceleration at heel-off and the rate ``toe_off_rate`` at toe-off; the heel and the
   sensor rise (the sensor is not still although the toe is);
2. **swing** (``toe_off`` .. 1): heel position (ENU) and pitch by quintic Hermite interpolation
   between the toe-off state (position, velocity, acceleration of the rocker) and the heel
   contact state (heel ``impact_time * v_c / 2`` before ``G_{j+1}``, velocity ``v_c`` =
   ``heel_strike_velocity`` forward/down, pitch ``heel_strike_pitch`` with rate
   ``heel_strike_rate``), plus a clearance bump ``clearance * 64 u^3 (1-u)^3``; the heading
   turns by a quintic smooth step;
3. **impact + heel rocker** (0 .. ``foot_flat``): the heel decelerates from ``v_c`` to rest in
   ``impact_time`` with a raised-cosine deceleration (peak ``2 |v_c| / impact_time``: the
   heel-strike shock), then stays; meanwhile the foot rotates about the heel down to flat
   (quintic, zero rate at foot flat);
4. **foot flat** (``foot_flat`` .. ``heel_off``): truly still (the only ``stationary``
   samples besides standing), or, with ``stance_roll`` > 0, rolling forward (toes down) by
   that angle about the sole point ``roll_pivot`` (a quintic smooth step): real feet keep
   turning at a few deg/s through the stance, so the sensor moves at ``w x r`` while a
   detector calls it still.

The kinematics are evaluated in closed form on a fine grid (``oversample`` times the output
rate), the position is the trapezoidal integral of the velocity (as in
:mod:`insgnss.simulate.trajectory`), and the IMU increments are the exact inverse
mechanization on the fine grid summed over each output interval. They therefore contain the
intra-interval coning and sculling of the real motion, as a sensor that integrates its
rates would deliver them; ``ideal`` is the exact dual of the output-rate truth (no
intra-interval motion: velocity and attitude are reproduced exactly, position to the
output-rate trapezoid truncation, 0.1 mm within a swing and 1 um per stride, because the truth
position is the fine-grid integral). An accelerometer or gyro range clips the fine-grid samples before they
are summed (saturation happens on the raw signal, inside the impact).

References
----------
- J. Perry, *Gait Analysis: Normal and Pathological Function*, 1992 (heel, ankle and forefoot
  rockers; phase timing).
- Skog, Nilsson, Handel, "Evaluation of zero-velocity detectors for foot-mounted inertial
  navigation systems", IPIN 2010; Nilsson, Skog, Handel, "Foot-mounted INS for everybody",
  IPIN 2012 (the sensor is not still during the rockers).
- Savage, "Strapdown inertial navigation integration algorithm design", JGCD 21 (1998)
  (coning and sculling are intra-interval effects of summed increments).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields, replace

import numpy as np
import pandas as pd

from ..attitude import euler_to_dcm
from ..errors import ConfigError
from ..imu import increments_table, rates_table
from ..mechanization.inverse import integrate_position, inverse_increments, inverse_mechanize
from ..mechanization.strapdown import NAV_COLS

#: phase codes of :attr:`GaitWalk.truth` ``phase``
STAND, TOE_ROCKER, SWING, IMPACT, HEEL_ROCKER, FOOT_FLAT, STANCE_ROLL = 0, 1, 2, 3, 4, 5, 6
PHASES = {STAND: "stand", TOE_ROCKER: "toe_rocker", SWING: "swing", IMPACT: "impact",
          HEEL_ROCKER: "heel_rocker", FOOT_FLAT: "foot_flat", STANCE_ROLL: "stance_roll"}


@dataclass(frozen=True)
class GaitParams:
    """One walking gait (SI units, radians; adult walking at ~1.3 m/s).

    Attributes
    ----------
    stride_length, stride_time : float
        Distance [m] and duration [s] of one stride of the instrumented foot.
    foot_flat, heel_off, toe_off : float
        Ends of the heel rocker, start of the toe rocker, end of stance, as fractions of the
        stride from heel strike (0.10, 0.35, 0.60: Perry 1992).
    heel_strike_pitch, toe_off_pitch : float
        Foot pitch at heel strike (toes up, > 0) and at toe-off (heel up, magnitude) [rad].
    heel_strike_rate, toe_off_rate : float
        Pitch rate at heel contact and at toe-off [rad/s] (both negative: the foot plantar-flexes).
    heel_strike_velocity : (float, float)
        Heel velocity at contact: forward and downward [m/s].
    impact_time : float
        Duration of the heel deceleration [s] (shoe and heel pad; 0.01-0.03 s).
    clearance : float
        Amplitude of the mid-swing lift added to the interpolated heel path [m].
    foot_length : float
        Heel to toe (metatarsal) contact distance [m].
    sensor_forward, sensor_up : float
        Sensor position in the foot frame from the heel contact point [m] (instep: 0.12, 0.06).
    turn : float
        Heading change per stride [rad, clockwise], applied during the swing.
    rise : float
        Floor height change per stride [m] (0: level floor; stairs: the step height x 2).
    stance_roll : float
        Pitch change [rad] during the mid-stance (0: the foot is flat and still): the foot
        keeps rolling forward (toes down) about the sole point ``roll_pivot`` [m from the
        heel], as real feet do at a few deg/s between the heel and the toe rockers.
    roll_pivot : float
        Sole point of the mid-stance roll, forward of the heel [m].
    """

    stride_length: float = 1.4
    stride_time: float = 1.1
    foot_flat: float = 0.10
    heel_off: float = 0.35
    toe_off: float = 0.60
    heel_strike_pitch: float = np.radians(20.0)
    toe_off_pitch: float = np.radians(50.0)
    heel_strike_rate: float = np.radians(-60.0)
    toe_off_rate: float = np.radians(-300.0)
    heel_strike_velocity: tuple[float, float] = (0.3, 0.3)
    impact_time: float = 0.015
    clearance: float = 0.05
    foot_length: float = 0.18
    sensor_forward: float = 0.12
    sensor_up: float = 0.06
    turn: float = 0.0
    rise: float = 0.0
    stance_roll: float = 0.0
    roll_pivot: float = 0.12

    def __post_init__(self):
        for name in ("stride_length", "stride_time", "impact_time", "foot_length"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError("must be positive", column=name, found=v)
        if not 0.0 < self.foot_flat < self.heel_off < self.toe_off < 1.0:
            raise ConfigError("phase fractions must satisfy 0 < foot_flat < heel_off < toe_off "
                              "< 1", column="foot_flat/heel_off/toe_off",
                              found=(self.foot_flat, self.heel_off, self.toe_off))
        if self.impact_time >= self.foot_flat * self.stride_time:
            raise ConfigError("the impact must end before foot flat", column="impact_time",
                              expected=f"< {self.foot_flat * self.stride_time:.3f} s",
                              found=self.impact_time)

    def durations(self) -> tuple[float, float, float, float]:
        """(toe rocker, swing, heel rocker incl. impact, foot flat) [s]."""
        T = self.stride_time
        return ((self.toe_off - self.heel_off) * T, (1.0 - self.toe_off) * T,
                self.foot_flat * T, (self.heel_off - self.foot_flat) * T)

    @classmethod
    def from_dict(cls, d: dict, base: GaitParams | None = None) -> GaitParams:
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ConfigError("unknown gait parameter", column=unknown[0],
                              expected=sorted(names), found=unknown)
        if "heel_strike_velocity" in d:
            d = {**d, "heel_strike_velocity": tuple(float(x) for x in d["heel_strike_velocity"])}
        return replace(base or cls(), **d)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class GaitWalk:
    """Result of :func:`simulate_walk`.

    Attributes
    ----------
    truth : DataFrame
        Output-rate truth of the sensor point: :data:`NAV_COLS`, ``stationary`` (1.0 in foot
        flat and standing) and ``phase`` (:data:`PHASES` codes).
    imu : DataFrame
        IMU table (increments ``dtheta_* dv_*`` or rates), body frame RFU, from the fine-grid
        motion (coning, sculling and clipping included).
    ideal : DataFrame
        Exact dual increments of ``truth`` at the output rate (no intra-interval motion).
    stances : DataFrame
        One row per foot-flat interval: ``start stop`` [s], ``east north up`` of the heel
        contact point relative to the start [m].
    params : list of GaitParams
        The gait of each walk segment.
    """

    truth: pd.DataFrame
    imu: pd.DataFrame
    ideal: pd.DataFrame
    stances: pd.DataFrame
    params: list


# --- closed-form pieces ------------------------------------------------------------------------
_M5 = np.array([[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 0, 2, 0, 0, 0],
                [1, 1, 1, 1, 1, 1], [0, 1, 2, 3, 4, 5], [0, 0, 2, 6, 12, 20]], float)
_M5_INV = np.linalg.inv(_M5)


def quintic(u: np.ndarray, D: float, p0, v0, a0, p1, v1, a1) -> tuple[np.ndarray, np.ndarray]:
    """Quintic Hermite on ``t = u D``, ``u in [0, 1]``: value and time derivative, matching
    value, rate and acceleration at both ends (arrays of any trailing shape)."""
    p0, v0, a0, p1, v1, a1 = (np.asarray(x, float) for x in (p0, v0, a0, p1, v1, a1))
    rhs = np.stack([p0, v0 * D, a0 * D * D, p1, v1 * D, a1 * D * D])
    c = np.tensordot(_M5_INV, rhs, axes=1)  # (6, ...)
    u = np.asarray(u, float)
    pw = np.stack([u**i for i in range(6)], -1)  # (n, 6)
    dpw = np.stack([i * u ** max(i - 1, 0) if i else np.zeros_like(u) for i in range(6)], -1)
    c2 = c.reshape(6, -1)
    val = (pw @ c2).reshape(u.shape + p0.shape)
    der = (dpw @ c2).reshape(u.shape + p0.shape) / D
    return val, der


def _fwd(psi):
    return np.stack([np.sin(psi), np.cos(psi), np.zeros_like(psi)], -1)


def _offset(theta, psi, y, z):
    """World offset of the foot point (y forward, z up) and its partials d/dtheta, d/dpsi."""
    f = _fwd(psi)
    df = np.stack([np.cos(psi), -np.sin(psi), np.zeros_like(psi)], -1)
    c, s = np.cos(theta), np.sin(theta)
    h = (y * c - z * s)[..., None]
    vert = (y * s + z * c)
    off = f * h
    off[..., 2] += vert
    d_th = f * (-y * s - z * c)[..., None]
    d_th[..., 2] += y * c - z * s
    d_psi = df * h
    return off, d_th, d_psi


def _plan(segments: Sequence[dict], base: GaitParams, heading0: float):
    """Steps (start time, params, psi_from, psi_to, G_from, G_to) and stand intervals."""
    steps = []
    plan = []
    t = 0.0
    psi = heading0
    G = np.zeros(3)
    for i, seg in enumerate(segments):
        where = f"segments[{i}]"
        if not isinstance(seg, dict) or seg.get("type") not in ("stand", "walk"):
            raise ConfigError("each segment is a table with type 'stand' or 'walk'",
                              column=f"{where}.type", found=repr(seg))
        if seg["type"] == "stand":
            d = float(seg.get("duration", 0.0))
            if not d > 0:
                raise ConfigError("stand needs a positive duration", column=f"{where}.duration",
                                  found=seg.get("duration"))
            plan.append(("stand", t, t + d))
            t += d
            continue
        n = seg.get("steps")
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ConfigError("'steps' must be a positive integer", column=f"{where}.steps",
                              found=n)
        p = GaitParams.from_dict({k: v for k, v in seg.items() if k not in ("type", "steps")},
                                 base)
        d_tr, d_sw, d_hr, d_ff = p.durations()
        start = t
        for _ in range(n):
            psi1 = psi + p.turn
            G1 = G + p.stride_length * _fwd(np.array(psi1)) + np.array([0.0, 0.0, p.rise])
            steps.append((t, p, psi, psi1, G.copy(), G1))
            psi, G = psi1, G1
            t += d_tr + d_sw + d_hr + d_ff
        plan.append(("walk", start, t))
    return steps, plan, t


def _kinematics(tr: np.ndarray, steps, heading0: float, sensor: tuple[float, float] | None):
    """Sensor position (relative to the first heel point), velocity (N,3), pitch, heading (N,)
    and phase codes on the sorted times ``tr`` (one Python iteration per step)."""
    n = tr.size
    theta = np.zeros(n)
    psi = np.full(n, heading0)
    dtheta = np.zeros(n)
    dpsi = np.zeros(n)
    pH = np.zeros((n, 3))
    vH = np.zeros((n, 3))
    phase = np.full(n, STAND, np.int8)
    ys, zs = (GaitParams().sensor_forward, GaitParams().sensor_up) if sensor is None else sensor
    z3 = np.zeros(3)
    heel_end, theta_end = np.zeros(3), 0.0  # foot pose at the end of the previous stance
    for (t0, p, psi0, psi1, _G0, G1) in steps:
        if sensor is None:
            ys, zs = p.sensor_forward, p.sensor_up
        d_tr, d_sw, d_hr, d_ff = p.durations()
        L = p.foot_length
        i0, i1, i2, i3, i4 = np.searchsorted(
            tr, [t0, t0 + d_tr, t0 + d_tr + d_sw, t0 + d_tr + d_sw + d_hr,
                 t0 + d_tr + d_sw + d_hr + d_ff])
        f1 = _fwd(np.array(psi1))
        # 1. toe rocker about the toe where the previous stance left it
        toe_rel, _, _ = _offset(np.array(theta_end), np.array(psi0), L, 0.0)
        toe = heel_end + toe_rel
        s = slice(i0, i1)
        u = (tr[s] - t0) / d_tr
        th, dth = quintic(u, d_tr, theta_end, 0.0, 0.0, -p.toe_off_pitch, p.toe_off_rate, 0.0)
        rel, d_rel, _ = _offset(th, np.full(th.shape, psi0), -L, 0.0)
        pH[s], vH[s] = toe + rel, d_rel * dth[:, None]
        theta[s], dtheta[s], psi[s], dpsi[s], phase[s] = th, dth, psi0, 0.0, TOE_ROCKER
        # toe-off state of the heel: theta' = toe_off_rate, theta'' = 0; the second
        # theta-derivative of a sagittal offset is minus the offset
        th_e, w_e = -p.toe_off_pitch, p.toe_off_rate
        rel_e, d_e, _ = _offset(np.array(th_e), np.array(psi0), -L, 0.0)
        pH0, vH0, aH0 = toe + rel_e, d_e * w_e, -rel_e * w_e * w_e
        # 2. swing to the pre-impact heel point with the contact velocity v_c
        vc_f, vc_d = p.heel_strike_velocity
        vc = vc_f * f1 - np.array([0.0, 0.0, vc_d])
        pH1 = G1 - vc * p.impact_time / 2.0
        s = slice(i1, i2)
        u = (tr[s] - t0 - d_tr) / d_sw
        ph, dph = quintic(u, d_sw, pH0, vH0, aH0, pH1, vc, z3)
        ph[:, 2] += p.clearance * 64.0 * u**3 * (1.0 - u) ** 3
        dph[:, 2] += p.clearance * 192.0 * u**2 * (1.0 - u) ** 2 * (1.0 - 2.0 * u) / d_sw
        th, dth = quintic(u, d_sw, th_e, w_e, 0.0, p.heel_strike_pitch, p.heel_strike_rate, 0.0)
        s5, ds5 = quintic(u, d_sw, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0)
        pH[s], vH[s], theta[s], dtheta[s] = ph, dph, th, dth
        psi[s], dpsi[s], phase[s] = psi0 + (psi1 - psi0) * s5, (psi1 - psi0) * ds5, SWING
        # 3. impact (raised-cosine deceleration of the heel) and heel rocker
        s = slice(i2, i3)
        tau = tr[s] - (t0 + d_tr + d_sw)
        th, dth = quintic(tau / d_hr, d_hr, p.heel_strike_pitch, p.heel_strike_rate, 0.0,
                          0.0, 0.0, 0.0)
        ui = np.clip(tau / p.impact_time, 0.0, 1.0)
        removed = ui - np.sin(2.0 * np.pi * ui) / (2.0 * np.pi)
        travel = p.impact_time * (ui - ui**2 / 2.0
                                  - (1.0 - np.cos(2.0 * np.pi * ui)) / (4.0 * np.pi**2))
        pH[s], vH[s] = pH1 + vc * travel[:, None], vc * (1.0 - removed)[:, None]
        theta[s], dtheta[s], psi[s], dpsi[s] = th, dth, psi1, 0.0
        phase[s] = np.where(tau < p.impact_time, IMPACT, HEEL_ROCKER)
        # 4. foot flat: still, or rolling about the sole point ``roll_pivot`` from the heel
        #    by ``-stance_roll`` (smooth step, zero rate at both ends)
        s = slice(i3, i4)
        pivot = G1 + p.roll_pivot * f1
        u = (tr[s] - (t0 + d_tr + d_sw + d_hr)) / d_ff
        th, dth = quintic(u, d_ff, 0.0, 0.0, 0.0, -p.stance_roll, 0.0, 0.0)
        rel, d_rel, _ = _offset(th, np.full(th.shape, psi1), -p.roll_pivot, 0.0)
        pH[s], vH[s], theta[s], dtheta[s] = pivot + rel, d_rel * dth[:, None], th, dth
        psi[s], dpsi[s] = psi1, 0.0
        phase[s] = FOOT_FLAT if p.stance_roll == 0.0 else STANCE_ROLL
        rel, _, _ = _offset(np.array(-p.stance_roll), np.array(psi1), -p.roll_pivot, 0.0)
        heel_end, theta_end = pivot + rel, -p.stance_roll
        # standing until the next step (if any) overwrites
        s = slice(i4, n)
        pH[s], vH[s], theta[s], dtheta[s], psi[s], dpsi[s] = heel_end, 0.0, theta_end, 0.0, \
            psi1, 0.0
        phase[s] = STAND
    off, d_th, d_psi = _offset(theta, psi, ys, zs)
    return pH + off, vH + d_th * dtheta[:, None] + d_psi * dpsi[:, None], theta, psi, phase


def simulate_walk(
    segments: Sequence[dict],
    *,
    rate: float = 200.0,
    lat: float = np.radians(45.0),
    lon: float = 0.0,
    height: float = 0.0,
    heading: float = 0.0,
    params: GaitParams | None = None,
    oversample: int = 16,
    sensor: tuple[float, float] | None = None,
    accel_range: float | None = None,
    gyro_range: float | None = None,
    output: str = "increments",
    gravity_model: str = "somigliana",
) -> GaitWalk:
    """Simulate a foot-mounted IMU on a walk of ``stand`` and ``walk`` segments.

    Parameters
    ----------
    segments : list of dict
        ``{"type": "stand", "duration": s}`` or ``{"type": "walk", "steps": n, **gait}``
        with any :class:`GaitParams` field overriding ``params`` for that segment.
    rate : float
        IMU output rate [Hz].
    lat, lon, height, heading : float
        Start position [rad, rad, m] and heading [rad].
    params : GaitParams, optional
        Default gait.
    oversample : int
        Fine-grid samples per output interval (the motion inside an interval).
    sensor : (float, float), optional
        Sensor position (forward, up) from the heel [m], overriding the gait's.
    accel_range, gyro_range : float, optional
        Measurement ranges [m/s^2], [rad/s]: fine-grid samples beyond them are clipped.
    output : {"increments", "rates"}
        Increments summed over each interval, or the rate samples at the output times
        (fine-grid values nearest each output time).

    Returns
    -------
    GaitWalk
    """
    if output not in ("increments", "rates"):
        raise ConfigError("output must be 'increments' or 'rates'", column="output",
                          found=output)
    if isinstance(oversample, bool) or not isinstance(oversample, int) or oversample < 1:
        raise ConfigError("oversample must be a positive integer", column="oversample",
                          found=oversample)
    base = params or GaitParams()
    steps, plan, total = _plan(segments, base, heading)
    n_out = int(np.floor(total * rate + 1e-9)) + 1
    t_out = np.arange(n_out) / rate
    t_fine = np.arange((n_out - 1) * oversample + 1) / (rate * oversample)
    pos_rel, vel, theta, psi, phase = _kinematics(t_fine, steps, heading, sensor)
    pos = integrate_position(t_fine, vel, lat, lon, height + pos_rel[0, 2])
    C = euler_to_dcm(np.zeros_like(theta), theta, psi)
    dth, dv = inverse_increments(t_fine, pos[:, 0], pos[:, 2], vel, C, gravity_model)
    dtf = 1.0 / (rate * oversample)
    if accel_range is not None:
        dv = np.clip(dv, -accel_range * dtf, accel_range * dtf)
    if gyro_range is not None:
        dth = np.clip(dth, -gyro_range * dtf, gyro_range * dtf)
    idx = np.arange(n_out) * oversample
    if output == "increments":
        c_th = np.vstack([np.zeros((1, 3)), np.cumsum(dth[1:], axis=0)])
        c_dv = np.vstack([np.zeros((1, 3)), np.cumsum(dv[1:], axis=0)])
        sth, sdv = np.diff(c_th[idx], axis=0), np.diff(c_dv[idx], axis=0)
        imu = increments_table(t_out, np.vstack([np.zeros((1, 3)), sth]),
                               np.vstack([np.zeros((1, 3)), sdv]))
    else:
        # rate of the fine interval ending at each output time (the first: the one after it)
        j = np.maximum(idx, 1)
        imu = rates_table(t_out, dth[j] / dtf, dv[j] / dtf)
    data = np.empty((n_out, 9))
    data[:, 0:3] = pos[idx]
    data[:, 3:6] = vel[idx]
    data[:, 6] = 0.0
    data[:, 7] = theta[idx]
    data[:, 8] = np.mod(psi[idx], 2.0 * np.pi)
    truth = pd.DataFrame(data, index=pd.Index(t_out, name="time"), columns=NAV_COLS)
    ph = phase[idx]
    truth["stationary"] = np.isin(ph, (STAND, FOOT_FLAT)).astype(float)
    truth["phase"] = ph
    ideal = inverse_mechanize(truth[NAV_COLS], gravity_model=gravity_model)
    still = np.isin(phase, (STAND, FOOT_FLAT)).astype(np.int8)
    d = np.diff(np.concatenate([[0], still, [0]]))
    a, b = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    rest = pos_rel[a] - pos_rel[0]  # the sensor point at rest, from the start
    stances = pd.DataFrame({"start": t_fine[a], "stop": t_fine[b - 1], "east": rest[:, 0],
                            "north": rest[:, 1], "up": rest[:, 2]})
    seg_params = [s[1] for s in steps]
    return GaitWalk(truth, imu, ideal, stances, list(dict.fromkeys(seg_params)))


__all__ = ["GaitParams", "GaitWalk", "PHASES", "quintic", "simulate_walk"]
