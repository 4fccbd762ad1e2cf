"""Continuous-time aircraft flight with exact IMU increments: a reference for integration accuracy.

The flight is defined by closed-form channels (no discrete integration anywhere in the truth):

- horizontal speed ``v_h(t) = v0 + dv sin(2 pi t / P_v)``, vertical speed
  ``v_u(t) = a_u sin(2 pi t / P_u)`` (so ``h(t)`` is closed form);
- heading rate ``dpsi/dt = sum_i W_i sin^2(pi (t - t_i) / T_i)`` on ``[t_i, t_i + T_i]`` (turns with
  peak coordinated bank ``phi_i``: ``W_i = g0 tan(phi_i) / v_h(t_i + T_i / 2)``), heading in
  closed form;
- attitude: roll ``atan(v_h dpsi/dt / g0)`` (coordinated turn), pitch ``atan2(v_u, v_h)``
  (flight-path angle), heading ``psi``; ENU velocity ``(v_h sin psi, v_h cos psi, v_u)``.

Latitude and longitude come from the exact kinematic ODE ``dlat/dt = v_n / (M + h)``,
``dlon/dt = v_e / ((N + h) cos lat)`` solved by scipy's DOP853 at ``rtol = 1e-13`` (dense output,
well below a micrometre). The sensors are the exact continuous-time quantities

    w_ib^b = w_lb^b + C_l^b (w_ie^l + w_el^l),
    f^b    = C_l^b (dv^l/dt + (2 w_ie^l + w_el^l) x v^l + (0, 0, g)),

with ``w_lb^b`` from the Euler-angle rates of ``C_b^l = Rz(-A) Rx(p) Ry(r)``, integrated over each
IMU interval by 3-point Gauss-Legendre quadrature on sub-intervals of at most ``max_sub`` seconds
(error of order ``max_sub^6``: rounding level). Nothing here shares code with the discrete
strapdown step, so the end-position difference of a mechanization run is its integration error.

Used by ``bench/bench_integration_order.py`` and the tests of the strapdown step's order.

References: Savage, *Strapdown Analytics*, 2000, ch. 7 and 19 (accuracy assessment of strapdown
algorithms with analytic trajectories); Groves 2013, eqs. 5.44 and 5.54 (kinematic equations).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

from ..earth import OMEGA_E, gravity_somigliana, radii
from ..imu import increments_table

G0 = 9.80665  #: gravity used to define the coordinated bank [m/s^2]
_GL_NODES = np.array([-np.sqrt(0.6), 0.0, np.sqrt(0.6)])
_GL_WEIGHTS = np.array([5.0, 8.0, 5.0]) / 9.0


def _default_turns() -> list[tuple[float, float, float]]:
    """(start [s], duration [s], peak bank [deg], sign) of the default 20-minute flight."""
    banks = [15, 25, 35, 20, 30, 35, 15, 25, 30, 20]
    out = []
    t = 40.0
    for i, b in enumerate(banks):
        dur = 50.0 + 5.0 * (i % 4)
        out.append((t, dur, float(b) * (1 if i % 2 == 0 else -1)))
        t += dur + 65.0
    return out


@dataclass
class CoordinatedFlight:
    """A closed-form coordinated flight (see the module docstring).

    Parameters
    ----------
    lat0, lon0 : float
        Start position [rad].
    h0 : float
        Start height [m].
    duration : float
        [s].
    speed, speed_swing, speed_period : float
        ``v_h = speed + speed_swing sin(2 pi t / speed_period)`` [m/s, m/s, s].
    climb_rate, climb_period : float
        ``v_u = climb_rate sin(2 pi t / climb_period)`` [m/s, s].
    heading0 : float
        Initial heading [rad].
    turns : list of (start, duration, signed peak bank [deg])
        Turns; positive bank turns right.
    """

    lat0: float = np.radians(45.0)
    lon0: float = np.radians(7.0)
    h0: float = 1000.0
    duration: float = 1200.0
    speed: float = 220.0
    speed_swing: float = 20.0
    speed_period: float = 400.0
    climb_rate: float = 4.0
    climb_period: float = 300.0
    heading0: float = np.radians(30.0)
    turns: list = field(default_factory=_default_turns)

    def __post_init__(self):
        tr = np.array(self.turns, float).reshape(-1, 3)
        self._t0, self._T = tr[:, 0], tr[:, 1]
        # peak rate for the peak bank at the speed of the turn's middle
        self._W = G0 * np.tan(np.radians(tr[:, 2])) / self._speed(self._t0 + 0.5 * self._T)[0]
        sol = solve_ivp(self._latlon_rate, (0.0, self.duration), [self.lat0, self.lon0],
                        method="DOP853", rtol=1e-13, atol=1e-16, dense_output=True,
                        max_step=2.0)
        self._latlon = sol.sol

    # --- closed-form channels ---
    def _speed(self, t):
        w = 2 * np.pi / self.speed_period
        return self.speed + self.speed_swing * np.sin(w * t), self.speed_swing * w * np.cos(w * t)

    def _vertical(self, t):
        w = 2 * np.pi / self.climb_period
        vu = self.climb_rate * np.sin(w * t)
        h = self.h0 + self.climb_rate / w * (1.0 - np.cos(w * t))
        return h, vu, self.climb_rate * w * np.cos(w * t)

    def _heading(self, t):
        """psi, dpsi/dt, d2psi/dt2."""
        t = np.asarray(t, float)[..., None]
        u = np.clip((t - self._t0) / self._T, 0.0, 1.0)
        inside = (t > self._t0) & (t < self._t0 + self._T)
        psi = self.heading0 + np.sum(self._W * self._T * (u / 2 - np.sin(2 * np.pi * u) / (4 * np.pi)),
                                     axis=-1)
        rate = np.sum(np.where(inside, self._W * np.sin(np.pi * u) ** 2, 0.0), axis=-1)
        acc = np.sum(np.where(inside, self._W * np.pi / self._T * np.sin(2 * np.pi * u), 0.0), axis=-1)
        return psi, rate, acc

    def _velocity(self, t):
        vh, dvh = self._speed(t)
        _, vu, dvu = self._vertical(t)
        psi, dpsi, _ = self._heading(t)
        s, c = np.sin(psi), np.cos(psi)
        v = np.stack([vh * s, vh * c, vu], -1)
        a = np.stack([dvh * s + vh * c * dpsi, dvh * c - vh * s * dpsi, dvu], -1)
        return v, a

    def _latlon_rate(self, t, y):
        lat = y[0]
        h, _, _ = self._vertical(t)
        v, _ = self._velocity(t)
        M, N = radii(lat)
        return [v[1] / (M + h), v[0] / ((N + h) * np.cos(lat))]

    # --- truth ---
    def state(self, t):
        """Truth at times ``t``: dict of lat, lon, h, vel (N,3), roll, pitch, heading, their
        rates and the ENU acceleration."""
        t = np.atleast_1d(np.asarray(t, float))
        latlon = self._latlon(t)
        h, vu, dvu = self._vertical(t)
        vh, dvh = self._speed(t)
        psi, dpsi, ddpsi = self._heading(t)
        v, a = self._velocity(t)
        x = vh * dpsi / G0
        roll = np.arctan(x)
        droll = (dvh * dpsi + vh * ddpsi) / G0 / (1.0 + x * x)
        pitch = np.arctan2(vu, vh)
        dpitch = (vh * dvu - vu * dvh) / (vh * vh + vu * vu)
        return {"lat": latlon[0], "lon": latlon[1], "h": h, "vel": v, "acc": a, "roll": roll,
                "pitch": pitch, "heading": psi, "droll": droll, "dpitch": dpitch,
                "dheading": dpsi}

    def truth(self, rate: float) -> pd.DataFrame:
        """Truth table (NAV_COLS) sampled at ``rate`` [Hz]."""
        t = self.times(rate)
        s = self.state(t)
        return pd.DataFrame({"lat": s["lat"], "lon": s["lon"], "height": s["h"],
                             "vel_e": s["vel"][:, 0], "vel_n": s["vel"][:, 1],
                             "vel_u": s["vel"][:, 2], "roll": s["roll"], "pitch": s["pitch"],
                             "heading": np.mod(s["heading"], 2 * np.pi)},
                            index=pd.Index(t, name="time"))

    def times(self, rate: float) -> np.ndarray:
        n = int(round(self.duration * rate))
        return np.arange(n + 1) / rate

    def sensors(self, t):
        """Exact angular rate ``w_ib^b`` and specific force ``f^b`` (N, 3) at times ``t``."""
        s = self.state(t)
        lat, h, v = s["lat"], s["h"], s["vel"]
        r, p, A = s["roll"], s["pitch"], s["heading"]
        sr, cr, sp, cp, sA, cA = np.sin(r), np.cos(r), np.sin(p), np.cos(p), np.sin(A), np.cos(A)
        # C_b^l = Rz(-A) Rx(p) Ry(r), built explicitly (independent of insgnss.attitude)
        Rz = np.zeros(r.shape + (3, 3))
        Rz[..., 0, 0], Rz[..., 0, 1], Rz[..., 1, 0], Rz[..., 1, 1], Rz[..., 2, 2] = cA, sA, -sA, cA, 1
        Rx = np.zeros_like(Rz)
        Rx[..., 0, 0], Rx[..., 1, 1], Rx[..., 1, 2], Rx[..., 2, 1], Rx[..., 2, 2] = 1, cp, -sp, sp, cp
        Ry = np.zeros_like(Rz)
        Ry[..., 0, 0], Ry[..., 0, 2], Ry[..., 1, 1], Ry[..., 2, 0], Ry[..., 2, 2] = cr, sr, 1, -sr, cr
        RxRy = Rx @ Ry
        C = Rz @ RxRy
        ez = np.array([0.0, 0.0, 1.0])
        ex = np.array([1.0, 0.0, 0.0])
        # w_lb^b = Ry^T Rx^T (-dA e_z) + Ry^T (dp e_x) + dr e_y
        w_lb = (np.einsum("kji,j->ki", RxRy, ez) * -s["dheading"][:, None]
                + np.einsum("kji,j->ki", Ry, ex) * s["dpitch"][:, None])
        w_lb[:, 1] += s["droll"]
        M, N = radii(lat)
        sl, cl = np.sin(lat), np.cos(lat)
        wie = np.stack([0 * lat, OMEGA_E * cl, OMEGA_E * sl], -1)
        wel = np.stack([-v[:, 1] / (M + h), v[:, 0] / (N + h), v[:, 0] * sl / cl / (N + h)], -1)
        w_ib = w_lb + np.einsum("kji,kj->ki", C, wie + wel)
        f_l = s["acc"] + np.cross(2 * wie + wel, v)
        f_l[:, 2] += gravity_somigliana(lat, h)
        f_b = np.einsum("kji,kj->ki", C, f_l)
        return w_ib, f_b

    def increments(self, rate: float, max_sub: float = 1.0 / 800.0, chunk: int = 200_000
                   ) -> pd.DataFrame:
        """Exact IMU increments (``dtheta``, ``dv``) at ``rate`` [Hz] (row 0 zero)."""
        t = self.times(rate)
        dt = 1.0 / rate
        m = max(1, int(np.ceil(dt / max_sub - 1e-9)))
        h = dt / m
        sub = h * np.arange(m)
        nodes = 0.5 * h * (1.0 + _GL_NODES)
        wq = (0.5 * h * _GL_WEIGHTS)[None, None, :, None]
        dth = np.zeros((t.size, 3))
        dv = np.zeros((t.size, 3))
        step = max(1, chunk // (3 * m))
        for i0 in range(0, t.size - 1, step):
            i1 = min(i0 + step, t.size - 1)
            tq = (t[i0:i1, None, None] + sub[None, :, None] + nodes).ravel()
            w, f = self.sensors(tq)
            dth[i0 + 1:i1 + 1] = np.sum(w.reshape(i1 - i0, m, 3, 3) * wq, axis=(1, 2))
            dv[i0 + 1:i1 + 1] = np.sum(f.reshape(i1 - i0, m, 3, 3) * wq, axis=(1, 2))
        return increments_table(t, dth, dv)
