"""RISS error-state model: 3D reduced inertial sensor system (one vertical gyro, two horizontal
accelerometers, odometer) as the process model of the closed-loop error-state Kalman filter.

Why these states
----------------
The 3D RISS (:mod:`insgnss.mechanization.riss`) integrates only the heading; pitch and roll are
algebraic functions of the accelerometers and the odometer, and the velocity is the odometer
speed along the body forward axis. Its errors are therefore driven by a few sensor errors
(Iqbal, Okou & Noureldin, PLANS 2008; Noureldin, Karamat & Georgy 2013, ch. 14; Cossaboom et al.,
IJNO 2012), and the error state is (error = nominal minus true, as in :mod:`.models`)::

    x = [dr_e dr_n dr_u | dv_e dv_n dv_u | dA | dk | db_gz | db_ax db_ay | (ds_gz) | (b0_gz b0_ax b0_ay)]
         position [m]     velocity [m/s]  azim. odo.  gyro z   accel x, y    gyro z     turn-on parts
                          (algebraic)     [rad] scale bias     biases        scale      (random const.)

Noureldin et al. use ``[dlat, dlon, dh, dv_e, dv_n, dv_u, dA, da_od, dw_z]``; here the odometer
error is a scale factor (a wheel-radius error is multiplicative; Iqbal et al. 2008) and the two
horizontal accelerometer biases are states: through pitch and roll they produce the vertical
velocity and tilt errors (``dp = -db_y / (g cos p)``: 1 mg is 1 mrad of pitch, 2 cm/s of
vertical velocity at 20 m/s) and, through the roll, a heading-rate error in turns on slopes.
The biases follow the IMU error model: ``gauss_markov`` (first-order Gauss-Markov instability
with its correlation time; the turn-on bias, which does not decay, is a separate random-constant
state ``b0`` so that an unobservable bias - the transversal accelerometer on a level road - does
not "decay" to the instability level and make the filter overconfident), ``random_walk`` or
``random_constant``; the odometer scale is a random constant (or slow random walk).

Error dynamics
--------------
The dynamic part ``y`` (all states except the velocity) has the continuous model::

    d(dr)/dt = dv                    (ENU metres)
    d(dA)/dt = c_b (db_gz + w_z ds_gz) + c_p dp + c_r dr + we cos(lat) dr_n / (M + h) - c_b n_g
    d(b)/dt  = -b / tau + w_b        d(dk)/dt = w_k        d(b0)/dt = 0

with the pitch, roll and velocity errors (linearised RISS equations 1, 2 and 4)::

    dp = (a_od dk - db_y) / (g cos p) + n_y / (g cos p)
    dr = [(db_x + v w dk + v (db_gz + w_z ds_gz)) / (g cos p) + sin r tan p dp
          - (n_x + v n_g + w n_od) / (g cos p)] / cos r
    dv = u (-v dk + n_od) + v du/dA dA + v du/dp dp,        u = (sin A cos p, cos A cos p, sin p)

(``db`` stands for the sum of the Gauss-Markov and turn-on parts). For the ``"exact"`` azimuth
``dA/dt = (dp/dt sin r - w_z + (C^T w_il)_z) / (cos p cos r)`` gives ``c_b = 1 / (cos p cos r)``,
``c_p = dA/dt tan p - (C e_y . w_il) / cos p`` and ``c_r = dA/dt tan r + (dp/dt) / cos p +
(C e_x . w_il) / (cos p cos r)``; ``"level"``: ``c_b = 1``, ``c_p = c_r = 0``; ``"projected"``:
``cos p cos r``, ``w_z sin p cos r``, ``w_z cos p sin r``. ``n_g, n_x, n_y`` are the gyro and
accelerometer white noises (PSDs ARW^2, VRW^2), ``n_od`` the odometer speed noise.

The velocity error is *algebraic*: ``dv = J_v y`` plus the white part of the pitch and
odometer errors and of the vehicle's side slip (``slip_std``, lateral and vertical body
velocity, the tolerance of the non-holonomic assumption; without it the lateral velocity error
would equal ``v dA`` exactly and P would be singular). It is kept in the state vector so that
GNSS velocity updates, the smoother and the outputs treat it like the strapdown's velocity
error. Its discrete model is exact for an algebraic state: transition rows ``J_v(t_k+1)
Phi_y`` with zero velocity columns, process noise ``J_v Q_y J_v^T + Sigma_eps``. Pitch and roll
errors are algebraic too (not states): they are reported with their stds and used for the tilt
of lever-arm terms.

Discretisation: ``Phi_y`` and ``Q_y`` are accumulated per IMU interval in compiled code
(``A = I + F dt + (F dt)^2 / 2``, ``Q <- A Q A^T + G Qc G^T dt``); ``epoch_interval`` only sets
how often P is formed in Python.

Filter framework
----------------
:class:`RissModel` is a process model of the filter engine (:mod:`insgnss.filter.engine`):
the engine runs the event loop (epochs at the measurements and every ``epoch_interval``;
chi-square gating and gate recovery; health checks; compiled predict/update in Joseph form (kalman.py);
closed-loop feedback and reset; the smoother) and :func:`run_riss_filter` returns the same
:class:`~insgnss.filter.engine.FilterResult` as :func:`insgnss.filter.engine.run_filter`, with
the same table columns (``NAV_COLS``, ``STD_COLS``, then the parameter states and their
stds). The measurement models of :mod:`insgnss.filter.measurements` are used unchanged: they
see a 15-state strapdown-like :class:`~insgnss.filter.measurements.NominalState` and their
``H`` is mapped to the RISS state by ``H T`` with ``T`` the linear map from the RISS error to
``(dr, dv, phi, db_g, db_a)`` (``phi`` the l-frame misalignment implied by the heading, pitch
and roll errors). Measurements that need extra states (e.g. an odometer ``BodyVelocity`` - the
odometer is the RISS *input*) are refused. GNSS epochs between IMU samples are compared with
the nominal of the last sample extrapolated with its velocity.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from .. import earth
from ..aot import entry
from ..earth import OMEGA_E, radii
from ..errors import ConfigError
from ..imu import grade
from ..jit import njit
from ..mechanization.riss import (
    N_PAR,
    ST_A,
    ST_H,
    ST_LAT,
    ST_LON,
    ST_P,
    ST_R,
    ST_VE,
    ST_VN,
    ST_VU,
    RissInputs,
    azimuth_mode_id,
    initial_riss_state,
    riss_dcm_col,
    riss_inputs,
    riss_step,
    riss_velocity,
)
from ..mechanization.strapdown import NAV_COLS, NavState
from .engine import FilterConfig, FilterResult, run_engine
from .kernels import correct_position_velocity
from .measurements import NominalState, Zaru
from .models import NamedBlocks, StateLayout
from .process import ProcessModelBase
from .strapdown_model import STD_COLS

__all__ = ["RissConfig", "RissLayout", "RissModel", "run_riss_filter", "riss_process",
           "PROCESS_MODELS"]

#: process models a job can select (``process_model = "riss"``)
PROCESS_MODELS = ("strapdown", "riss")

# base columns of the linearised model (the layout's dynamic states map onto these)
B_E, B_N, B_U, B_HEAD, B_ODO, B_BGZ, B_BAX, B_BAY, B_SGZ = range(9)
NB = 9
# noise inputs: gyro z, accel x, accel y, odometer speed
W_G, W_X, W_Y, W_OD = range(4)


class RissLayout(NamedBlocks):
    """Named blocks of the RISS error state (same interface as :class:`.models.StateLayout`).

    Blocks: ``pos`` (3), ``vel`` (3), ``heading`` (1), ``odometer_scale`` (1), ``gyro_bias_z``
    (1), ``accel_bias_xy`` (2), optionally ``gyro_scale_z`` (1) and ``bias_turn_on`` (3: gyro z,
    accel x, accel y turn-on biases, random constants beside the Gauss-Markov parts).

    Attributes
    ----------
    y_index : array
        Index in x of every dynamic state (all but the velocity).
    y_base : array
        Column of the linearised model (``B_*``) each dynamic state enters with.
    y_twin : array of bool
        True for the turn-on states (same columns as their Gauss-Markov partner, no dynamics).
    param_labels : list
        Output parameter columns: ``odometer_scale gyro_bias_z accel_bias_x accel_bias_y``
        [``gyro_scale_z``] (biases are the totals, turn-on included).
    param_x : (n_out, 2) int array
        x indices whose sum is the error of each output parameter (-1: none).
    param_nominal : array
        Index of each output parameter in the nominal parameter vector.
    """

    def __init__(self, gyro_scale: bool = False, turn_on: bool = False):
        blocks = [("pos", 3), ("vel", 3), ("heading", 1), ("odometer_scale", 1),
                  ("gyro_bias_z", 1), ("accel_bias_xy", 2)]
        labels = ["east", "north", "up", "vel_e", "vel_n", "vel_u", "heading",
                  "odometer_scale", "gyro_bias_z", "accel_bias_x", "accel_bias_y"]
        y_index = [0, 1, 2, 6, 7, 8, 9, 10]
        y_base = [B_E, B_N, B_U, B_HEAD, B_ODO, B_BGZ, B_BAX, B_BAY]
        y_twin = [False] * 8
        if gyro_scale:
            blocks.append(("gyro_scale_z", 1))
            labels.append("gyro_scale_z")
            y_index.append(11)
            y_base.append(B_SGZ)
            y_twin.append(False)
        n = 11 + int(gyro_scale)
        if turn_on:
            blocks.append(("bias_turn_on", 3))
            labels += ["gyro_bias_z_turn_on", "accel_bias_x_turn_on", "accel_bias_y_turn_on"]
            y_index += [n, n + 1, n + 2]
            y_base += [B_BGZ, B_BAX, B_BAY]
            y_twin += [True] * 3
        self.gyro_scale = bool(gyro_scale)
        self.turn_on = bool(turn_on)
        self._slices: dict[str, slice] = {}
        i = 0
        for name, size in blocks:
            self._slices[name] = slice(i, i + size)
            i += size
        self.n = i
        self.labels = labels
        self.y_index = np.array(y_index, np.int64)
        self.y_base = np.array(y_base, np.int64)
        self.y_twin = np.array(y_twin, np.bool_)
        self.ny = self.y_index.size
        self.param_labels = ["odometer_scale", "gyro_bias_z", "accel_bias_x", "accel_bias_y"]
        px = [[7, -1], [8, -1], [9, -1], [10, -1]]
        self.param_nominal = [0, 1, 2, 3]
        if gyro_scale:
            self.param_labels.append("gyro_scale_z")
            px.append([11, -1])
            self.param_nominal.append(4)
        if turn_on:
            t0 = self._slices["bias_turn_on"].start
            px[1][1], px[2][1], px[3][1] = t0, t0 + 1, t0 + 2
        self.param_x = np.array(px, np.int64)
        self.param_nominal = np.array(self.param_nominal, np.int64)


# --- configuration ----------------------------------------------------------------------------------
@dataclass
class RissConfig:
    """RISS-specific settings (the common ones - IMU model, bias model, gating, epochs,
    initial position / heading / bias stds, smoother - come from
    :class:`~insgnss.filter.engine.FilterConfig`).

    Attributes
    ----------
    odometer_speed_std : float
        White noise of each odometer speed sample [m/s].
    odometer_rate : float, optional
        Rate of independent odometer samples [Hz]; sets the position random walk
        ``odometer_speed_std^2 / rate``. Default: the odometer table's rate (the IMU rate for
        speeds given per IMU sample).
    odometer_scale_std : float
        Initial std of the odometer scale factor (fraction).
    odometer_scale_psd : float
        Random-walk PSD of the odometer scale factor [1/s] (0: random constant).
    slip_std : float
        White lateral and vertical body velocity [m/s] (non-holonomic tolerance).
    gyro_scale : bool
        Estimate the vertical gyro scale factor (initial std from the IMU model or
        ``FilterConfig.initial_gyro_scale_std``).
    split_turn_on : bool
        With ``bias_model="gauss_markov"``, model the turn-on biases as separate random
        constants (see the module docstring). False: one Gauss-Markov state per bias whose
        initial std includes the turn-on bias (the usual, but inconsistent, shortcut).
    azimuth : {"exact", "level", "projected"}
    coriolis : bool
    window : float
        Centred averaging window of accelerometers and odometer acceleration [s].
    odometer_scale, gyro_scale_z : float
        Initial nominal values.
    """

    odometer_speed_std: float = 0.02
    odometer_rate: float | None = None
    odometer_scale_std: float = 0.02
    odometer_scale_psd: float = 0.0
    slip_std: float = 0.02
    gyro_scale: bool = False
    split_turn_on: bool = True
    azimuth: str = "exact"
    coriolis: bool = True
    window: float = 1.0
    odometer_scale: float = 0.0
    gyro_scale_z: float = 0.0

    def validate(self) -> None:
        azimuth_mode_id(self.azimuth)
        for key in ("odometer_speed_std", "odometer_scale_std", "odometer_scale_psd", "slip_std",
                    "window"):
            v = getattr(self, key)
            if not (np.isfinite(v) and v >= 0):
                raise ConfigError("must be a finite non-negative number", column=key, found=v)
        if self.slip_std <= 0 and self.odometer_speed_std <= 0:
            raise ConfigError("slip_std or odometer_speed_std must be positive (regular P)",
                              column="slip_std", found=self.slip_std)


def _component(x, i):
    """Component ``i`` of a scalar-or-3-vector setting."""
    a = np.asarray(x, float)
    return float(a) if a.ndim == 0 else float(a.reshape(-1)[i])


@dataclass
class RissProcess:
    """Numbers of the RISS error process (SI): noise PSDs ``qc = (q_g, q_a, q_a, q_od)``,
    per-dynamic-state ``decay`` (1/tau) and driving PSD ``qdiag``, initial std ``p0`` (all x
    states), initial nominal parameters ``par0`` and the instantaneous variances used for the
    algebraic velocity / tilt."""

    layout: RissLayout
    qc: np.ndarray
    decay: np.ndarray
    qdiag: np.ndarray
    p0: np.ndarray
    par0: np.ndarray
    odometer_var: float
    accel_var_window: float
    odo_accel_var: float
    gyro_var_window: float
    slip_var: float


def _bias_parts(turn_on, instab, tau, rrw, model, split):
    """((std, decay, psd) of the dynamic bias state, turn-on std or None)."""
    if model == "gauss_markov":
        if instab > 0 and np.isfinite(tau) and tau > 0:
            if split and turn_on > 0:
                return (instab, 1.0 / tau, 2.0 * instab**2 / tau), turn_on
            return (float(np.hypot(turn_on, instab)), 1.0 / tau, 2.0 * instab**2 / tau), None
        return (float(np.hypot(turn_on, instab)), 0.0, rrw**2), None
    p0 = float(np.hypot(turn_on, instab))
    if model == "random_walk":
        if rrw > 0:
            return (p0, 0.0, rrw**2), None
        if instab > 0 and np.isfinite(tau) and tau > 0:
            return (p0, 0.0, 2.0 * instab**2 / tau), None
        return (p0, 0.0, 0.0), None
    if model == "random_constant":
        return (p0, 0.0, 0.0), None
    raise ConfigError(f"unknown bias model {model!r}", column="bias_model",
                      expected=["gauss_markov", "random_walk", "random_constant"], found=model)


def riss_process(config: FilterConfig, riss: RissConfig, imu_dt: float) -> RissProcess:
    """Build the RISS process numbers from the filter and RISS settings and the IMU interval."""
    m = grade(config.imu_model) if isinstance(config.imu_model, str) else config.imu_model
    (sg, dg, qg), g0 = _bias_parts(m.gyro_bias, m.gyro_bias_instability, m.bias_correlation_time,
                                   m.gyro_rrw, config.bias_model, riss.split_turn_on)
    (sa, da, qa), a0 = _bias_parts(m.accel_bias, m.accel_bias_instability,
                                   m.bias_correlation_time, m.accel_rrw, config.bias_model,
                                   riss.split_turn_on)
    if config.initial_gyro_bias_std is not None:
        sg, g0 = _component(config.initial_gyro_bias_std, 2), None
    if config.initial_accel_bias_std is not None:
        sa, a0 = _component(config.initial_accel_bias_std, 0), None
    turn_on = g0 is not None or a0 is not None
    layout = RissLayout(riss.gyro_scale, turn_on)
    ny, n = layout.ny, layout.n
    decay = np.zeros(ny)
    qdiag = np.zeros(ny)
    p0 = np.zeros(n)
    p0[0:3] = [_component(config.initial_pos_std, i) for i in range(3)]
    p0[3:6] = [_component(config.initial_vel_std, i) for i in range(3)]
    p0[6] = _component(config.initial_att_std, 2)
    p0[7] = riss.odometer_scale_std
    qdiag[4] = riss.odometer_scale_psd
    p0[8], decay[5], qdiag[5] = sg, dg, qg
    p0[9] = p0[10] = sa
    decay[6] = decay[7] = da
    qdiag[6] = qdiag[7] = qa
    if riss.gyro_scale:
        p0[11] = (m.gyro_scale if config.initial_gyro_scale_std is None
                  else _component(config.initial_gyro_scale_std, 2))
    if turn_on:
        t0 = layout["bias_turn_on"].start
        p0[t0] = g0 or 0.0
        p0[t0 + 1] = p0[t0 + 2] = a0 or 0.0
    par0 = np.zeros(N_PAR)
    par0[0] = riss.odometer_scale
    if config.gyro_bias is not None:
        par0[1] = _component(config.gyro_bias, 2)
    if config.accel_bias is not None:
        par0[2], par0[3] = _component(config.accel_bias, 0), _component(config.accel_bias, 1)
    par0[4] = riss.gyro_scale_z
    rate = riss.odometer_rate if riss.odometer_rate else 1.0 / imu_dt
    q_od = riss.odometer_speed_std**2 / rate
    qc = np.array([m.gyro_arw**2, m.accel_vrw**2, m.accel_vrw**2, q_od])
    # instantaneous variances of the window averages: white noise of PSD q averaged over w has
    # variance q / w; the odometer acceleration is a difference of two speeds w apart, each
    # interpolated half-way between two IMU-rate samples when averaged (variance halved)
    w = max(riss.window, imu_dt)
    w_od = max(riss.window, 1.0 / rate)
    interp = 0.5 if (riss.window > imu_dt and riss.odometer_rate is None) else 1.0
    if np.any(p0 < 0) or not np.all(np.isfinite(p0)):
        raise ConfigError("initial standard deviations must be finite and non-negative")
    return RissProcess(layout, qc, decay, qdiag, p0, par0, riss.odometer_speed_std**2,
                       m.accel_vrw**2 / w, 2.0 * interp * riss.odometer_speed_std**2 / w_od**2,
                       m.gyro_arw**2 / w, riss.slip_std**2)


# --- compiled error dynamics -------------------------------------------------------------------------
@entry
@njit(cache=True)
def riss_jacobians(st, aux, az_mode, Jp, Jr, Jv, Gp, Gr, Gv, Ja, Ga):
    """Linearised pitch, roll, velocity and azimuth-rate errors at the current nominal, in the
    base columns ``B_*`` (9) and noise inputs ``W_*`` (4).

    ``dp = Jp y + Gp w``, ``dr = Jr y + Gr w``, ``dv = Jv y + Gv w`` (Jv (3, 9), Gv (3, 4)) and
    ``d(dA)/dt = Ja y + Ga w``. ``aux`` is the auxiliary output of
    :func:`insgnss.mechanization.riss.riss_step`.
    """
    w_lb, vm, a, g, adot = aux[0], aux[1], aux[2], aux[3], aux[4]
    vk, wz, pdot = aux[6], aux[7], aux[8]
    A, p, r = st[ST_A], st[ST_P], st[ST_R]
    sp, cp = np.sin(p), np.cos(p)
    sr, cr = np.sin(r), np.cos(r)
    sa, ca = np.sin(A), np.cos(A)
    tp = sp / cp
    gcp = g * cp
    for i in range(NB):
        Jp[i] = 0.0
        Jr[i] = 0.0
        Ja[i] = 0.0
        for k in range(3):
            Jv[k, i] = 0.0
    for i in range(4):
        Gp[i] = 0.0
        Gr[i] = 0.0
        Ga[i] = 0.0
        for k in range(3):
            Gv[k, i] = 0.0
    # pitch (eq. 1)
    Jp[B_ODO] = a / gcp
    Jp[B_BAY] = -1.0 / gcp
    Gp[W_Y] = 1.0 / gcp
    # roll (eq. 2)
    Jr[B_ODO] = vm * w_lb / gcp
    Jr[B_BGZ] = vm / gcp
    Jr[B_BAX] = 1.0 / gcp
    Jr[B_SGZ] = vm * wz / gcp
    Gr[W_G] = -vm / gcp
    Gr[W_X] = -1.0 / gcp
    Gr[W_OD] = -w_lb / gcp
    k = sr * tp
    for i in range(NB):
        Jr[i] = (Jr[i] + k * Jp[i]) / cr
    for i in range(4):
        Gr[i] = (Gr[i] + k * Gp[i]) / cr
    # azimuth rate (eq. 3 variants)
    if az_mode == 0:  # level
        cb, cpp, crr = 1.0, 0.0, 0.0
    elif az_mode == 1:  # projected
        cb, cpp, crr = cp * cr, wz * sp * cr, wz * cp * sr
    else:  # exact: dA/dt = (dp/dt sin r - w_z + (C^T w_il)_z) / (cos p cos r)
        # d(C e_z)/dr = C e_x and d(C e_z)/dp = -cos r C e_y give the Earth/transport-rate terms
        lat, h = st[ST_LAT], st[ST_H]
        M, N = radii(lat)
        wil_e = -st[ST_VN] / (M + h)
        wil_n = OMEGA_E * np.cos(lat) + st[ST_VE] / (N + h)
        wil_u = OMEGA_E * np.sin(lat) + st[ST_VE] * np.tan(lat) / (N + h)
        cx = (ca * cr + sa * sp * sr) * wil_e + (-sa * cr + ca * sp * sr) * wil_n - cp * sr * wil_u
        cy = sa * cp * wil_e + ca * cp * wil_n + sp * wil_u
        cb = 1.0 / (cp * cr)
        cpp = adot * tp - cy / cp
        crr = adot * sr / cr + pdot / cp + cx * cb
    for i in range(NB):
        Ja[i] = cpp * Jp[i] + crr * Jr[i]
    Ja[B_BGZ] += cb
    Ja[B_SGZ] += cb * wz
    for i in range(4):
        Ga[i] = cpp * Gp[i] + crr * Gr[i]
    Ga[W_G] -= cb
    # velocity (eq. 4)
    u0, u1, u2 = sa * cp, ca * cp, sp
    up0, up1, up2 = -sa * sp, -ca * sp, cp
    for i in range(NB):
        Jv[0, i] = vk * up0 * Jp[i]
        Jv[1, i] = vk * up1 * Jp[i]
        Jv[2, i] = vk * up2 * Jp[i]
    Jv[0, B_ODO] -= vk * u0
    Jv[1, B_ODO] -= vk * u1
    Jv[2, B_ODO] -= vk * u2
    Jv[0, B_HEAD] += vk * ca * cp
    Jv[1, B_HEAD] -= vk * sa * cp
    for i in range(4):
        Gv[0, i] = vk * up0 * Gp[i]
        Gv[1, i] = vk * up1 * Gp[i]
        Gv[2, i] = vk * up2 * Gp[i]
    Gv[0, W_OD] += u0
    Gv[1, W_OD] += u1
    Gv[2, W_OD] += u2


@entry
@njit(cache=True)
def riss_propagate(st, par, j0, j1, t, dthz, fx, fy, aod, vw, vbar, vod, gravity_model, az_mode,
                   coriolis, ybase, ytwin, qc, decay, qdiag, Phi, Qd, out_st, out_aux):
    """Run the RISS nominal from sample ``j0`` to ``j1`` and accumulate ``Phi_y``, ``Q_y``.

    The dynamic states map onto the base columns ``ybase`` (turn-on twins, ``ytwin``, share
    their partner's columns and have no dynamics of their own). ``out_st[k]`` /
    ``out_aux[k]`` receive the state and the auxiliary quantities of every sample k in
    ``(j0, j1]``. ``Phi`` and ``Qd`` (ny, ny) are overwritten.
    """
    ny = Phi.shape[0]
    cols = np.empty((5, 3))
    aux = np.empty(9)
    Jp = np.empty(NB)
    Jr = np.empty(NB)
    Ja = np.empty(NB)
    Jv = np.empty((3, NB))
    Gp = np.empty(4)
    Gr = np.empty(4)
    Ga = np.empty(4)
    Gv = np.empty((3, 4))
    Fb = np.zeros((NB, NB))
    Gb = np.zeros((NB, 4))
    F = np.empty((ny, ny))
    G = np.empty((ny, 4))
    Ad = np.empty((ny, ny))
    T1 = np.empty((ny, ny))
    T2 = np.empty((ny, ny))
    for r in range(ny):
        for c in range(ny):
            Phi[r, c] = 1.0 if r == c else 0.0
            Qd[r, c] = 0.0
    for k in range(j0 + 1, j1 + 1):
        dt = t[k] - t[k - 1]
        lat, h = st[ST_LAT], st[ST_H]
        M, _ = radii(lat)
        riss_step(st, k, t, dthz, fx, fy, aod, vw, vbar, vod, par, gravity_model, az_mode,
                  coriolis, cols, aux)
        riss_jacobians(st, aux, az_mode, Jp, Jr, Jv, Gp, Gr, Gv, Ja, Ga)
        # continuous F and G in base columns
        for r in range(3):
            for c in range(NB):
                Fb[r, c] = Jv[r, c]
            for c in range(4):
                Gb[r, c] = Gv[r, c]
        for c in range(NB):
            Fb[B_HEAD, c] = Ja[c]
        Fb[B_HEAD, B_N] += OMEGA_E * np.cos(lat) / (M + h)
        for c in range(4):
            Gb[B_HEAD, c] = Ga[c]
        # map onto the layout's dynamic states
        for r in range(ny):
            for c in range(ny):
                F[r, c] = 0.0 if ytwin[r] else Fb[ybase[r], ybase[c]]
            for c in range(4):
                G[r, c] = 0.0 if ytwin[r] else Gb[ybase[r], c]
            F[r, r] -= decay[r]
        # A = I + F dt + (F dt)^2 / 2
        for r in range(ny):
            for c in range(ny):
                s2 = 0.0
                for m in range(ny):
                    s2 += F[r, m] * F[m, c]
                Ad[r, c] = F[r, c] * dt + 0.5 * s2 * dt * dt + (1.0 if r == c else 0.0)
        # Phi <- A Phi
        for r in range(ny):
            for c in range(ny):
                s2 = 0.0
                for m in range(ny):
                    s2 += Ad[r, m] * Phi[m, c]
                T1[r, c] = s2
        for r in range(ny):
            for c in range(ny):
                Phi[r, c] = T1[r, c]
        # Qd <- A Qd A^T + (G Qc G^T + diag(qdiag)) dt
        for r in range(ny):
            for c in range(ny):
                s2 = 0.0
                for m in range(ny):
                    s2 += Ad[r, m] * Qd[m, c]
                T1[r, c] = s2
        for r in range(ny):
            for c in range(ny):
                s2 = 0.0
                for m in range(ny):
                    s2 += T1[r, m] * Ad[c, m]
                gq = 0.0
                for m in range(4):
                    gq += G[r, m] * qc[m] * G[c, m]
                T2[r, c] = s2 + gq * dt
            T2[r, r] += qdiag[r] * dt
        for r in range(ny):
            for c in range(ny):
                Qd[r, c] = 0.5 * (T2[r, c] + T2[c, r])
        for i in range(st.shape[0]):
            out_st[k, i] = st[i]
        for i in range(9):
            out_aux[k, i] = aux[i]


# --- Python-level helpers ------------------------------------------------------------------------------
def _jacobians_y(st, aux, az_mode, lay: RissLayout):
    """Pitch, roll (ny) and velocity (3, ny) Jacobians in the layout's dynamic states, and the
    velocity noise gain Gv (3, 4)."""
    Jp, Jr, Ja = np.empty(NB), np.empty(NB), np.empty(NB)
    Jv = np.empty((3, NB))
    Gp, Gr, Ga = np.empty(4), np.empty(4), np.empty(4)
    Gv = np.empty((3, 4))
    riss_jacobians(st, aux, az_mode, Jp, Jr, Jv, Gp, Gr, Gv, Ja, Ga)
    b = lay.y_base
    return Jp[b], Jr[b], Jv[:, b], Gv


def _white_cov(proc: RissProcess) -> np.ndarray:
    """Instantaneous covariance of the white inputs (gyro, accel x, accel y, odometer speed) as
    they enter the window-averaged pitch, roll and velocity at one epoch."""
    return np.diag([proc.gyro_var_window, proc.accel_var_window,
                    proc.accel_var_window + proc.odo_accel_var, proc.odometer_var])


def transition(proc: RissProcess, Phi_y, Q_y, Jv, Gv, C):
    """Full-state ``Phi`` and ``Q`` from the dynamic-state ones (algebraic velocity rows);
    ``C`` (C_b^l) orients the lateral / vertical slip noise."""
    lay = proc.layout
    n, yi = lay.n, lay.y_index
    Phi = np.zeros((n, n))
    Q = np.zeros((n, n))
    Phi[np.ix_(yi, yi)] = Phi_y
    Phi[3:6, yi] = Jv @ Phi_y
    Q[np.ix_(yi, yi)] = Q_y
    JQ = Jv @ Q_y
    Q[3:6, yi] = JQ
    Q[yi, 3:6] = JQ.T
    Q[3:6, 3:6] = (JQ @ Jv.T + Gv @ _white_cov(proc) @ Gv.T
                   + proc.slip_var * (np.outer(C[:, 0], C[:, 0]) + np.outer(C[:, 2], C[:, 2])))
    return Phi, 0.5 * (Q + Q.T)


def tilt_map(lay: RissLayout, Jp, Jr, st) -> np.ndarray:
    """(3, n) map from the RISS error state to the l-frame misalignment ``phi`` (``C_nom =
    (I + [phi x]) C_true``): ``phi = dp (cA, -sA, 0) + dr (sA cp, cA cp, sp) - dA (0, 0, 1)``."""
    A, p = st[ST_A], st[ST_P]
    sa, ca, sp, cp = np.sin(A), np.cos(A), np.sin(p), np.cos(p)
    T = np.zeros((3, lay.n))
    T[:, lay.y_index] += np.outer([ca, -sa, 0.0], Jp) + np.outer([sa * cp, ca * cp, sp], Jr)
    T[2, 6] -= 1.0
    return T


def virtual_map(lay: RissLayout, Jp, Jr, st) -> np.ndarray:
    """(15, n) map ``T`` from the RISS error to the strapdown error ``(dr, dv, phi, db_g,
    db_a)`` seen by the measurement models (gyro x/y and accelerometer z biases: zero)."""
    T = np.zeros((15, lay.n))
    T[0:6, 0:6] = np.eye(6)
    T[6:9] = tilt_map(lay, Jp, Jr, st)
    for row, k in ((11, 0), (12, 1), (13, 2)):  # gyro z, accel x, accel y (+ turn-on parts)
        for xi in lay.param_x[k + 1]:
            if xi >= 0:
                T[row, xi] = 1.0
    return T


_VIRTUAL_LAYOUT = StateLayout()


def _nominal_state(st, par, aux, fb_mean, time, seg_dur, gyro_psd) -> NominalState:
    """The RISS nominal as a strapdown :class:`NominalState` for the measurement models."""
    cols = np.empty((5, 3))
    riss_dcm_col(st[ST_A], st[ST_P], st[ST_R], cols)
    nav = NominalState()
    nav.time = time
    nav.lat, nav.lon, nav.height = st[ST_LAT], st[ST_LON], st[ST_H]
    nav.vel = st[ST_VE:ST_VU + 1].copy()
    nav.C = np.ascontiguousarray(cols[:3].T)
    g = aux[3] if aux[3] > 0 else 9.8
    nav.omega_ib = np.array([0.0, 0.0, aux[7]])
    nav.f_ib = nav.C.T @ np.array([0.0, 0.0, g])
    nav.omega_ib_mean, nav.f_ib_mean = fb_mean
    nav.segment_duration = seg_dur
    nav.params = np.array([0.0, 0.0, par[1], par[2], par[3], 0.0])
    nav.layout = _VIRTUAL_LAYOUT
    nav.M, nav.N = radii(nav.lat)
    nav.gyro_psd = gyro_psd
    return nav


def _extrapolate(nav: NominalState, dt: float) -> None:
    """Move the nominal position by ``vel * dt`` (measurement between IMU samples)."""
    if dt != 0.0:
        nav.lat += nav.vel[1] * dt / (nav.M + nav.height)
        nav.lon += nav.vel[0] * dt / ((nav.N + nav.height) * np.cos(nav.lat))
        nav.height += nav.vel[2] * dt
        nav.time += dt


def _feedback(st, par, bparts, x, lay: RissLayout, Jp, Jr):
    """Closed-loop correction of the nominal state with the error estimate ``x``.

    ``bparts`` (2, 3) holds the nominal Gauss-Markov (row 0) and turn-on (row 1) parts of the
    gyro z, accel x and accel y biases; ``par[1:4]`` is their sum."""
    M, N = radii(st[ST_LAT])
    h = st[ST_H]
    lat = st[ST_LAT]
    st[ST_LAT] = lat - x[1] / (M + h)
    st[ST_LON] -= x[0] / ((N + h) * np.cos(lat))
    st[ST_H] -= x[2]
    st[ST_VE:ST_VU + 1] -= x[3:6]
    y = x[lay.y_index]
    st[ST_A] = np.mod(st[ST_A] - x[6], 2 * np.pi)
    st[ST_P] -= Jp @ y
    st[ST_R] -= Jr @ y
    par[0] -= x[7]
    if lay.gyro_scale:
        par[4] -= x[11]
    for i in range(3):
        bparts[0, i] -= x[8 + i]
        if lay.turn_on:
            bparts[1, i] -= x[lay["bias_turn_on"].start + i]
    par[1:4] = bparts[0] + bparts[1]


class RissModel(ProcessModelBase):
    """The 3D RISS as a process model of the filter engine (module docstring).

    Epochs sit on IMU samples (``split = False``); a measurement between samples sees the
    nominal of the sample at or before it extrapolated with its velocity. Measurement models
    see a 15-state strapdown :class:`~insgnss.filter.measurements.NominalState`; their ``H`` is
    mapped by :func:`virtual_map` (and a ZARU reduced to its vertical row: the RISS has one
    gyro).
    """

    n_nav = 7  # position, velocity, heading
    split = False
    noise_blocks = (slice(0, 3), slice(3, 6), slice(6, 7))

    def __init__(self, inputs: RissInputs, initial: NavState, config: FilterConfig,
                 riss: RissConfig, proc: RissProcess):
        self.inputs = inputs
        self.t = inputs.t
        self.proc = proc
        self.layout = lay = proc.layout
        self.riss = riss
        self.az_mode = azimuth_mode_id(riss.azimuth)
        self.gmod = earth.gravity_model_id(config.gravity_model)
        self.arrays = inputs.arrays()
        m_imu = grade(config.imu_model) if isinstance(config.imu_model, str) else config.imu_model
        self.gyro_psd = np.full(3, m_imu.gyro_arw**2)
        self.st = initial_riss_state(initial)
        self.par = proc.par0.copy()
        # nominal bias parts: Gauss-Markov (row 0; decays with its correlation time, as its error
        # model says) and turn-on (row 1); the kernel uses their sum par[1:4]
        self.bparts = np.zeros((2, 3))
        self.bparts[1 if lay.turn_on else 0] = self.par[1:4]
        self.bdecay = proc.decay[5:8]
        riss_velocity(self.st, inputs.v_od[0] / (1.0 + self.par[0]))
        self.n_par = N_PAR + 6
        self.j = 0  # current sample
        self.timing = {"mechanization": 0.0, "covariance": 0.0}
        ny = lay.ny
        self.Phi_y = np.empty((ny, ny))
        self.Q_y = np.empty((ny, ny))
        self.cols = np.empty((5, 3))

    def prepare(self, epochs: np.ndarray, dense=None) -> None:
        n_rows = self.t.size
        self.out_st = np.empty((n_rows, 9))
        self.out_aux = np.zeros((n_rows, 9))
        self.out_st[0] = self.st
        v0 = self.inputs.v_od[0]
        self.out_aux[0] = [0.0, v0, 0.0, earth.normal_gravity(self.st[ST_LAT], self.st[ST_H]),
                           0.0, 0.0, v0, 0.0, 0.0]
        self.seg = np.zeros(n_rows, np.int64)
        self.post = np.zeros(n_rows, np.bool_)
        self.post[0] = True
        self._epoch_state(0, 0)

    def initial_covariance(self) -> np.ndarray:
        return np.diag(self.proc.p0**2)

    def _epoch_state(self, j0: int, j1: int) -> None:
        """Jacobians and the measurement map at the epoch sample ``j1``."""
        self.Jp, self.Jr, self.Jv, self.Gv = _jacobians_y(self.st, self.out_aux[j1], self.az_mode,
                                                          self.layout)
        self.T = None
        self.seg_dur = self.t[j1] - self.t[j0]
        self.j0 = j0

    def propagate(self, t_end: float, node: int):
        perf = _time.perf_counter
        c0 = perf()
        j0 = self.j
        j1 = int(np.searchsorted(self.t, t_end))
        riss_propagate(self.st, self.par, j0, j1, *self.arrays, self.gmod, self.az_mode,
                       bool(self.riss.coriolis), self.layout.y_base, self.layout.y_twin,
                       self.proc.qc, self.proc.decay, self.proc.qdiag, self.Phi_y, self.Q_y,
                       self.out_st, self.out_aux)
        if np.any(self.bdecay > 0):
            self.bparts[0] *= np.exp(-self.bdecay * (self.t[j1] - self.t[j0]))
            self.par[1:4] = self.bparts[0] + self.bparts[1]
        self.seg[j0 + 1:j1 + 1] = node
        self.j = j1
        c1 = perf()
        self._epoch_state(j0, j1)
        riss_dcm_col(self.st[ST_A], self.st[ST_P], self.st[ST_R], self.cols)
        Phi, Q = transition(self.proc, self.Phi_y, self.Q_y, self.Jv, self.Gv, self.cols[:3].T)
        self.timing["mechanization"] += c1 - c0
        self.timing["covariance"] += perf() - c1
        return Phi, Q

    def nominal_finite(self) -> bool:
        return bool(np.all(np.isfinite(self.st)))

    def nominal(self, time: float) -> NominalState:
        j0, j1 = self.j0, self.j
        dthz = np.sum(self.inputs.dtheta_z[j0 + 1:j1 + 1])
        dur = self.seg_dur
        wz = (dthz / dur - self.par[1]) / (1.0 + self.par[4]) if dur > 0 else 0.0
        fmean = (np.array([0.0, 0.0, wz]), np.array([0.0, 0.0, 0.0]))
        nav = _nominal_state(self.st, self.par, self.out_aux[j1], fmean, self.t[j1], dur,
                             self.gyro_psd)
        _extrapolate(nav, time - self.t[j1])
        return nav

    def observe(self, m, z, H, R):
        if isinstance(m, Zaru):  # only the vertical gyro exists
            z, H, R = z[2:], H[2:], R[2:, 2:]
        if self.T is None:
            self.T = virtual_map(self.layout, self.Jp, self.Jr, self.st)
        return z, H @ self.T, R

    def feedback(self, x: np.ndarray) -> None:
        _feedback(self.st, self.par, self.bparts, x, self.layout, self.Jp, self.Jr)
        self.out_st[self.j] = self.st

    def params(self) -> np.ndarray:
        return np.concatenate([self.par, self.bparts.ravel()])

    def close_epoch(self, node: int, time: float) -> None:
        self.seg[self.j] = node
        self.post[self.j] = True

    def output(self, store, n_nodes: int, n_rows: int, smoothed=None) -> pd.DataFrame:
        t = self.t[:n_rows]
        if smoothed is None:
            zeros = np.zeros((n_nodes, self.layout.n))
            return _assemble(t, self.out_st, self.out_aux, self.seg, self.post, store.t,
                             store.Pf[:n_nodes], store.Pp[:n_nodes], zeros, zeros, store.par,
                             self.proc)
        xs_plus, xs_minus, Ps, _ = smoothed
        return _assemble(t, self.out_st, self.out_aux, self.seg, self.post, store.t, Ps, Ps,
                         xs_plus, xs_minus, store.par, self.proc)

    def final_state(self, time: float) -> NavState:
        j = int(np.searchsorted(self.t, time))
        s_end = self.out_st[j]
        cols = np.empty((5, 3))
        riss_dcm_col(s_end[ST_A], s_end[ST_P], s_end[ST_R], cols)
        return NavState(s_end[ST_LAT], s_end[ST_LON], s_end[ST_H], s_end[ST_VE:ST_VU + 1].copy(),
                        np.ascontiguousarray(cols[:3].T), float(self.t[j]))


def run_riss_filter(
    imu: pd.DataFrame,
    odometer,
    initial: NavState,
    measurements: list,
    config: FilterConfig | None = None,
    riss: RissConfig | None = None,
    *,
    inputs: RissInputs | None = None,
) -> FilterResult:
    """RISS/GNSS closed-loop error-state Kalman filter with smoother: the filter engine
    (:func:`insgnss.filter.engine.run_engine`) with the RISS process model (:class:`RissModel`).

    Parameters
    ----------
    imu : DataFrame
        IMU table (rates or increments); only the ``z`` gyro and the ``x, y`` accelerometers
        are used.
    odometer : DataFrame or array
        Odometer (``speed`` [m/s] or ``distance`` [m] increments, indexed by time), or speeds
        at the IMU times - the RISS input.
    initial : NavState
        Initial position and heading (pitch, roll and velocity follow from the sensors).
    measurements : list of Measurement
        Models of :mod:`insgnss.filter.measurements` (GNSS position / velocity, ZUPT, CUPT,
        heading, non-holonomic ``BodyVelocity`` without extra states).
    config : FilterConfig
        Common settings (IMU model, bias model, ``epoch_interval``, gating, smoother, initial
        stds: ``initial_att_std[2]`` is the heading std).
    riss : RissConfig
        RISS-specific settings.
    inputs : RissInputs, optional
        Pre-built inputs (skips :func:`insgnss.mechanization.riss.riss_inputs`).

    Returns
    -------
    FilterResult
        As :func:`insgnss.filter.engine.run_filter`; the parameter columns are
        ``odometer_scale gyro_bias_z accel_bias_x accel_bias_y`` [``gyro_scale_z``] and their
        ``_std``; ``params`` holds per epoch the nominal ``[k, b_gz, b_ax, b_ay, s_gz]``
        followed by the Gauss-Markov parts and the turn-on parts of ``b_gz, b_ax, b_ay``.
    """
    config = FilterConfig() if config is None else config
    riss = RissConfig() if riss is None else riss
    config.validate()
    riss.validate()
    measurements = list(measurements)
    for m in measurements:
        if m.extra_states():
            raise ConfigError(f"{type(m).__name__} needs extra states; with the RISS process "
                              "model the odometer is an input, not a measurement",
                              column="measurements", found=repr(m))
        if getattr(m, "high_rate", False):
            raise ConfigError(f"{type(m).__name__}: the RISS process model has no compiled "
                              "high-rate path (use high_rate=False)", column="measurements",
                              found=repr(m))
    if inputs is None:
        inputs = riss_inputs(imu, odometer, window=riss.window)
    dt_imu = float(np.median(np.diff(inputs.t)))
    if riss.odometer_rate is None and isinstance(odometer, pd.DataFrame) and len(odometer) > 1:
        dt_odo = float(np.median(np.diff(odometer.index.to_numpy(float))))
        if dt_odo > 1.1 * dt_imu:  # slower than the IMU: its samples are the independent ones
            riss = replace(riss, odometer_rate=1.0 / dt_odo)
    model = RissModel(inputs, initial, config, riss, riss_process(config, riss, dt_imu))
    return run_engine(model, measurements, config)


def _assemble(t, out_st, out_aux, seg, is_ep, ep_t, P_start, P_end, X_start, X_end, par_ep,
              proc: RissProcess) -> pd.DataFrame:
    """IMU-rate output table: nominal corrected by the (interpolated) error estimate, stds."""
    lay = proc.layout
    npar = len(lay.param_labels)
    data = np.empty((t.size, 18 + 2 * npar))
    white = np.array([proc.accel_var_window + proc.odo_accel_var, proc.accel_var_window,
                      proc.gyro_var_window, proc.odometer_var])
    _assemble_kernel(t, out_st, out_aux, seg, is_ep, ep_t, np.ascontiguousarray(P_start),
                     np.ascontiguousarray(P_end), np.ascontiguousarray(X_start),
                     np.ascontiguousarray(X_end), par_ep, lay.y_index, lay.y_base,
                     lay.param_x, lay.param_nominal, white, data)
    cols = NAV_COLS + STD_COLS + lay.param_labels + [f"{c}_std" for c in lay.param_labels]
    return pd.DataFrame(data, index=pd.Index(t, name="time"), columns=cols, copy=False)


@entry
@njit(cache=True)
def _assemble_kernel(t, out_st, out_aux, seg, is_ep, ep_t, P_start, P_end, X_start, X_end,
                     par_ep, yi, yb, par_x, par_nom, white, out):
    """Row k of segment e (``ep_t[e-1] < t_k <= ep_t[e]``): the epoch row itself takes
    ``X_start[e], P_start[e]``; the other rows interpolate linearly in time between
    ``(X_start[e-1], P_start[e-1])`` and ``(X_end[e], P_end[e])`` (see
    :mod:`insgnss.filter.smoother`). Forward run: X = 0, ``P_start = P(e|e)``,
    ``P_end = P(e|e-1)``; smoothed: ``X_start = xs_plus``, ``X_end = xs_minus``,
    ``P_start = P_end = Ps``."""
    n = P_start.shape[1]
    ny = yi.shape[0]
    npar = par_x.shape[0]
    x = np.empty(n)
    P = np.empty((n, n))
    Jpb = np.empty(NB)
    Jrb = np.empty(NB)
    for k in range(t.shape[0]):
        e = seg[k]
        if is_ep[k] or e == 0:
            for a in range(n):
                x[a] = X_start[e, a]
                for b in range(n):
                    P[a, b] = P_start[e, a, b]
            pe = e
        else:
            w = (t[k] - ep_t[e - 1]) / (ep_t[e] - ep_t[e - 1])
            for a in range(n):
                x[a] = (1.0 - w) * X_start[e - 1, a] + w * X_end[e, a]
                for b in range(n):
                    P[a, b] = (1.0 - w) * P_start[e - 1, a, b] + w * P_end[e, a, b]
            pe = e - 1
        A, p, r = out_st[k, 6], out_st[k, 7], out_st[k, 8]
        w_lb, vm, acc, g, wz = out_aux[k, 0], out_aux[k, 1], out_aux[k, 2], out_aux[k, 3], out_aux[k, 7]
        if g <= 0.0:
            g = 9.8
        cp, cr = np.cos(p), np.cos(r)
        gcp = g * cp
        for a in range(NB):
            Jpb[a] = 0.0
            Jrb[a] = 0.0
        Jpb[B_ODO] = acc / gcp
        Jpb[B_BAY] = -1.0 / gcp
        Jrb[B_ODO] = vm * w_lb / gcp
        Jrb[B_BGZ] = vm / gcp
        Jrb[B_BAX] = 1.0 / gcp
        Jrb[B_SGZ] = vm * wz / gcp
        kk = np.sin(r) * np.tan(p)
        for a in range(NB):
            Jrb[a] = (Jrb[a] + kk * Jpb[a]) / cr
        correct_position_velocity(out_st, k, x, out)
        dp = 0.0
        dr = 0.0
        vp = 0.0
        vr = 0.0
        for a in range(ny):
            ja = Jpb[yb[a]]
            ra = Jrb[yb[a]]
            dp += ja * x[yi[a]]
            dr += ra * x[yi[a]]
            for b in range(ny):
                vp += ja * P[yi[a], yi[b]] * Jpb[yb[b]]
                vr += ra * P[yi[a], yi[b]] * Jrb[yb[b]]
        vp += white[0] / gcp**2
        vr += (white[1] + vm * vm * white[2] + w_lb * w_lb * white[3]) / (gcp * cr) ** 2
        out[k, 6] = r - dr
        out[k, 7] = p - dp
        out[k, 8] = (A - x[6]) % (2.0 * np.pi)
        for i in range(6):
            out[k, 9 + i] = np.sqrt(max(P[i, i], 0.0))
        out[k, 15] = np.sqrt(max(vr, 0.0))
        out[k, 16] = np.sqrt(max(vp, 0.0))
        out[k, 17] = np.sqrt(max(P[6, 6], 0.0))
        for i in range(npar):
            v = par_ep[pe, par_nom[i]]
            var = 0.0
            for a in range(2):
                ia = par_x[i, a]
                if ia < 0:
                    continue
                v -= x[ia]
                for b in range(2):
                    ib = par_x[i, b]
                    if ib >= 0:
                        var += P[ia, ib]
            out[k, 18 + i] = v
            out[k, 18 + npar + i] = np.sqrt(max(var, 0.0))


# --- pipeline entry point ------------------------------------------------------------------------------
