"""Measurement models of the error-state filter.

Every model is a small object holding its epoch times; given the nominal state at one of them
(:class:`NominalState`) it returns ``(z, H, R)`` or ``None`` (nothing to use at that epoch).
The innovation is ``z - H x`` with ``z = h(nominal) - measured``, so that with the
"nominal minus true" error convention of :mod:`.models` ``z = H dx + noise``.

Models
------
- :class:`GnssPosition`: antenna position with lever arm ``l`` (body RFU, IMU to antenna):
  ``z = r_nom + C l - r_gnss`` (ENU metres), ``H = [I, 0, -[(C l) x], 0...]``.
- :class:`GnssVelocity`: antenna velocity ``v + C (w_ib x l) - w_il x (C l)``;
  ``H_v = I``, ``H_phi = [w_il x][(C l) x] - [(C (w x l)) x]``, ``H_bg = C [l x]``.
- :class:`Zupt`: zero velocity, ``z = v_nom``.
- :class:`Zaru`: zero angular rate relative to the Earth,
  ``z = w_ib,nom - C^T w_ie^l``, ``H_bg = -I``, ``H_phi = -C^T [w_ie x]``; observes the gyro
  bias, the vertical one included.
- :class:`Cupt`: known coordinates at given times (surveyed control points).
- :class:`Heading`: magnetometer / dual-antenna heading (with a mounting offset).
- :class:`BodyVelocity`: constraints on body (vehicle) frame velocity components at a body
  point - non-holonomic (lateral / vertical zero), odometer forward speed with an optional
  scale-factor state and optional IMU-to-vehicle misalignment states. This is the hook
  used by the land-vehicle and RISS processing.

High rate: :class:`Zupt`, :class:`Zaru` and :class:`BodyVelocity` have one compiled (numba)
implementation of their ``(z, H, R)`` (:func:`evaluate_compiled`), used by their
:meth:`~Measurement.evaluate` and by the engine's compiled high-rate path
(:mod:`insgnss.filter.highrate`): built with ``high_rate=True`` they are applied at the IMU
sample nearest each of their times inside compiled code (ZUPT/ZARU at every IMU sample of a
foot-mounted INS, NHC, odometer), with the same gating, recovery and logs.

GNSS quality: per-epoch ``*_std`` columns are used as the measurement sigmas; an optional
``std_scale`` mapping ``{q: multiplier}`` inflates them by RTKLIB quality flag ``q``
(``q`` values absent from the mapping are skipped when ``use_q`` restricts them).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np
import pandas as pd

from ..aot import entry
from ..attitude import wrap_pi
from ..earth import GRAVITY_SOMIGLIANA, OMEGA_E, normal_gravity_sc
from ..errors import InputFormatError, InvalidValueError
from ..jit import njit
from .linalg import matmul, matvec
from .models import ExtraState, StateLayout


class NominalState:
    """The nominal (mechanized, fed-back) state handed to measurement models at an epoch.

    Attributes
    ----------
    time : float
    lat, lon, height : float
        [rad, rad, m]
    vel : (3,) array
        ENU velocity [m/s].
    C : (3, 3) array
        ``C_b^l``.
    omega_ib, f_ib : (3,) arrays
        Compensated angular rate [rad/s] and specific force [m/s^2] of the last IMU interval.
    omega_ib_mean, f_ib_mean : (3,) arrays
        Their means since the previous filter epoch.
    segment_duration : float
        Time since the previous filter epoch [s].
    params : (n - 9,) array
        Nominal parameter values (biases, scale factors, extra states), in layout order
        from index 9.
    layout : StateLayout
    M, N : float
        Meridian and prime-vertical radii at ``lat``.
    gyro_psd : (3,) array
        Gyro white-noise PSD of the process model (used for default ZARU sigmas).
    """

    __slots__ = ("time", "lat", "lon", "height", "vel", "C", "omega_ib", "f_ib", "omega_ib_mean",
                 "f_ib_mean", "segment_duration", "params", "layout", "M", "N", "gyro_psd")

    def param(self, name: str) -> np.ndarray:
        """Nominal value of a parameter block (e.g. ``"gyro_bias"``, ``"odometer_scale"``)."""
        s = self.layout[name]
        if s.start < 9:
            raise KeyError(f"{name!r} is a navigation block, not a parameter")
        return self.params[s.start - 9:s.stop - 9]

    def enu_offset(self, lat, lon, h) -> np.ndarray:
        """ENU metres from the point (lat, lon, h) to the nominal position (local radii; the
        longitude difference wrapped to (-pi, pi], so that a route across the antimeridian
        sees metres, not the circumference)."""
        return np.array([
            wrap_pi(self.lon - lon) * (self.N + self.height) * np.cos(self.lat),
            (self.lat - lat) * (self.M + self.height),
            self.height - h,
        ])


class Measurement:
    """Base class of the measurement models.

    Subclasses set :attr:`name` (the type used in logs and for per-type gating), provide
    :attr:`times` and implement :meth:`evaluate`.

    Parameters
    ----------
    times : array_like
        Epoch times [s], same time base as the IMU.
    gate_probability : float, optional
        Chi-square gating probability for this measurement; ``None`` uses the filter
        configuration, ``0`` disables gating.
    """

    name = "measurement"

    #: applied by the compiled high-rate path of the engine (models with :meth:`compiled`)
    high_rate = False

    #: the gate recovery may force it in (:mod:`.gating`): only absolute measurements that can
    #: re-anchor the state (GNSS position and velocity, control points, pseudoranges); never a
    #: constraint that is only approximately true (NHC in a skidding turn, a ZUPT detected
    #: while the vehicle creeps, an odometer on a slipping wheel)
    recoverable = False

    def __init__(self, times, gate_probability: float | None = None, name: str | None = None):
        self.times = np.asarray(times, dtype=float).reshape(-1)
        if self.times.size and not np.all(np.isfinite(self.times)):
            raise InvalidValueError(f"{type(self).__name__}: non-finite epoch times")
        self.gate_probability = gate_probability
        if name is not None:
            self.name = name

    def compiled(self, layout: StateLayout) -> CompiledSpec | None:
        """The model's description for the compiled path (:func:`evaluate_compiled`), or
        None if it has no compiled implementation."""
        return None

    def extra_states(self) -> list[ExtraState]:
        """States this measurement needs appended to the error state (default none)."""
        return []

    def evaluate(self, i: int, nav: NominalState):
        """``(z, H, R)`` for epoch ``i`` of :attr:`times`, or ``None``."""
        raise NotImplementedError

    def __len__(self) -> int:
        return self.times.size

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, epochs={self.times.size})"



#: prior sigma of a land vehicle's suspension pitch compliance [rad / (m/s^2)]: 10 deg/g,
#: a few times the pitch gradient of passenger cars (a few deg/g), so the data decides
PITCH_COMPLIANCE_STD = float(np.radians(10.0) / 9.80665)


# --- compiled implementation shared by the Python and the high-rate update paths -------------------
ZUPT, ZARU, BODY_VELOCITY = 0, 1, 2


class CompiledSpec(NamedTuple):
    """A measurement model for :func:`evaluate_compiled`: ``kind``, integer and float
    parameters ``ip`` (8,), ``fp`` (8,) and per-epoch ``values`` and ``std`` (N, 3)."""

    kind: int
    ip: np.ndarray
    fp: np.ndarray
    values: np.ndarray
    std: np.ndarray


@entry
@njit(cache=True)
def evaluate_compiled(kind, ip, fp, val, std, vel, C, lat, w_ib, window, gyro_psd, pnom, z, H, R):
    """``(z, H, R)`` of a compiled measurement model (``kind`` ZUPT, ZARU or BODY_VELOCITY with
    the parameters of :meth:`Measurement.compiled`) at one epoch, written into ``z`` (3,),
    the first rows of ``H`` (3, n) and ``R`` (3, 3). Returns the dimension (0: nothing to use).

    The nominal: ENU velocity ``vel``, ``C = C_b^l``, latitude, the compensated angular rate
    ``w_ib`` (of the last IMU interval, or averaged over ``window`` seconds), the gyro white-noise
    PSD and the parameter nominal ``pnom`` (error-state index 9 onwards). Equations: module
    docstring and the classes :class:`Zupt`, :class:`Zaru`, :class:`BodyVelocity`.
    """
    n = H.shape[1]
    for a in range(3):
        for c in range(n):
            H[a, c] = 0.0
        for b in range(3):
            R[a, b] = 0.0
    if kind == ZUPT:
        for a in range(3):
            z[a] = vel[a]
            H[a, 3 + a] = 1.0
            R[a, a] = std[a] * std[a]
        return 3
    if kind == ZARU:
        wie1 = OMEGA_E * np.cos(lat)
        wie2 = OMEGA_E * np.sin(lat)
        for a in range(3):
            z[a] = w_ib[a] - (C[1, a] * wie1 + C[2, a] * wie2)
            H[a, 9 + a] = -1.0
            # -C^T [w_ie x], [w_ie x] = [[0, -wu, wn], [wu, 0, 0], [-wn, 0, 0]]
            H[a, 6] = -(C[1, a] * wie2 - C[2, a] * wie1)
            H[a, 7] = -(-C[0, a] * wie2)
            H[a, 8] = -(C[0, a] * wie1)
            if fp[3] >= 0.0:
                s = fp[3 + a]
            else:
                if window <= 0.0:
                    return 0
                s = np.sqrt(gyro_psd[a] / window)
            s = max(s, fp[6])
            R[a, a] = s * s
        return 3
    # body velocity: v_b = C^T v + w x l, v_v = (I - [mu x]) v_b, h_k = (1 + s) v_v[k]
    k = ip[0]
    for r in range(k):
        if not np.isfinite(val[r]):
            return 0
    l0, l1, l2 = fp[0], fp[1], fp[2]
    vb = np.empty(3)
    J = np.zeros((3, n))
    for a in range(3):
        vb[a] = C[0, a] * vel[0] + C[1, a] * vel[1] + C[2, a] * vel[2]
        for c in range(3):
            J[a, 3 + c] = C[c, a]
    vb[0] += w_ib[1] * l2 - w_ib[2] * l1
    vb[1] += w_ib[2] * l0 - w_ib[0] * l2
    vb[2] += w_ib[0] * l1 - w_ib[1] * l0
    # C^T [v x]
    for a in range(3):
        J[a, 6] = C[1, a] * vel[2] - C[2, a] * vel[1]
        J[a, 7] = -C[0, a] * vel[2] + C[2, a] * vel[0]
        J[a, 8] = C[0, a] * vel[1] - C[1, a] * vel[0]
    # [l x]
    J[0, 10], J[0, 11] = -l2, l1
    J[1, 9], J[1, 11] = l2, -l0
    J[2, 9], J[2, 10] = -l1, l0
    vv = vb
    im = ip[6]
    if im >= 0:
        m0, m1, m2 = pnom[im - 9], pnom[im - 8], pnom[im - 7]
        Rm = np.array([[1.0, m2, -m1], [-m2, 1.0, m0], [m1, -m0, 1.0]])  # I - [mu x]
        vv = np.empty(3)
        J2 = np.empty((3, n))
        for a in range(3):
            vv[a] = Rm[a, 0] * vb[0] + Rm[a, 1] * vb[1] + Rm[a, 2] * vb[2]
            for c in range(n):
                J2[a, c] = Rm[a, 0] * J[0, c] + Rm[a, 1] * J[1, c] + Rm[a, 2] * J[2, c]
        J = J2
        # d v_v / d mu = [v_b x]
        J[0, im], J[0, im + 1], J[0, im + 2] = 0.0, -vb[2], vb[1]
        J[1, im], J[1, im + 1], J[1, im + 2] = vb[2], 0.0, -vb[0]
        J[2, im], J[2, im + 1], J[2, im + 2] = -vb[1], vb[0], 0.0
    isc = ip[4]
    sc = pnom[isc - 9] if isc >= 0 else 0.0
    for r in range(k):
        ax = ip[1 + r]
        h = vv[ax]
        for c in range(n):
            H[r, c] = J[ax, c]
        if isc >= 0 and ax == ip[5]:
            for c in range(n):
                H[r, c] *= 1.0 + sc
            H[r, isc] = vv[ip[5]]
            h *= 1.0 + sc
        z[r] = h - val[r]
        R[r, r] = std[r] * std[r]
        if ax == 0 and fp[3] > 0.0:
            # lateral slip of the tyres ~ slip_gradient x lateral acceleration (yaw rate x
            # speed), at the forward speed: sigma_slip = k |w_z| v^2 (BodyVelocity)
            slip = fp[3] * abs(w_ib[2]) * vb[1] * vb[1]
            R[r, r] += slip * slip
    return k


def _run_compiled(spec: CompiledSpec, i: int, nav: NominalState, w, window):
    """:func:`evaluate_compiled` on a NominalState (the Python update path)."""
    n = nav.layout.n
    z, H, R = np.empty(3), np.empty((3, n)), np.empty((3, 3))
    k = evaluate_compiled(spec.kind, spec.ip, spec.fp, spec.values[i], spec.std[i], nav.vel,
                          nav.C, nav.lat, w, window, nav.gyro_psd, nav.params, z, H, R)
    if k == 0:
        return None
    return z[:k], H[:k], R[:k, :k]


def _per_epoch(std, n: int, width: int, what: str) -> np.ndarray:
    """Sigmas as (n, width): scalar, per-component vector, per-epoch (n,) or (n, width)."""
    s = np.asarray(std, float)
    if s.ndim == 1 and s.size == n and s.size != width:  # one sigma per epoch
        s = s[:, None]
    try:
        return np.ascontiguousarray(np.broadcast_to(s, (n, width)), dtype=float)
    except ValueError:
        raise ValueError(f"{what}: std must be a scalar, {width} values, {n} values or an "
                         f"({n}, {width}) array; got shape {s.shape}") from None


def _pad3(a: np.ndarray) -> np.ndarray:
    out = np.full((a.shape[0], 3), np.nan)
    out[:, :a.shape[1]] = a
    return out

def cross3(a, b) -> np.ndarray:
    """Cross product of two 3-vectors (np.cross costs ~100 us of argument handling per call,
    which matters at one call per measurement)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def skew(v) -> np.ndarray:
    """``[v x]`` of one 3-vector (cheaper than the vectorised :func:`insgnss.attitude.skew`)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _vec3(x, what) -> np.ndarray:
    a = np.asarray(x, float)
    if a.ndim == 0:
        return np.full(3, float(a))
    if a.shape != (3,):
        raise ValueError(f"{what} must be a scalar or a 3-vector, got shape {a.shape}")
    return a.copy()


def _require(df: pd.DataFrame, cols, what: str):
    missing = [c for c in cols if c not in df.columns]
    if missing:
        raise InputFormatError(f"{what} table lacks columns {missing}", column=missing[0],
                               expected=list(cols), found=list(df.columns))


def _stds(df: pd.DataFrame, cols, default, std_scale, use_q, min_std):
    """Per-epoch sigmas (N, 3) from std columns (or ``default``), inflated by quality."""
    n = len(df)
    if all(c in df.columns for c in cols):
        s = df[list(cols)].to_numpy(float)
    else:
        if default is None:
            raise InputFormatError(f"no std columns {list(cols)} and no default std given",
                                   column=cols[0])
        s = np.broadcast_to(_vec3(default, "std"), (n, 3)).copy()
    valid = np.ones(n, bool)
    if "q" in df.columns and (std_scale or use_q is not None):
        q = df["q"].to_numpy()
        if std_scale:
            mult = np.array([std_scale.get(int(v), 1.0) if np.isfinite(v) else np.nan for v in q])
            s = s * mult[:, None]
        if use_q is not None:
            valid &= np.isin(q, list(use_q))
    s = np.maximum(s, min_std)
    valid &= np.all(np.isfinite(s), axis=1) & np.all(s > 0, axis=1)
    return s, valid


@njit(cache=True)
def _skew3(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@njit(cache=True)
def _cross3(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def _put3(H, c0, A, sign):
    """``H[:, c0:c0 + 3] = sign * A`` (3x3) by elements: a compiled slice assignment of an
    array brings numba's shape-mismatch error machinery (its string formatting) into the
    first-run compile, 2-3 s for the process."""
    for r in range(3):
        for c in range(3):
            H[r, c0 + c] = sign * A[r, c]


@entry
@njit(cache=True)
def _gnss_position(p, std, lever, C, lat, lon, height, M, N, n):
    """``(z, H, R)`` of :meth:`GnssPosition.evaluate`, compiled: one call per epoch instead of
    a dozen small array operations (their Python overhead was most of the epoch's cost).
    ``z``: ENU offset of the nominal antenna from the fix (:meth:`NominalState.enu_offset`
    plus ``C l``), ``H = [I, 0, -[C l x], 0]``."""
    la = matvec(C, lever)
    d = lon - p[1]  # wrap_pi: the longitude difference in (-pi, pi]
    d = -(np.mod(-d + np.pi, 2 * np.pi) - np.pi)
    z = np.empty(3)
    z[0] = d * (N + height) * np.cos(lat) + la[0]
    z[1] = (lat - p[0]) * (M + height) + la[1]
    z[2] = (height - p[2]) + la[2]
    H = np.zeros((3, n))
    H[0, 0] = H[1, 1] = H[2, 2] = 1.0
    _put3(H, 6, _skew3(la), -1.0)
    return z, H, np.diag(std ** 2)


@entry
@njit(cache=True)
def _gnss_velocity(v, std, lever, use_arm, vel, C, omega_ib, lat, height, M, N, n):
    """``(z, H, R)`` of :meth:`GnssVelocity.evaluate`, compiled (see :func:`_gnss_position`).
    With a lever arm ``l``: ``z += C (w_ib x l) - w_il x (C l)``, attitude rows
    ``[w_il x][C l x] - [C (w_ib x l) x]`` and gyro-bias rows ``C [l x]`` (the lever-arm
    terms of the antenna velocity, linearised about the nominal)."""
    H = np.zeros((3, n))
    H[0, 3] = H[1, 4] = H[2, 5] = 1.0
    z = vel - v
    if use_arm:
        u = matvec(C, _cross3(omega_ib, lever))
        cl = matvec(C, lever)
        w_il = np.array([
            -vel[1] / (M + height),
            OMEGA_E * np.cos(lat) + vel[0] / (N + height),
            OMEGA_E * np.sin(lat) + vel[0] * np.tan(lat) / (N + height),
        ])
        z = z + u - _cross3(w_il, cl)
        _put3(H, 6, matmul(_skew3(w_il), _skew3(cl)) - _skew3(u), 1.0)
        _put3(H, 9, matmul(C, _skew3(lever)), 1.0)
    return z, H, np.diag(std ** 2)


class GnssPosition(Measurement):
    """GNSS antenna position.

    Parameters
    ----------
    data : DataFrame
        Indexed by time with ``lat lon height`` [rad, m] and ``east_std north_std up_std`` [m]
        (or give ``std``); optional ``q`` for quality-based weighting.
    lever_arm : 3-vector
        IMU to antenna in the body frame (right-forward-up) [m].
    std : scalar or 3-vector, optional
        Sigmas (east, north, up) used when the table has no std columns.
    std_scale : mapping, optional
        ``{q: multiplier}`` applied to the sigmas by quality flag.
    use_q : collection, optional
        Only epochs with these ``q`` values are used.
    min_std : float
        Lower bound on the sigmas [m].
    """

    name = "gnss_pos"
    recoverable = True
    STD_COLS = ("east_std", "north_std", "up_std")

    def __init__(self, data: pd.DataFrame, lever_arm=(0.0, 0.0, 0.0), std=None,
                 std_scale: Mapping | None = None, use_q=None, min_std: float = 1e-3,
                 gate_probability: float | None = None, name: str | None = None):
        _require(data, ("lat", "lon", "height"), "GNSS position")
        super().__init__(np.asarray(data.index, float), gate_probability, name)
        self.pos = data[["lat", "lon", "height"]].to_numpy(float)
        self.std, valid = _stds(data, self.STD_COLS, std, std_scale, use_q, min_std)
        self.valid = valid & np.all(np.isfinite(self.pos), axis=1)
        self.lever_arm = _vec3(lever_arm, "lever_arm")

    def evaluate(self, i, nav):
        if not self.valid[i]:
            return None
        return _gnss_position(self.pos[i], self.std[i], self.lever_arm, nav.C, nav.lat,
                              nav.lon, nav.height, nav.M, nav.N, nav.layout.n)


class GnssVelocity(Measurement):
    """GNSS antenna velocity (ENU).

    ``data`` holds ``vel_e vel_n vel_u`` [m/s] and ``vel_e_std vel_n_std vel_u_std`` (or give
    ``std``); other parameters as :class:`GnssPosition`.
    """

    name = "gnss_vel"
    recoverable = True
    STD_COLS = ("vel_e_std", "vel_n_std", "vel_u_std")

    def __init__(self, data: pd.DataFrame, lever_arm=(0.0, 0.0, 0.0), std=None,
                 std_scale: Mapping | None = None, use_q=None, min_std: float = 1e-4,
                 gate_probability: float | None = None, name: str | None = None):
        _require(data, ("vel_e", "vel_n", "vel_u"), "GNSS velocity")
        super().__init__(np.asarray(data.index, float), gate_probability, name)
        self.vel = data[["vel_e", "vel_n", "vel_u"]].to_numpy(float)
        self.std, valid = _stds(data, self.STD_COLS, std, std_scale, use_q, min_std)
        self.valid = valid & np.all(np.isfinite(self.vel), axis=1)
        self.lever_arm = _vec3(lever_arm, "lever_arm")
        self._use_arm = bool(np.any(self.lever_arm != 0.0))

    def evaluate(self, i, nav):
        if not self.valid[i]:
            return None
        return _gnss_velocity(self.vel[i], self.std[i], self.lever_arm, self._use_arm, nav.vel,
                              nav.C, nav.omega_ib, nav.lat, nav.height, nav.M, nav.N,
                              nav.layout.n)


class Zupt(Measurement):
    """Zero-velocity update at the given times (the IMU is at rest).

    Parameters
    ----------
    times : array_like
    std : float, 3-vector, (N,) or (N, 3)
        Sigma of the zero-velocity pseudo-measurement [m/s] (per epoch: e.g. a soft ZUPT
        weighted by the stillness statistic).
    high_rate : bool
        Apply it on the engine's compiled high-rate path (at the IMU sample nearest each time).
    recoverable : bool
        Let the gate recovery force it in (:attr:`Measurement.recoverable`): only where rest
        is certain, as in the stance of a foot-mounted IMU; a vehicle's detected stillness
        may be slow motion.
    """

    name = "zupt"

    def __init__(self, times, std=0.01, gate_probability: float | None = None,
                 name: str | None = None, high_rate: bool = False, recoverable: bool = False):
        super().__init__(times, gate_probability, name)
        self.std = _per_epoch(std, self.times.size, 3, "Zupt")
        self.high_rate = bool(high_rate)
        self.recoverable = bool(recoverable)
        self._spec = CompiledSpec(ZUPT, np.zeros(8, np.int64), np.zeros(8), self.std, self.std)

    def compiled(self, layout):
        return self._spec

    def evaluate(self, i, nav):
        return _run_compiled(self._spec, i, nav, nav.omega_ib, 0.0)


class Zaru(Measurement):
    """Zero angular-rate update: at rest the body turns only with the Earth.

    ``z = w_ib - C^T w_ie^l`` with ``w_ib`` the bias-compensated gyro rate, averaged since the
    previous filter epoch (``average=True``) or of the last IMU interval.

    Parameters
    ----------
    times : array_like
    std : float or 3-vector, optional
        Sigma [rad/s]. Default: the gyro white noise averaged over the window,
        ``sqrt(psd / window)``, floored at ``min_std``.
    high_rate : bool
        Apply it on the engine's compiled high-rate path (at the IMU sample nearest each time;
        the averaging window is then that IMU interval).
    recoverable : bool
        Let the gate recovery force it in (see :class:`Zupt`).
    """

    name = "zaru"

    def __init__(self, times, std=None, average: bool = True, min_std: float = 1e-7,
                 gate_probability: float | None = None, name: str | None = None,
                 high_rate: bool = False, recoverable: bool = False):
        super().__init__(times, gate_probability, name)
        self.recoverable = bool(recoverable)
        self.std = None if std is None else _vec3(std, "std")
        self.average = bool(average)
        self.min_std = float(min_std)
        self.high_rate = bool(high_rate)
        fp = np.zeros(8)
        fp[3:6] = -1.0 if self.std is None else self.std
        fp[6] = self.min_std
        ip = np.zeros(8, np.int64)
        ip[7] = int(self.average)
        empty = np.zeros((self.times.size, 3))
        self._spec = CompiledSpec(ZARU, ip, fp, empty, empty)

    def compiled(self, layout):
        return self._spec

    def evaluate(self, i, nav):
        w = nav.omega_ib_mean if self.average else nav.omega_ib
        window = nav.segment_duration if self.average else 0.0
        return _run_compiled(self._spec, i, nav, w, window)


class Cupt(Measurement):
    """Coordinate update at control points: the IMU (or a body point) is at known coordinates.

    Parameters
    ----------
    times : array_like
        When the vehicle is at each control point.
    lat, lon, height : array_like
        Coordinates [rad, m] (one per time).
    std : scalar, 3-vector or (N, 3)
        Sigma of the control-point coordinates (east, north, up) [m].
    lever_arm : 3-vector
        IMU to the point that sits on the control point (body RFU) [m].
    """

    name = "cupt"
    recoverable = True

    def __init__(self, times, lat, lon, height, std=0.01, lever_arm=(0.0, 0.0, 0.0),
                 gate_probability: float | None = None, name: str | None = None):
        super().__init__(times, gate_probability, name)
        n = self.times.size
        self.pos = np.column_stack([np.broadcast_to(np.asarray(v, float), (n,))
                                    for v in (lat, lon, height)])
        s = np.asarray(std, float)
        self.std = np.broadcast_to(s if s.ndim != 1 or s.size == 3 else s[:, None], (n, 3)).copy()
        self.lever_arm = _vec3(lever_arm, "lever_arm")

    @classmethod
    def from_table(cls, data: pd.DataFrame, **kw) -> Cupt:
        """From a table indexed by time with ``lat lon height`` and optional std columns."""
        _require(data, ("lat", "lon", "height"), "control point")
        std = kw.pop("std", 0.01)
        if all(c in data.columns for c in GnssPosition.STD_COLS):
            std = data[list(GnssPosition.STD_COLS)].to_numpy(float)
        return cls(data.index, data["lat"], data["lon"], data["height"], std=std, **kw)

    def evaluate(self, i, nav):
        p = self.pos[i]
        la = nav.C @ self.lever_arm
        z = nav.enu_offset(p[0], p[1], p[2]) + la
        H = np.zeros((3, nav.layout.n))
        H[0, 0] = H[1, 1] = H[2, 2] = 1.0
        H[:, 6:9] = -skew(la)
        return z, H, np.diag(self.std[i] ** 2)


class Heading(Measurement):
    """Heading measurement (magnetometer or dual-antenna GNSS).

    ``z = wrap(A_nom + offset - A_measured)`` with ``H_phi = [C01 C21, C11 C21,
    -(C01^2 + C11^2)] / (C01^2 + C11^2)`` (derivative of ``atan2(C01, C11)`` under
    ``C_nom = (I + [phi x]) C``).

    Parameters
    ----------
    times, heading : array_like
        Heading [rad], clockwise from north.
    std : float or array_like
        Sigma [rad].
    offset : float
        Heading of the sensor's reference direction minus the body heading [rad] (e.g.
        the dual-antenna baseline azimuth in the body frame, or magnetic declination
        with the opposite sign for a magnetometer).
    """

    name = "heading"

    def __init__(self, times, heading, std, offset: float = 0.0,
                 gate_probability: float | None = None, name: str | None = None):
        super().__init__(times, gate_probability, name)
        n = self.times.size
        self.heading = np.broadcast_to(np.asarray(heading, float), (n,)).copy()
        self.std = np.broadcast_to(np.asarray(std, float), (n,)).copy()
        self.offset = float(offset)

    @classmethod
    def from_table(cls, data: pd.DataFrame, std=None, **kw) -> Heading:
        """From a table with ``heading`` [rad] and ``heading_std`` (or ``std``)."""
        _require(data, ("heading",), "heading")
        if "heading_std" in data.columns:
            std = data["heading_std"].to_numpy(float)
        if std is None:
            raise InputFormatError("heading table lacks 'heading_std' and no std was given",
                                   column="heading_std")
        return cls(data.index, data["heading"], std, **kw)

    def evaluate(self, i, nav):
        m = self.heading[i]
        if not np.isfinite(m):
            return None
        C = nav.C
        a = np.arctan2(C[0, 1], C[1, 1])
        h2 = C[0, 1] ** 2 + C[1, 1] ** 2
        if h2 < 1e-6:  # heading undefined near +-90 deg pitch
            return None
        H = np.zeros((1, nav.layout.n))
        H[0, 6] = C[0, 1] * C[2, 1] / h2
        H[0, 7] = C[1, 1] * C[2, 1] / h2
        H[0, 8] = -1.0
        z = np.array([float(wrap_pi(a + self.offset - m))])
        return z, H, np.array([[self.std[i] ** 2]])


class BodyVelocity(Measurement):
    """Constraints on components of the vehicle-frame velocity of a body point.

    Predicted measurement per constrained axis ``k`` (0 right, 1 forward, 2 up)::

        v_b = C^T v + w_ib x l                (velocity of the point, body frame)
        v_v = (I - [mu x]) v_b                (vehicle frame; mu = IMU-to-vehicle misalignment)
        h_k = (1 + s) v_v[k]  if k is the scaled axis, else v_v[k]
        h_up += kappa a_f v_v[forward]        (with a pitch-compliance state kappa)

    and ``z = h - measured``. The pitch-compliance term is the suspension's pitch: a car body
    squats (nose up) when it accelerates and dives when it brakes, by ``kappa`` [rad per
    m/s^2] of forward acceleration ``a_f = f_b[forward] + (C^T g^l)[forward]`` (the mean over
    the segment since the previous filter epoch; passenger cars: a few deg/g), so the body's
    forward axis is pitched up by ``kappa a_f`` from the road and the IMU sees a vertical
    body velocity ``-kappa a_f v_forward`` there. A vertical NHC without this term reads the
    squat as a pitch error, which tilts gravity into the forward channel (``g kappa a_f``:
    0.06 m/s^2 at 1 m/s^2 and 3.4 deg/g) and drives along-track drift in a GNSS outage.
    The term uses the IMU's forward body velocity ``v_f = (C^T v)[forward]`` (the lever arm and
    misalignment change it by far less than the 1 % that ``kappa a_f`` is of ``v_f``); its
    Jacobian: ``a_f v_f`` in ``kappa``, ``kappa a_f C[:, 1]`` in ``dv``, ``kappa (a_f C[:, 1]
    x v - v_f g (C[1, 1], -C[0, 1], 0))`` in ``phi``, ``-kappa v_f`` in the forward
    accelerometer bias.
    Typical uses:

    - non-holonomic constraint: ``axes=(0, 2)``, ``values=0``, sigmas ~0.05-0.2 m/s, the
      lever arm to the rear-axle centre (the point of a car that does not move sideways:
      elsewhere the yaw rate adds ``w_z x l`` of lateral velocity, 0.45 m/s at 1.5 m and
      0.3 rad/s);
    - odometer: ``axes=(1,)``, ``values=speed``, ``scale_state="odometer_scale"``.

    In a turn the tyres slip: the lateral velocity of the rear axle is about the slip angle
    times the speed, and the slip angle grows with the lateral acceleration ``a_y = w_z v``
    (linear tyre range: ``alpha = k a_y``, ``k = m_axle / C_alpha``; a passenger car has about
    0.5-0.7 deg per m/s^2, Gillespie 1992 ch. 6, Rajamani 2012 ch. 2). With
    ``slip_gradient = k`` the lateral sigma becomes ``sqrt(std^2 + (k |w_z| v^2)^2)`` (``v``
    the forward velocity of the point, ``w_z`` the body yaw rate), so the constraint is not
    over-weighted in sharp turns: 0.45 m/s at 15 m/s and 0.2 rad/s with ``k = 0.01``.

    Parameters
    ----------
    times : array_like
    values : scalar, (N,) or (N, len(axes))
        Measured velocity components [m/s]; a 1-D array holds one value per epoch.
    axes : sequence of int
    std : scalar, sequence per axis, (N,) per epoch or (N, len(axes)) array [m/s]
    lever_arm : 3-vector
        IMU to the constrained point (e.g. rear axle centre, wheel) [m].
    slip_gradient : float
        Tyre slip angle per lateral acceleration ``k`` [rad / (m/s^2)] for the turn-rate-aware
        lateral sigma (above; 0: constant sigma).
    scale_state : str, optional
        Name of a scale-factor state (appended) applied to ``scale_axis``.
    scale_axis : int
    scale_std, scale_psd : float
        Initial sigma and random-walk PSD of the scale-factor state.
    misalignment_state : str, optional
        Name of a 3-element IMU-to-vehicle misalignment state (random constant).
    misalignment_std : float
        Initial sigma of the misalignment [rad].
    misalignment_initial : 3-vector
        Initial nominal value of the misalignment [rad] (default 0: the declared mounting), e.g.
        a smoothed estimate of an earlier pass over the same data (``[filter]
        smoother_passes``).
    pitch_compliance_state : str, optional
        Name of a 1-element suspension pitch-compliance state ``kappa`` [rad / (m/s^2)]
        (random constant, zero initial value; needs the vertical axis 2 and the Python update
        path, not ``high_rate``).
    pitch_compliance_std : float
        Initial sigma of ``kappa`` [rad / (m/s^2)].
    high_rate : bool
        Apply it on the engine's compiled high-rate path (at the IMU sample nearest each time).
    violation_state : str, optional
        Name of a block of first-order Gauss-Markov states ``s`` (one per constrained axis)
        added to the predicted components, ``h_k += s_k``: the time-correlated part of the
        constraint's violation (side slip, suspension heave) as a shaping filter (Bryson and
        Henrikson 1968), so that ``std`` is only its white part. Python update path only.
    violation_std : scalar or sequence per axis
        Stationary sigma of ``s`` [m/s].
    violation_tau : float
        Correlation time of ``s`` [s].
    """

    name = "body_velocity"

    def __init__(self, times, values=0.0, axes: Sequence[int] = (0, 2), std=0.1,
                 lever_arm=(0.0, 0.0, 0.0), scale_state: str | None = None, scale_axis: int = 1,
                 scale_std: float = 0.01, scale_psd: float = 0.0,
                 misalignment_state: str | None = None, misalignment_std: float = 0.02,
                 misalignment_initial=(0.0, 0.0, 0.0),
                 pitch_compliance_state: str | None = None,
                 pitch_compliance_std: float = PITCH_COMPLIANCE_STD,
                 gate_probability: float | None = None, name: str | None = None,
                 high_rate: bool = False, slip_gradient: float = 0.0,
                 violation_state: str | None = None, violation_std=0.1,
                 violation_tau: float = 1.0):
        super().__init__(times, gate_probability, name)
        self.high_rate = bool(high_rate)
        self.slip_gradient = float(slip_gradient)
        if not (np.isfinite(self.slip_gradient) and self.slip_gradient >= 0.0):
            raise InvalidValueError("BodyVelocity: slip_gradient must be finite and >= 0",
                                    found=slip_gradient)
        n = self.times.size
        self.axes = np.asarray(axes, int).reshape(-1)
        k = self.axes.size
        if k == 0 or np.any((self.axes < 0) | (self.axes > 2)):
            raise ValueError("axes must be a non-empty subset of (0, 1, 2)")
        if pitch_compliance_state and (2 not in self.axes or high_rate):
            raise ValueError("a pitch-compliance state needs the vertical axis 2 and the Python "
                             "update path (high_rate=False)")
        self.pitch_compliance_state = pitch_compliance_state
        self.pitch_compliance_std = float(pitch_compliance_std)
        if violation_state and high_rate:
            raise ValueError("violation states need the Python update path (high_rate=False)")
        self.violation_state = violation_state
        self.violation_std = np.broadcast_to(np.asarray(violation_std, float),
                                             (k,)).copy()
        self.violation_tau = float(violation_tau)
        if violation_state and not (np.all(np.isfinite(self.violation_std))
                                    and np.all(self.violation_std > 0)
                                    and np.isfinite(self.violation_tau)
                                    and self.violation_tau > 0):
            raise InvalidValueError("BodyVelocity: violation_std and violation_tau must be "
                                    "finite and > 0", found=(violation_std, violation_tau))
        v = np.asarray(values, float)
        if v.ndim == 1 and v.size == n:  # one value per epoch
            v = v[:, None]
        self.values = np.broadcast_to(v, (n, k)).copy()
        s = np.asarray(std, float)
        if s.ndim == 1 and s.size == n and s.size != k:  # one sigma per epoch
            s = s[:, None]
        self.std = np.broadcast_to(s, (n, k)).copy()
        self.lever_arm = _vec3(lever_arm, "lever_arm")
        self.scale_state = scale_state
        self.scale_axis = int(scale_axis)
        self.scale_std = float(scale_std)
        self.scale_psd = float(scale_psd)
        self.misalignment_state = misalignment_state
        self.misalignment_std = float(misalignment_std)
        self.misalignment_initial = _vec3(misalignment_initial, "misalignment_initial")

    def extra_states(self):
        out = []
        if self.scale_state:
            out.append(ExtraState(self.scale_state, 1, self.scale_std, np.inf, self.scale_psd))
        if self.misalignment_state:
            out.append(ExtraState(self.misalignment_state, 3, self.misalignment_std,
                                  initial_value=tuple(float(x)
                                                      for x in self.misalignment_initial),
                                  labels=(f"{self.misalignment_state}_x",
                                          f"{self.misalignment_state}_y",
                                          f"{self.misalignment_state}_z")))
        if self.pitch_compliance_state:
            out.append(ExtraState(self.pitch_compliance_state, 1, self.pitch_compliance_std,
                                  np.inf, 0.0))
        if self.violation_state:
            sd = tuple(float(x) for x in self.violation_std)
            out.append(ExtraState(self.violation_state, self.axes.size, sd, self.violation_tau,
                                  tuple(2.0 * x * x / self.violation_tau for x in sd),
                                  labels=tuple(f"{self.violation_state}_{'xyz'[a]}"
                                               for a in self.axes)))
        return out

    def compiled(self, layout):
        spec = getattr(self, "_spec", None)
        if spec is not None and spec[0] is layout:
            return spec[1]
        # columns of the violation and pitch-compliance states (-1: none) for constraint_terms
        self._terms = (layout.index(self.violation_state) if self.violation_state else -1,
                       layout.index(self.pitch_compliance_state)
                       if self.pitch_compliance_state else -1)
        ip = np.full(8, -1, np.int64)
        ip[0] = self.axes.size
        ip[1:1 + self.axes.size] = self.axes
        ip[4] = layout.index(self.scale_state) if self.scale_state else -1
        ip[5] = self.scale_axis
        ip[6] = layout.index(self.misalignment_state) if self.misalignment_state else -1
        fp = np.zeros(8)
        fp[0:3] = self.lever_arm
        fp[3] = self.slip_gradient
        spec = CompiledSpec(BODY_VELOCITY, ip, fp, _pad3(self.values), _pad3(self.std))
        self._spec = (layout, spec)
        return spec

    def evaluate(self, i, nav):
        out = _run_compiled(self.compiled(nav.layout), i, nav, nav.omega_ib, 0.0)
        if out is None or not (self.pitch_compliance_state or self.violation_state):
            return out
        z, H, R = out
        iv, ik = self._terms
        constraint_terms(z, H, nav.params, self.axes, iv, ik, nav.C, nav.vel, nav.f_ib_mean,
                         nav.lat, nav.height)
        return z, H, R


@entry
@njit(cache=True)
def constraint_terms(z, H, params, axes, iv, ik, C, vel, f_ib_mean, lat, height):
    """The state terms of :class:`BodyVelocity` beyond the compiled body velocity, added to
    its ``z`` and ``H`` in place (``params``: the nominal parameter states, column 9 on):

    - violation states ``s`` (column ``iv``, one per constrained axis): ``h_k += s_k``;
    - suspension pitch compliance ``kappa`` (column ``ik``), on the vertical axis:
      ``h += kappa a_f v_f`` with the forward acceleration ``a_f = f_f - g C[2, 1]`` (normal
      gravity, Somigliana) and the forward body velocity ``v_f = C[:, 1] . v``; its Jacobian
      ``kappa a_f C[:, 1]`` in ``dv``, ``kappa (a_f C[:, 1] x v - v_f g (C[1, 1], -C[0, 1],
      0))`` in ``phi``, ``-kappa v_f`` in the forward accelerometer bias, ``a_f v_f`` in
      ``kappa`` (nominal minus true: ``C_nom = (I + [phi x]) C``, ``f_nom = f - db_a``).
    """
    if iv >= 0:
        for r in range(axes.shape[0]):
            z[r] += params[iv - 9 + r]
            H[r, iv + r] += 1.0
    if ik < 0:
        return
    kappa = params[ik - 9]
    g = normal_gravity_sc(np.sin(lat), np.cos(lat), height, GRAVITY_SOMIGLIANA)
    c1 = np.empty(3)
    for q in range(3):
        c1[q] = C[q, 1]
    a_f = f_ib_mean[1] - g * c1[2]
    v_f = c1[0] * vel[0] + c1[1] * vel[1] + c1[2] * vel[2]
    r = 0
    while axes[r] != 2:
        r += 1
    z[r] += kappa * a_f * v_f
    cx = _cross3(c1, vel)
    for q in range(3):
        H[r, 3 + q] += kappa * a_f * c1[q]
    H[r, 6] += kappa * (a_f * cx[0] - v_f * g * c1[1])
    H[r, 7] += kappa * (a_f * cx[1] + v_f * g * c1[0])
    H[r, 8] += kappa * (a_f * cx[2])
    H[r, 13] -= kappa * v_f
    H[r, ik] = a_f * v_f
