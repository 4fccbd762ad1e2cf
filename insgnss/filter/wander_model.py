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
from numba import njit

from .. import earth
from ..attitude import dcm_to_euler, euler_to_dcm, rotvec_to_dcm
from ..errors import ConfigError
from ..mechanization.wander import nav_state, wander_state
from . import kernels
from .measurements import NominalState
from .strapdown_model import StrapdownModel, levelling_covariance, output_columns

__all__ = ["WanderModel", "WanderNominalState", "run_wander_filter"]

#: output rows assembled at once (their interpolated covariances are held in memory)
OUTPUT_CHUNK = 8192


class WanderNominalState(NominalState):
    """:class:`.measurements.NominalState` of the wander model: ENU quantities at the nominal
    point plus its ECEF position ``r_e`` and ``C_e^l`` (``Cel``), so that offsets from measured
    coordinates are exact ECEF differences."""

    __slots__ = ("r_e", "Cel")

    def enu_offset(self, lat, lon, h) -> np.ndarray:
        """ENU metres at the nominal point from ``(lat, lon, h)`` to the nominal position:
        ``C_e^l (r_nom - r(lat, lon, h))`` (any latitude, no longitude wrap)."""
        return self.Cel @ (self.r_e - np.array(earth.geodetic_to_ecef(lat, lon, h)))


def ecef_position(Cne, h: float) -> np.ndarray:
    """ECEF position of a wander nominal from the normal ``u = C_w^e[:, 2]`` and the height
    (``r = ((N + h) u_x, (N + h) u_y, (N (1 - e^2) + h) u_z)``; no longitude needed)."""
    u = Cne[:, 2]
    _, N = earth.radii(np.arctan2(u[2], np.hypot(u[0], u[1])))
    return np.array([(N + h) * u[0], (N + h) * u[1], (N * (1.0 - earth.E2) + h) * u[2]])


def _normal(lat, lon) -> np.ndarray:
    cl = np.cos(lat)
    return np.array([cl * np.cos(lon), cl * np.sin(lon), np.sin(lat)])


def carry_frame(Cne, u_new) -> np.ndarray:
    """``C_w^e`` moved to the point with normal ``u_new`` by the smallest rotation of its vertical
    (``R(u -> u_new) C_w^e``); its third column becomes ``u_new``."""
    u = Cne[:, 2]
    k = np.cross(u, u_new)
    s = np.linalg.norm(k)
    if s == 0.0:
        return Cne.copy()
    R = rotvec_to_dcm(k / s * np.arctan2(s, float(u @ u_new)))
    return R @ Cne


