"""Wander-azimuth strapdown INS as a process model of the filter engine: the filter over the
poles.

Nominal state: the wander-azimuth mechanization (:mod:`insgnss.mechanization.wander`) -
position as ``C_w^e`` and height, velocity ``v^w``, attitude ``C_b^w`` - of the IMU increments
compensated with the nominal parameter estimates, exactly as the LLF model
(:class:`.strapdown_model.StrapdownModel`) does with its ENU nominal.

Error state: position, velocity and misalignment errors resolved in ECEF, then the LLF model's
parameter states (:mod:`.ecef_dynamics`: continuous F without ``tan(lat)``, ``1/cos(lat)`` or
the wander angle). The layout, labels and noise model are those of :mod:`.models`; only the
three navigation blocks mean ECEF instead of ENU metres, m/s and radians.

Measurements: the measurement models are written for the LLF error state at the nominal point
(:class:`.measurements.NominalState`: ENU position, velocity and ``C_b^l``). :meth:`observe`
maps their ``H`` onto the ECEF errors, ``dx_l = T dx_e`` with ``T = diag(C_e^l, C_e^l, C_e^l,
I)``, and the nominal hands them an :meth:`~WanderNominalState.enu_offset` computed from the
ECEF difference (exact at any latitude and across the antimeridian). The ENU frame of the
nominal point and the one of the true point differ by the rotation ``|dr| / R`` about the
horizontal and ``|dr_e| tan(lat) / R`` about the vertical; ``T`` neglects it, which is a
second-order term for position measurements and for lever-arm attitude terms, but not for ENU
*velocity* measurements close to a pole: there ``tan(lat)`` is unbounded (a receiver's ENU
velocity is ill-defined near the pole). Within ~100 km of a pole aid the wander filter with
positions (or give ECEF-consistent velocities at the nominal point).

Feedback: ``r^e <- r^e - dr``, the frame carried to the new point by the smallest rotation of
its vertical (``C_w^e <- R(u -> u') C_w^e``: the wander angle moves by the frame's own change, no
singular step), ``v^e <- v^e - dv``, ``C_b^e <- exp(-[phi x]) C_b^e``, ``p <- p - dp``.

Output: the same columns as the LLF model (NAV_COLS, STD_COLS, parameters and their stds); the
position, velocity and attitude stds are those of the ECEF covariance rotated into the ENU axes
of each row (east, north, up; roll, pitch, heading), the smoothed rows are corrected in ECEF.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .. import earth
from ..attitude import dcm_to_euler_nb, euler_to_dcm_nb, rotvec_to_dcm_nb
from ..earth import E2, A, ecef_to_geodetic, geodetic_to_ecef_nb
from ..errors import ConfigError
from ..jit import njit
from ..mechanization.wander import nav_state, wander_state
from . import kernels
from .measurements import NominalState
from .strapdown_model import StrapdownModel, levelling_covariance, output_columns

__all__ = ["WanderModel", "WanderNominalState", "run_wander_filter"]


class WanderNominalState(NominalState):
    """:class:`.measurements.NominalState` of the wander model: ENU quantities at the nominal
    point plus its ECEF position ``r_e`` and ``C_e^l`` (``Cel``), so that offsets from measured
    coordinates are exact ECEF differences."""

    __slots__ = ("r_e", "Cel")

    def enu_offset(self, lat, lon, h) -> np.ndarray:
        """ENU metres at the nominal point from ``(lat, lon, h)`` to the nominal position:
        ``C_e^l (r_nom - r(lat, lon, h))`` (any latitude, no longitude wrap)."""
        return self.Cel @ (self.r_e - np.array(earth.geodetic_to_ecef(lat, lon, h)))


@njit(cache=True)
def _ecef_position_nb(Cne, h, r):
    u0, u1, u2 = Cne[0, 2], Cne[1, 2], Cne[2, 2]
    s2 = u2 * u2 / (u0 * u0 + u1 * u1 + u2 * u2)
    N = A / np.sqrt(1.0 - E2 * s2)
    r[0], r[1], r[2] = (N + h) * u0, (N + h) * u1, (N * (1.0 - E2) + h) * u2


def ecef_position(Cne, h: float) -> np.ndarray:
    """ECEF position of a wander nominal from the normal ``u = C_w^e[:, 2]`` and the height
    (``r = ((N + h) u_x, (N + h) u_y, (N (1 - e^2) + h) u_z)``; no longitude needed)."""
    r = np.empty(3)
    _ecef_position_nb(np.ascontiguousarray(Cne, dtype=float), float(h), r)
    return r


@njit(cache=True)
def wander_feedback(Cne, hv, vel, C, pnom, x):
    """Closed-loop correction of a wander nominal (``C_w^e``, height ``hv[0]``, ``v^w``,
    ``C_b^w``, parameters) by the ECEF error estimate ``x``, in place: ``r^e -= dr``,
    ``v^e -= dv``, ``C_b^e <- exp(-[phi x]) C_b^e``, ``p -= dp``; the frame is carried to the new
    point by the smallest rotation of its vertical ``u`` (``C_w^e <- R(u -> u') C_w^e``)."""
    r = np.empty(3)
    _ecef_position_nb(Cne, hv[0], r)
    lat, lon, h = ecef_to_geodetic(r[0] - x[0], r[1] - x[1], r[2] - x[2])
    cl = np.cos(lat)
    un = np.array([cl * np.cos(lon), cl * np.sin(lon), np.sin(lat)])
    u = Cne[:, 2].copy()
    ve = Cne @ vel.copy()
    R = np.empty((3, 3))
    phi = np.array([-x[6], -x[7], -x[8]])
    rotvec_to_dcm_nb(phi, R)
    Cbe = R @ (Cne @ C)
    k = np.array([u[1] * un[2] - u[2] * un[1], u[2] * un[0] - u[0] * un[2], u[0] * un[1] - u[1] * un[0]])
    s = np.sqrt(k[0] ** 2 + k[1] ** 2 + k[2] ** 2)
    if s > 0.0:
        k *= np.arctan2(s, u[0] * un[0] + u[1] * un[1] + u[2] * un[2]) / s
        rotvec_to_dcm_nb(k, R)
        Cn = R @ Cne
        Cne[:, :] = Cn
    hv[0] = h
    for i in range(3):
        vel[i] = Cne[0, i] * (ve[0] - x[3]) + Cne[1, i] * (ve[1] - x[4]) + Cne[2, i] * (ve[2] - x[5])
    C[:, :] = Cne.T @ Cbe
    for i in range(pnom.shape[0]):
        pnom[i] -= x[9 + i]


class WanderModel(StrapdownModel):
    """Wander-azimuth strapdown process model (module docstring). Parameters as
    :class:`.strapdown_model.StrapdownModel`; ``initial.wander_angle`` is the initial wander
    angle (any value; the results do not depend on it)."""

    high_rate = False
    heading_reset = False  # its attitude error is in the ECEF frame (.heading_reinit: LLF)

    def _setup(self, t, dth, dv, initial, extras, config):
        if config.error_dynamics != "full":
            raise ConfigError(
                "the wander-azimuth process model has the full error dynamics only",
                column="error_dynamics",
                expected=["full"],
                found=config.error_dynamics,
            )
        super()._setup(t, dth, dv, initial, extras, config)
        Cne, h, vel, C = wander_state(initial)
        self.Cne = np.ascontiguousarray(Cne)
        self.hv = np.array([h])
        self.vel = np.ascontiguousarray(vel)
        self.C = np.ascontiguousarray(C)
        self._buf = np.empty(10)  # the nominal's ENU row plus the wander angle
        self._row = np.empty((1, 9))
        self._nav = WanderNominalState()
        self._nav.layout = self.layout
        self._nav.gyro_psd = self.noise.gyro_psd
        self._update_pos()

    def _update_pos(self):
        """The nominal's ENU row and wander angle into ``self._buf``, its lat, lon, h into
        ``self.pos``."""
        kernels.store_nav_wander(self._row, 0, self.Cne, self.hv[0], self.vel, self.C, self._buf)
        self.pos[:] = self._buf[0:3]

    def _store(self, j):
        kernels.store_nav_wander(self.table, j, self.Cne, self.hv[0], self.vel, self.C, self._buf)

    def _enu_transform(self, lat, lon):
        """``C_e^l`` at (lat, lon)."""
        return earth.ecef_to_enu_matrix(lat, lon)

    # --- engine calls -------------------------------------------------------------------------
    def prepare(self, epochs: np.ndarray, dense=None) -> None:
        super().prepare(epochs, dense)
        self._store(0)

    def initial_covariance(self) -> np.ndarray:
        """``P0`` of the ENU initial stds (and levelling correlation) rotated into ECEF."""
        P = np.diag(self.noise.p0**2)
        Cbl = self._nav_enu_C()
        if self.levelling:
            g = earth.normal_gravity(self.pos[0], self.pos[2], self.gravity_model)
            P = levelling_covariance(P, Cbl, self.layout["att"], self.layout["accel_bias"], g)
        T = self._T()
        return T.T @ P @ T

    def _nav_enu_C(self):
        alpha = self._buf[9]
        ca, sa = np.cos(alpha), np.sin(alpha)
        return np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]]) @ self.C

    def _T(self):
        """``T`` with ``dx_l = T dx_e`` at the nominal."""
        n = self.layout.n
        T = np.eye(n)
        Cel = self._enu_transform(self.pos[0], self.pos[1])
        for k in range(3):
            T[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] = Cel
        return T

    def _propagate_nominal(self, t_end: float, node: int):
        pm = self.noise
        out = kernels.propagate_nominal(
            self.t,
            self.dth,
            self.dv,
            self.j,
            self.frac,
            t_end,
            self.pos,
            self.vel,
            self.C,
            self.pnom,
            self.i_sg,
            self.i_sa,
            self.gmodel,
            self.aupd,
            self.sub_T,
            self.Fint,
            self.Qint,
            self.sub_dt,
            pm.gyro_psd,
            pm.accel_psd,
            self.table,
            self.seg,
            node,
            self.rates,
            pm.dyn_noise,
            0,
            self.Cne,
            self.hv,
        )
        self._update_pos()
        return out

    def nominal_finite(self) -> bool:
        return bool(np.isfinite(self.Cne.sum() + self.hv[0] + self.vel.sum() + self.C.sum()))

    def _nominal_velocity_attitude(self) -> tuple[np.ndarray, np.ndarray]:
        return self._buf[3:6].copy(), self._nav_enu_C()

    def _complete_nominal(self, nav: WanderNominalState) -> None:
        pos = self.pos
        nav.r_e = ecef_position(self.Cne, self.hv[0])
        nav.Cel = self._enu_transform(pos[0], pos[1])

    def observe(self, m, z, H, R):
        """``H`` of the LLF error state mapped onto the ECEF errors (``H T``)."""
        Cel = self._enu_transform(self.pos[0], self.pos[1])
        H = H.copy()
        for k in range(3):
            s = slice(3 * k, 3 * k + 3)
            H[:, s] = H[:, s] @ Cel
        return z, H, R

    def feedback(self, x: np.ndarray) -> None:
        wander_feedback(self.Cne, self.hv, self.vel, self.C, self.pnom, np.ascontiguousarray(x))
        self._update_pos()
        self._nav_time = None

    def close_epoch(self, node: int, time: float) -> None:
        j = self.j
        if self.frac == 0.0 and self.t[j - 1] == time:
            self._store(j - 1)
            self.seg[j - 1], self.post[j - 1] = node, True
        self._nav_time = None

    def output(self, store, n_nodes: int, n_rows: int, smoothed=None) -> pd.DataFrame:
        """IMU-rate forward table (``smoothed=None``) or smoothed table (``(xs_plus, xs_minus,
        Ps or None, xs_hr)``): rows interpolated between the nodes as in the LLF model
        (:func:`.kernels.assemble_output`), errors and covariances rotated from ECEF into the
        row's ENU axes."""
        cols = output_columns(self.layout)
        t = self.t[:n_rows]
        out = np.full((n_rows, len(cols)), np.nan)
        if n_rows:
            if smoothed is None:  # forward: P(e|e) at the start, P(e|e-1) at the end
                P0, P1 = store.Pf[:n_nodes], store.Pp[:n_nodes]
                X0 = X1 = np.zeros((1, self.layout.n))  # unused
            else:
                X0, X1, Ps, _ = smoothed
                P0 = P1 = store.Pf[:n_nodes] if Ps is None else Ps
            _wander_output(
                t,
                self.table,
                self.seg,
                self.post,
                store.t[:n_nodes],
                np.ascontiguousarray(P0),
                np.ascontiguousarray(P1),
                np.ascontiguousarray(X0),
                np.ascontiguousarray(X1),
                store.par[:n_nodes],
                smoothed is not None,
                out,
            )
            if smoothed is not None and smoothed[2] is None:
                out[:, 9:18] = np.nan
                out[:, 18 + self.n_par :] = np.nan
        return pd.DataFrame(out, index=pd.Index(t, name="time"), columns=cols, copy=False)

    def final_state(self, time: float):
        return nav_state(self.Cne, self.hv[0], self.vel, self.C, float(time))

    def f_pattern(self):
        raise ConfigError("the wander-azimuth process model has no compiled high-rate path")

    def high_rate_args(self):
        raise ConfigError("the wander-azimuth process model has no compiled high-rate path")