class WanderModel(StrapdownModel):
    """Wander-azimuth strapdown process model (module docstring). Parameters as
    :class:`.strapdown_model.StrapdownModel`; ``initial.wander_angle`` is the initial wander
    angle (any value; the results do not depend on it)."""

    high_rate = False

    def _setup(self, t, dth, dv, initial, extras, config):
        if config.error_dynamics != "full":
            raise ConfigError("the wander-azimuth process model has the full error dynamics "
                              "only", column="error_dynamics", expected=["full"],
                              found=config.error_dynamics)
        super()._setup(t, dth, dv, initial, extras, config)
        Cne, h, vel, C = wander_state(initial)
        self.Cne = np.ascontiguousarray(Cne)
        self.hv = np.array([h])
        self.vel = np.ascontiguousarray(vel)
        self.C = np.ascontiguousarray(C)
        self._buf = np.empty(10)
        self._nav = WanderNominalState()
        self._nav.layout = self.layout
        self._nav.gyro_psd = self.noise.gyro_psd
        self._update_pos()

    def _update_pos(self):
        """lat, lon, h of the nominal into ``self.pos`` (for output and the nominal)."""
        kernels.store_nav_wander(self._row, 0, self.Cne, self.hv[0], self.vel, self.C, self._buf)
        self.pos[:] = self._buf[0:3]

    @property
    def _row(self):
        if not hasattr(self, "_row_buf"):
            self._row_buf = np.empty((1, 9))
        return self._row_buf

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
            T[3 * k:3 * k + 3, 3 * k:3 * k + 3] = Cel
        return T

    def _propagate_nominal(self, t_end: float, node: int):
        pm = self.noise
        out = kernels.propagate_nominal(
            self.t, self.dth, self.dv, self.j, self.frac, t_end, self.pos, self.vel, self.C,
            self.pnom, self.i_sg, self.i_sa, self.gmodel, self.aupd, self.sub_T, self.Fint,
            self.Qint, self.sub_dt, pm.gyro_psd, pm.accel_psd, self.table, self.seg, node,
            self.rates, pm.dyn_noise, 0, self.Cne, self.hv)
        self._update_pos()
        return out

    def nominal_finite(self) -> bool:
        return bool(np.isfinite(self.Cne.sum() + self.hv[0] + self.vel.sum() + self.C.sum()))

    def nominal(self, time: float) -> WanderNominalState:
        nav = self._nav
        if self._nav_time == time:
            return nav
        pos, rates = self.pos, self.rates
        nav.time = time
        nav.lat, nav.lon, nav.height = pos[0], pos[1], pos[2]
        b = self._buf
        nav.vel = b[3:6].copy()
        nav.C = self._nav_enu_C()
        nav.omega_ib, nav.omega_ib_mean = rates[0], rates[1]
        nav.f_ib, nav.f_ib_mean = rates[2], rates[3]
        nav.segment_duration = self.seg_dur
        nav.params = self.pnom
        nav.M, nav.N = earth.radii(pos[0])
        nav.r_e = ecef_position(self.Cne, self.hv[0])
        nav.Cel = self._enu_transform(pos[0], pos[1])
        self._nav_time = time
        return nav

    def observe(self, m, z, H, R):
        """``H`` of the LLF error state mapped onto the ECEF errors (``H T``)."""
        Cel = self._enu_transform(self.pos[0], self.pos[1])
        H = H.copy()
        for k in range(3):
            s = slice(3 * k, 3 * k + 3)
            H[:, s] = H[:, s] @ Cel
        return z, H, R

    def feedback(self, x: np.ndarray) -> None:
        Cne = self.Cne
        r = ecef_position(Cne, self.hv[0]) - x[0:3]
        lat, lon, h = earth.ecef_to_geodetic(r[0], r[1], r[2])
        v_e = Cne @ self.vel - x[3:6]
        C_be = rotvec_to_dcm(-x[6:9]) @ (Cne @ self.C)
        Cn = carry_frame(Cne, _normal(lat, lon))
        self.Cne[:] = Cn
        self.hv[0] = h
        self.vel[:] = Cn.T @ v_e
        self.C[:] = Cn.T @ C_be
        self.pnom -= x[9:]
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
                P0, P1, X0, X1 = store.Pf[:n_nodes], store.Pp[:n_nodes], None, None
            else:
                X0, X1, Ps, _ = smoothed
                P0 = P1 = store.Pf[:n_nodes] if Ps is None else Ps
            for r0 in range(0, n_rows, OUTPUT_CHUNK):  # bounded memory: (rows, n, n) blocks
                r = slice(r0, min(r0 + OUTPUT_CHUNK, n_rows))
                _wander_output(t[r], self.table[r], self.seg[r], self.post[r], store.t[:n_nodes],
                               P0, P1, X0, X1, store.par[:n_nodes], out[r])
            if smoothed is not None and smoothed[2] is None:
                out[:, 9:18] = np.nan
                out[:, 18 + self.n_par:] = np.nan
        return pd.DataFrame(out, index=pd.Index(t, name="time"), columns=cols, copy=False)

    def final_state(self, time: float):
        return nav_state(self.Cne, self.hv[0], self.vel, self.C, float(time))

    def f_pattern(self):
        raise ConfigError("the wander-azimuth process model has no compiled high-rate path")

    def high_rate_args(self):
        raise ConfigError("the wander-azimuth process model has no compiled high-rate path")