@njit(cache=True)
def _enu_rows(lat, lon, out):
    """``C_e^l`` (rows east, north, up in ECEF) at (lat, lon) into ``out``."""
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    out[0, 0], out[0, 1], out[0, 2] = -so, co, 0.0
    out[1, 0], out[1, 1], out[1, 2] = -sl * co, -sl * so, cl
    out[2, 0], out[2, 1], out[2, 2] = cl * co, cl * so, sl


@njit(cache=True)
def _wander_output(t, nav, seg, post, ep_t, P0, P1, X0, X1, par, correct, out):
    """Row assembly of :meth:`WanderModel.output` (compiled): row ``j`` in segment
    ``e = seg[j]`` takes node ``e`` if ``post[j]``, else the linear interpolation between node
    ``e-1`` (``X0, P0``) and node ``e`` (``X1, P1``); ``correct``: subtract the (ECEF) error
    from the nominal (smoothed rows). The stds are those of the covariance rotated into the
    row's ENU axes."""
    n = P0.shape[1]
    npar = n - 9
    x = np.zeros(n)
    Cel = np.empty((3, 3))
    Cbl = np.empty((3, 3))
    Cbe = np.empty((3, 3))
    R = np.empty((3, 3))
    Pb = np.empty((3, 3))
    Pa = np.empty((3, 3))
    es = np.empty(3)
    phi = np.empty(3)
    ve = np.empty(3)
    for j in range(t.shape[0]):
        e = seg[j]
        if post[j]:
            a, w = e, 0.0
        else:
            a = e - 1
            w = (t[j] - ep_t[a]) / (ep_t[e] - ep_t[a])
        if correct:
            for i in range(n):
                x[i] = (1.0 - w) * X0[a, i] + w * X1[e, i]
        lat, lon, h = nav[j, 0], nav[j, 1], nav[j, 2]
        _enu_rows(lat, lon, Cel)
        euler_to_dcm_nb(nav[j, 6], nav[j, 7], nav[j, 8], Cbl)
        if correct:
            r0, r1, r2 = geodetic_to_ecef_nb(lat, lon, h)
            for i in range(3):  # v^e = C_l^e v^l - dv
                ve[i] = Cel[0, i] * nav[j, 3] + Cel[1, i] * nav[j, 4] + Cel[2, i] * nav[j, 5] - x[3 + i]
            for r in range(3):  # C_b^e = C_l^e C_b^l
                for c in range(3):
                    Cbe[r, c] = Cel[0, r] * Cbl[0, c] + Cel[1, r] * Cbl[1, c] + Cel[2, r] * Cbl[2, c]
            phi[0], phi[1], phi[2] = -x[6], -x[7], -x[8]
            rotvec_to_dcm_nb(phi, R)
            lat, lon, h = ecef_to_geodetic(r0 - x[0], r1 - x[1], r2 - x[2])
            _enu_rows(lat, lon, Cel)
            for r in range(3):  # C_b^l = C_e^l exp(-[phi x]) C_b^e
                for c in range(3):
                    Pb[r, c] = R[r, 0] * Cbe[0, c] + R[r, 1] * Cbe[1, c] + R[r, 2] * Cbe[2, c]
            for r in range(3):
                for c in range(3):
                    Cbl[r, c] = Cel[r, 0] * Pb[0, c] + Cel[r, 1] * Pb[1, c] + Cel[r, 2] * Pb[2, c]
            out[j, 0], out[j, 1], out[j, 2] = lat, lon, h
            for i in range(3):
                out[j, 3 + i] = Cel[i, 0] * ve[0] + Cel[i, 1] * ve[1] + Cel[i, 2] * ve[2]
            out[j, 6], out[j, 7], out[j, 8] = dcm_to_euler_nb(Cbl)
        else:
            for i in range(9):
                out[j, i] = nav[j, i]
        for blk in range(3):  # C_e^l P_blk C_l^e
            o = 3 * blk
            for r in range(3):
                for c in range(3):
                    Pb[r, c] = (1.0 - w) * P0[a, o + r, o + c] + w * P1[e, o + r, o + c]
            for r in range(3):
                for c in range(3):
                    v = 0.0
                    for k in range(3):
                        for m in range(3):
                            v += Cel[r, k] * Pb[k, m] * Cel[c, m]
                    Pa[r, c] = v
            if blk < 2:
                for r in range(3):
                    out[j, 9 + o + r] = np.sqrt(max(Pa[r, r], 0.0))
        kernels._euler_std(Cbl, Pa, 0, es)
        for i in range(3):
            out[j, 15 + i] = es[i]
        for i in range(npar):
            out[j, 18 + i] = par[a, i] - x[9 + i]
            v = (1.0 - w) * P0[a, 9 + i, 9 + i] + w * P1[e, 9 + i, 9 + i]
            out[j, 18 + npar + i] = np.sqrt(max(v, 0.0))


def run_wander_filter(imu: pd.DataFrame, initial, measurements, config=None):
    """:func:`insgnss.filter.engine.run_filter` with the wander-azimuth process model
    (:class:`WanderModel`): the same inputs, configuration and result, valid over the poles.

    Measurement models with ``high_rate=True`` are not supported (no compiled high-rate path),
    nor ``config.extra_noise`` with a vertical-only ``up_std`` (isotropic stds are).
    """
    from .engine import FilterConfig, run_engine

    config = FilterConfig() if config is None else config
    config.validate()
    xn = config.extra_noise
    if xn is not None and "up_std" in xn and np.any(np.asarray(xn["up_std"], float) != 0.0):
        # the engine adds it to the third position state: "up" in ENU, the polar axis here
        raise ConfigError(
            "extra_noise up_std (vertical-only position noise) is not supported "
            "by the wander-azimuth model (ECEF errors); use pos_std",
            column="extra_noise.up_std",
        )
    measurements = list(measurements)
    extras = []
    for m in measurements:
        extras.extend(m.extra_states())
    model = WanderModel(imu, initial, extras, config)
    return run_engine(model, measurements, config)