@njit(cache=True)
def _euler_std_rows(C, Pa, out):
    J = np.empty((3, 3))
    for j in range(C.shape[0]):
        kernels._euler_std(C[j], Pa[j], J, out[j])


def _wander_output(t, nav, seg, post, ep_t, P0, P1, X0, X1, par, out):
    """Vectorised row assembly of :meth:`WanderModel.output` (``X0 = None``: forward, no
    correction): row ``j`` in segment ``e = seg[j]`` takes node ``e`` if ``post[j]``, else the
    linear interpolation between node ``e-1`` (``X0, P0``) and node ``e`` (``X1, P1``)."""
    n = P0.shape[1]
    npar = n - 9
    e = seg.astype(np.int64)
    a = np.where(post, e, e - 1)
    w = np.where(post, 0.0, (t - ep_t[a]) / np.where(post, 1.0, ep_t[e] - ep_t[a]))
    P = (1.0 - w)[:, None, None] * P0[a] + w[:, None, None] * P1[e]
    x = None
    if X0 is not None:
        x = (1.0 - w)[:, None] * X0[a] + w[:, None] * X1[e]
    lat, lon, h = nav[:, 0], nav[:, 1], nav[:, 2]
    Cle = earth.enu_to_ecef_dcm(lat, lon)
    Cbl = euler_to_dcm(nav[:, 6], nav[:, 7], nav[:, 8])
    if x is None:
        out[:, 0:9] = nav[:, 0:9]
    else:
        r = np.column_stack(earth.geodetic_to_ecef(lat, lon, h)) - x[:, 0:3]
        lat, lon, h = earth.ecef_to_geodetic(r[:, 0], r[:, 1], r[:, 2])
        v_e = np.einsum("kij,kj->ki", Cle, nav[:, 3:6]) - x[:, 3:6]
        C_be = rotvec_to_dcm(-x[:, 6:9]) @ Cle @ Cbl
        Cle = earth.enu_to_ecef_dcm(lat, lon)
        Cel = np.swapaxes(Cle, 1, 2)
        Cbl = Cel @ C_be
        out[:, 0], out[:, 1], out[:, 2] = lat, lon, h
        out[:, 3:6] = np.einsum("kij,kj->ki", Cel, v_e)
        r_, p_, a_ = dcm_to_euler(Cbl)
        out[:, 6], out[:, 7], out[:, 8] = r_, p_, a_
    Cel = np.swapaxes(Cle, 1, 2)
    for k in range(2):  # position, velocity
        s = slice(3 * k, 3 * k + 3)
        Pk = Cel @ P[:, s, s] @ Cle
        out[:, 9 + 3 * k:12 + 3 * k] = np.sqrt(np.maximum(np.diagonal(Pk, axis1=1, axis2=2), 0.0))
    Pa = np.ascontiguousarray(Cel @ P[:, 6:9, 6:9] @ Cle)
    es = np.empty((len(t), 3))
    _euler_std_rows(np.ascontiguousarray(Cbl), Pa, es)
    out[:, 15:18] = es
    pd_ = np.sqrt(np.maximum(np.diagonal(P[:, 9:, 9:], axis1=1, axis2=2), 0.0))
    pnom = par[a]
    out[:, 18:18 + npar] = pnom - (x[:, 9:] if x is not None else 0.0)
    out[:, 18 + npar:] = pd_


def run_wander_filter(imu: pd.DataFrame, initial, measurements, config=None):
    """:func:`insgnss.filter.engine.run_filter` with the wander-azimuth process model
    (:class:`WanderModel`): the same inputs, configuration and result, valid over the poles.

    Measurement models with ``high_rate=True`` are not supported (no compiled high-rate path).
    """
    from .engine import FilterConfig, run_engine

    config = FilterConfig() if config is None else config
    config.validate()
    measurements = list(measurements)
    extras = []
    for m in measurements:
        extras.extend(m.extra_states())
    model = WanderModel(imu, initial, extras, config)
    return run_engine(model, measurements, config)

