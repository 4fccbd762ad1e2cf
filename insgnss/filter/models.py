"""Error-state model of the LLF (ENU) strapdown INS: state layout, continuous dynamics F, noise.

Error definition (all "nominal minus true", the convention of the measurement models too)
-----------------------------------------------------------------------------------------
- ``dr`` (3): position error in ENU metres at the nominal point:
  ``dr_e = (N + h) cos(lat) (lon_nom - lon)``, ``dr_n = (M + h) (lat_nom - lat)``,
  ``dr_u = h_nom - h``;
- ``dv`` (3): ENU velocity error ``v_nom - v``;
- ``phi`` (3): attitude misalignment in the l-frame, phi-angle (psi-angle in Groves' LLF
  notation) form ``C_nom = (I + [phi x]) C_true`` i.e. ``C_true = (I - [phi x]) C_nom``.
  It is exactly :func:`insgnss.attitude.attitude_error` (``C_est = exp([phi x]) C_true``);
- ``bg``, ``ba`` (3 + 3): errors of the gyro / accelerometer bias estimates
  (estimate minus true);
- optional ``sg``, ``sa`` (3 + 3): errors of the scale-factor estimates;
- optional extra states appended by measurement models (odometer scale factor, IMU-to-vehicle
  misalignment, ...), see :class:`ExtraState`.

Feedback (closed loop) therefore *subtracts* the estimated error from the nominal state.

Continuous error dynamics (Groves 2013 eqs. 14.64, 14.69, 14.71 rewritten for ENU and
``nominal - true`` errors; Noureldin et al. 2013 eqs. 10.17-10.35)::

    d(dr)/dt  = F_rr dr + dv
    d(dv)/dt  = F_vr dr + F_vv dv - [f^l x] phi - C ba - C diag(f^b) sa + C w_a
    d(phi)/dt = F_pr dr + F_pv dv - [w_il^l x] phi - C bg - C diag(w_ib^b) sg + C w_g
    d(b)/dt   = -b / tau + w_b         (first-order Gauss-Markov; tau = inf: random walk)

with ``F_vv = -[(2 w_ie + w_el) x] + [v x] dW_el/dv``, ``F_vr = [v x] (2 dW_ie/dr + dW_el/dr)``
plus the gravity gradient ``-dg/dh`` (about ``+2 g / R``: the unstable vertical channel) and
``-dg/dlat / (M + h)`` in ``F[vu, rn]``,
``F_pr = -(dW_ie/dr + dW_el/dr)``, ``F_pv = -dW_el/dv`` and the small terms of the
radii in ``F_rr``; ``dW/dr`` include the latitude derivatives of ``M`` and ``N``. Every entry
matches a numerical Jacobian of the exact equations (tests/test_linearization.py). ``w_g``,
``w_a`` are the gyro / accelerometer white noises (ARW and VRW densities), ``w_b`` the driving
noise of the bias processes.

For short pedestrian runs, :func:`accumulate_short_term_dynamics` is the same model without the
Earth-rate, transport-rate and gravity-gradient couplings (``FilterConfig.error_dynamics =
"short_term"``).

The compiled :func:`accumulate_error_dynamics` adds ``F dt`` for one IMU interval; the
propagation kernel integrates it over a covariance interval, so ``Phi = exp(int F dt)``
uses the interval-averaged F (first Magnus term). :func:`error_dynamics` is its Python
wrapper returning F itself (used by tests and for inspection).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..earth import E2, OMEGA_E, gravity_gradient_somigliana, radii
from ..imu import ImuErrorModel, grade
from ..jit import njit

#: indices of the core blocks
POS = slice(0, 3)
VEL = slice(3, 6)
ATT = slice(6, 9)
GYRO_BIAS = slice(9, 12)
ACCEL_BIAS = slice(12, 15)

BIAS_MODELS = ("gauss_markov", "random_walk", "random_constant")
#: error-dynamics models (``FilterConfig.error_dynamics``) and their compiled ids
ERROR_DYNAMICS = {"full": 0, "short_term": 1}


@dataclass(frozen=True)
class ExtraState:
    """A state appended to the core error state by a measurement model.

    Parameters
    ----------
    name : str
        Block name (unique), e.g. ``"odometer_scale"``.
    size : int
        Number of elements.
    initial_std : float or sequence
        Initial 1-sigma of the error.
    tau : float
        Gauss-Markov correlation time [s]; ``inf`` for a random walk / random constant.
    psd : float or sequence
        Power spectral density of the driving white noise [unit^2/s] (0: random constant).
    initial_value : float or sequence
        Initial nominal value of the parameter (e.g. 0 for a scale-factor correction).
    labels : sequence of str, optional
        Output column names of the elements (default ``name`` or ``name_0, name_1, ...``).
    dynamics : (size, size) nested sequence, optional
        Constant continuous-time dynamics matrix of the block (added to ``-1 / tau`` on the
        diagonal), for coupled states. A GNSS receiver clock (bias [m], drift [m/s]) is
        ``dynamics=((0, 1), (0, 0))``, which the discretisation turns into
        ``Phi = [[1, dt], [0, 1]]``.
    noise : (size, size) nested sequence, optional
        Driving-noise PSD matrix of the block (replaces ``psd``); the clock's
        ``diag(q_bias, q_drift)`` gives ``Qd = [[q_b dt + q_d dt^3 / 3, q_d dt^2 / 2],
        [q_d dt^2 / 2, q_d dt]]``.
    """

    name: str
    size: int = 1
    initial_std: float | tuple = 0.0
    tau: float = np.inf
    psd: float | tuple = 0.0
    initial_value: float | tuple = 0.0
    labels: tuple | None = None
    dynamics: tuple | None = None
    noise: tuple | None = None

    def __post_init__(self):
        for key in ("dynamics", "noise"):
            v = getattr(self, key)
            if v is not None:
                a = np.asarray(v, float)
                if a.shape != (self.size, self.size) or not np.all(np.isfinite(a)):
                    raise ValueError(f"extra state {self.name!r}: {key} must be a finite "
                                     f"{self.size} x {self.size} matrix")
                object.__setattr__(self, key, tuple(map(tuple, a.tolist())))

    def element_labels(self) -> list[str]:
        if self.labels is not None:
            if len(self.labels) != self.size:
                raise ValueError(f"extra state {self.name!r}: {self.size} labels expected")
            return list(self.labels)
        if self.size == 1:
            return [self.name]
        return [f"{self.name}_{i}" for i in range(self.size)]


class NamedBlocks:
    """Access to the named slices ``_slices`` of an error-state vector (shared by the strapdown
    and RISS layouts)."""

    _slices: dict[str, slice]
    n: int

    def __getitem__(self, name: str) -> slice:
        try:
            return self._slices[name]
        except KeyError:
            raise KeyError(f"no state block {name!r}; layout has {list(self._slices)}") from None

    def __contains__(self, name: str) -> bool:
        return name in self._slices

    def index(self, name: str) -> int:
        """First index of a block, -1 if absent."""
        s = self._slices.get(name)
        return -1 if s is None else s.start

    @property
    def blocks(self) -> list[str]:
        return list(self._slices)

    def __repr__(self) -> str:
        parts = ", ".join(f"{k}[{s.start}:{s.stop}]" for k, s in self._slices.items())
        return f"{type(self).__name__}(n={self.n}: {parts})"


class StateLayout(NamedBlocks):
    """Named blocks of the error-state vector.

    Core blocks ``pos vel att gyro_bias accel_bias`` (15), optionally
    ``gyro_scale accel_scale`` (21), then extra states in the order given.
    ``layout["vel"]`` is the slice of a block; measurement models build H by name::

        H = np.zeros((3, layout.n)); H[:, layout["vel"]] = np.eye(3)
    """

    CORE = (("pos", 3), ("vel", 3), ("att", 3), ("gyro_bias", 3), ("accel_bias", 3))
    SCALE = (("gyro_scale", 3), ("accel_scale", 3))
    #: output column names of the core parameter states (index 9 onwards)
    CORE_LABELS = {
        "pos": ["east", "north", "up"],
        "vel": ["vel_e", "vel_n", "vel_u"],
        "att": ["phi_e", "phi_n", "phi_u"],
        "gyro_bias": ["gyro_bias_x", "gyro_bias_y", "gyro_bias_z"],
        "accel_bias": ["accel_bias_x", "accel_bias_y", "accel_bias_z"],
        "gyro_scale": ["gyro_scale_x", "gyro_scale_y", "gyro_scale_z"],
        "accel_scale": ["accel_scale_x", "accel_scale_y", "accel_scale_z"],
    }

    def __init__(self, scale_factors: bool = False, extras: tuple | list = ()):
        blocks = list(self.CORE) + (list(self.SCALE) if scale_factors else [])
        self.scale_factors = bool(scale_factors)
        self.extras: list[ExtraState] = []
        self._slices: dict[str, slice] = {}
        self.labels: list[str] = []
        i = 0
        for name, size in blocks:
            self._slices[name] = slice(i, i + size)
            self.labels += self.CORE_LABELS[name]
            i += size
        for ex in extras:
            if ex.name in self._slices:
                if self._extra(ex.name) != ex:
                    raise ValueError(f"extra state {ex.name!r} declared twice with different parameters")
                continue
            self._slices[ex.name] = slice(i, i + ex.size)
            self.labels += ex.element_labels()
            self.extras.append(ex)
            i += ex.size
        self.n = i

    def _extra(self, name):
        for ex in self.extras:
            if ex.name == name:
                return ex
        return None


@dataclass
class ProcessModel:
    """Everything the kernels need about the error-state process besides the nominal state.

    Attributes
    ----------
    gyro_psd, accel_psd : (3,) arrays
        White-noise PSDs of the gyro [rad^2/s] and accelerometer [m^2/s^3] (ARW^2, VRW^2).
    decay : (n,) array
        ``1 / tau`` on the diagonal of F for the parameter states (0 elsewhere).
    qdiag : (n,) array
        Driving-noise PSDs of the parameter states (0 for the navigation states).
    p0 : (n,) array
        Initial standard deviations.
    initial_values : (n - 9,) array
        Initial nominal values of the parameter states (index 9 onwards).
    Fx, Qx : (n, n) arrays or None
        Constant dynamics and noise PSD of coupled augmenting states
        (:attr:`ExtraState.dynamics`, :attr:`ExtraState.noise`); None when there are none.
    dyn_noise : (2,) array
        Dynamics-dependent noise factors ``(k_a, k_g)`` [sqrt(s)] of
        :func:`insgnss.filter.kernels.interval_step` (0: none).
    """

    layout: StateLayout
    gyro_psd: np.ndarray
    accel_psd: np.ndarray
    decay: np.ndarray
    qdiag: np.ndarray
    p0: np.ndarray
    initial_values: np.ndarray
    Fx: np.ndarray | None = None
    Qx: np.ndarray | None = None
    dyn_noise: np.ndarray = field(default_factory=lambda: np.zeros(2))


def _bias_process(sigma_turn_on, sigma_instability, tau, rrw, model):
    """(initial std, decay, psd) of one bias triad under the chosen model."""
    p0 = float(np.hypot(sigma_turn_on, sigma_instability))
    if model == "gauss_markov":
        if sigma_instability > 0 and np.isfinite(tau) and tau > 0:
            return p0, 1.0 / tau, 2.0 * sigma_instability**2 / tau
        return p0, 0.0, rrw**2
    if model == "random_walk":
        if rrw > 0:
            return p0, 0.0, rrw**2
        if sigma_instability > 0 and np.isfinite(tau) and tau > 0:
            return p0, 0.0, 2.0 * sigma_instability**2 / tau
        return p0, 0.0, 0.0
    if model == "random_constant":
        return p0, 0.0, 0.0
    raise ValueError(f"unknown bias model {model!r}; expected one of {BIAS_MODELS}")


def _triad(x) -> np.ndarray:
    a = np.asarray(x, float)
    return np.full(3, float(a)) if a.ndim == 0 else a.reshape(3)


def process_model(
    layout: StateLayout,
    imu_model: ImuErrorModel | str,
    bias_model: str = "random_walk",
    initial_pos_std=1.0,
    initial_vel_std=0.1,
    initial_att_std=(0.01, 0.01, 0.05),
    initial_gyro_bias_std=None,
    initial_accel_bias_std=None,
    initial_gyro_scale_std=None,
    initial_accel_scale_std=None,
    gyro_bias=None,
    accel_bias=None,
) -> ProcessModel:
    """Build the process model from an IMU error model (grade preset, datasheet or Allan).

    - ARW / VRW become the white-noise PSDs ``arw^2``, ``vrw^2``;
    - ``gauss_markov``: bias instability ``sigma`` with correlation time ``tau`` becomes a
      first-order Gauss-Markov process with driving PSD ``2 sigma^2 / tau``;
      ``random_walk``: the rate random walk (or, if zero, the same ``2 sigma^2 / tau``
      without the decay, the short-time equivalent of the GM process);
      ``random_constant``: no driving noise;
    - the initial bias std is ``hypot(turn-on bias, instability)`` unless given;
    - scale factors (if in the layout) are random constants with the model's scale-factor std.

    ``initial_att_std`` is the std of the misalignment (east, north, up) [rad]; the up
    component is the heading uncertainty.
    """
    if isinstance(imu_model, str):
        imu_model = grade(imu_model)
    n = layout.n
    decay = np.zeros(n)
    qdiag = np.zeros(n)
    p0 = np.zeros(n)
    p0[POS] = _triad(initial_pos_std)
    p0[VEL] = _triad(initial_vel_std)
    p0[ATT] = _triad(initial_att_std)
    s, d, q = _bias_process(imu_model.gyro_bias, imu_model.gyro_bias_instability,
                            imu_model.bias_correlation_time, imu_model.gyro_rrw, bias_model)
    p0[GYRO_BIAS] = s if initial_gyro_bias_std is None else _triad(initial_gyro_bias_std)
    decay[GYRO_BIAS] = d
    qdiag[GYRO_BIAS] = q
    s, d, q = _bias_process(imu_model.accel_bias, imu_model.accel_bias_instability,
                            imu_model.bias_correlation_time, imu_model.accel_rrw, bias_model)
    p0[ACCEL_BIAS] = s if initial_accel_bias_std is None else _triad(initial_accel_bias_std)
    decay[ACCEL_BIAS] = d
    qdiag[ACCEL_BIAS] = q
    init = np.zeros(n - 9)
    if gyro_bias is not None:
        init[0:3] = _triad(gyro_bias)
    if accel_bias is not None:
        init[3:6] = _triad(accel_bias)
    if layout.scale_factors:
        sg = imu_model.gyro_scale if initial_gyro_scale_std is None else initial_gyro_scale_std
        sa = imu_model.accel_scale if initial_accel_scale_std is None else initial_accel_scale_std
        p0[layout["gyro_scale"]] = _triad(sg)
        p0[layout["accel_scale"]] = _triad(sa)
    Fx = Qx = None
    for ex in layout.extras:
        sl = layout[ex.name]
        p0[sl] = np.broadcast_to(np.asarray(ex.initial_std, float), (ex.size,))
        decay[sl] = 0.0 if not np.isfinite(ex.tau) else 1.0 / ex.tau
        if ex.noise is None:
            qdiag[sl] = np.broadcast_to(np.asarray(ex.psd, float), (ex.size,))
        else:
            Qx = np.zeros((n, n)) if Qx is None else Qx
            Qx[sl, sl] = np.asarray(ex.noise, float)
        if ex.dynamics is not None:
            Fx = np.zeros((n, n)) if Fx is None else Fx
            Fx[sl, sl] = np.asarray(ex.dynamics, float)
        init[sl.start - 9:sl.stop - 9] = np.broadcast_to(np.asarray(ex.initial_value, float),
                                                         (ex.size,))
    if np.any(p0 < 0) or not np.all(np.isfinite(p0)):
        raise ValueError("initial standard deviations must be finite and non-negative")
    return ProcessModel(layout, _triad(imu_model.gyro_arw) ** 2, _triad(imu_model.accel_vrw) ** 2,
                        decay, qdiag, p0, init, Fx, Qx)


# --- compiled dynamics -----------------------------------------------------------------------
@njit(cache=True)
def _sensor_error_terms(F, dt, C, dth_b, dv_b, i_sg, i_sa):
    """The sensor-error terms of F dt shared by both error models: ``-[f^l x] phi``,
    ``-C ba``, ``-C diag(f^b) sa`` (velocity rows) and ``-C bg``, ``-C diag(w_ib^b) sg``
    (attitude rows), with ``f^l dt = C dv_b`` and ``w dt = dth_b``."""
    # -[f^l x] phi with f^l dt = C dv_b
    fe = C[0, 0] * dv_b[0] + C[0, 1] * dv_b[1] + C[0, 2] * dv_b[2]
    fn = C[1, 0] * dv_b[0] + C[1, 1] * dv_b[1] + C[1, 2] * dv_b[2]
    fu = C[2, 0] * dv_b[0] + C[2, 1] * dv_b[1] + C[2, 2] * dv_b[2]
    F[3, 7] += fu
    F[3, 8] += -fn
    F[4, 6] += -fu
    F[4, 8] += fe
    F[5, 6] += fn
    F[5, 7] += -fe
    # -C ba, -C diag(f^b) sa
    for i in range(3):
        for k in range(3):
            F[3 + i, 12 + k] -= C[i, k] * dt
            F[6 + i, 9 + k] -= C[i, k] * dt
    if i_sa >= 0:
        for i in range(3):
            for k in range(3):
                F[3 + i, i_sa + k] -= C[i, k] * dv_b[k]
    if i_sg >= 0:
        for i in range(3):
            for k in range(3):
                F[6 + i, i_sg + k] -= C[i, k] * dth_b[k]


@njit(cache=True)
def accumulate_short_term_dynamics(F, dt, C, dth_b, dv_b, i_sg, i_sa):
    """Add ``F dt`` of the short-term (pedestrian) error model for one IMU interval: the
    dynamics of :func:`accumulate_error_dynamics` without the Earth-rate, transport-rate and
    gravity-gradient couplings (Groves 2013 eq. 14.63 with those terms dropped)::

        d(dr)/dt = dv,  d(dv)/dt = -[f^l x] phi - C ba (- C diag(f^b) sa),
        d(phi)/dt = -C bg (- C diag(w_ib^b) sg)

    Over a walk of minutes at walking speed the dropped terms are below 1e-4 of the retained
    ones (``w_ie ~ 7e-5 rad/s``, ``v / R ~ 2e-7 rad/s``, ``2 g / R ~ 3e-6 1/s^2``); F has about 30
    instead of 65 non-zero entries, which halves the covariance propagation at every IMU sample
    of a foot-mounted INS."""
    F[0, 3] += dt
    F[1, 4] += dt
    F[2, 5] += dt
    _sensor_error_terms(F, dt, C, dth_b, dv_b, i_sg, i_sa)


@njit(cache=True)
def accumulate_error_dynamics(F, dt, lat, h, vel, C, dth_b, dv_b, i_sg, i_sa):
    """Add ``F dt`` of the navigation part of the error dynamics for one IMU interval.

    Parameters
    ----------
    F : (n, n) array, modified in place
    dt : float
        Interval [s].
    lat, h, vel, C
        Nominal latitude [rad], height [m], ENU velocity and ``C_b^l`` at the interval start.
    dth_b, dv_b : (3,) arrays
        Compensated angular and velocity increments of the interval (body frame); they give
        ``int w_ib dt`` and ``int f^b dt``.
    i_sg, i_sa : int
        First index of the gyro / accelerometer scale-factor blocks, -1 if absent.

    Bias decay terms (``-1/tau``) are constant and added by the discretisation.
    """
    M, N = radii(lat)
    Rm = M + h
    Rn = N + h
    ve, vn, vu = vel[0], vel[1], vel[2]
    sl = np.sin(lat)
    cl = np.cos(lat)
    tl = sl / cl
    # radius derivatives dN/dlat = N e^2 s c / w, dM/dlat = 3 M e^2 s c / w (w = 1 - e^2 s^2)
    q = E2 * sl * cl / (1.0 - E2 * sl * sl)
    dN = N * q
    dM = 3.0 * M * q
    # --- d(omega_ie + omega_el)/d(dr), d(omega_el)/d(dv)
    # dW_ie/dr: only the north column
    wie_rn1 = -OMEGA_E * sl / Rm
    wie_rn2 = OMEGA_E * cl / Rm
    # dW_el/dr (columns n = 1, u = 2); d(dr_n) = (M + h) d(lat) moves M and N too
    wel_r01 = vn * dM / (Rm * Rm * Rm)
    wel_r11 = -ve * dN / (Rn * Rn * Rm)
    wel_r21 = ve / (cl * cl * Rn * Rm) - ve * tl * dN / (Rn * Rn * Rm)
    wel_r02 = vn / (Rm * Rm)
    wel_r12 = -ve / (Rn * Rn)
    wel_r22 = -ve * tl / (Rn * Rn)
    # dW_el/dv
    wel_v01 = -1.0 / Rm
    wel_v10 = 1.0 / Rn
    wel_v20 = tl / Rn
    # rates
    wie_n = OMEGA_E * cl
    wie_u = OMEGA_E * sl
    wel_e = -vn / Rm
    wel_n = ve / Rn
    wel_u = ve * tl / Rn
    # --- position rows
    # d(dr_e)/dt = d/dt[(N + h) cos lat] / ((N + h) cos lat) dr_e + (N + h) cos(lat) d(lon rate)
    F[0, 0] += (vu / Rn - vn * tl / Rm + vn * dN / (Rm * Rn)) * dt
    F[0, 1] += (ve * tl / Rm - ve * dN / (Rn * Rm)) * dt
    F[0, 2] += -ve / Rn * dt
    F[0, 3] += dt
    F[1, 1] += vu / Rm * dt
    F[1, 2] += -vn / Rm * dt
    F[1, 4] += dt
    F[2, 5] += dt
    # --- velocity rows
    # F_vv = -[(2 w_ie + w_el) x] + [v x] dW_el/dv
    ce = wel_e
    cn = 2.0 * wie_n + wel_n
    cu = 2.0 * wie_u + wel_u
    # [v x] M for M with columns: (v x m) = [vn m2 - vu m1, vu m0 - ve m2, ve m1 - vn m0]
    # dW_el/dv columns: col0 = (0, wel_v10, wel_v20); col1 = (wel_v01, 0, 0); col2 = 0
    F[3, 3] += (vn * wel_v20 - vu * wel_v10) * dt
    F[3, 4] += cu * dt
    F[3, 5] += -cn * dt
    F[4, 3] += (-cu - ve * wel_v20) * dt
    F[4, 4] += (vu * wel_v01) * dt
    F[4, 5] += ce * dt
    F[5, 3] += (cn + ve * wel_v10) * dt
    F[5, 4] += (-ce - vn * wel_v01) * dt
    # F_vr = [v x] (2 dW_ie/dr + dW_el/dr) + gravity gradient
    # columns of K = 2 dW_ie/dr + dW_el/dr: col1 = (wel_r01, 2 wie_rn1 + wel_r11,
    # 2 wie_rn2 + wel_r21); col2 = (wel_r02, wel_r12, wel_r22)
    k01 = wel_r01
    k11 = 2.0 * wie_rn1 + wel_r11
    k21 = 2.0 * wie_rn2 + wel_r21
    k02 = wel_r02
    k12 = wel_r12
    k22 = wel_r22
    F[3, 1] += (vn * k21 - vu * k11) * dt
    F[4, 1] += (vu * k01 - ve * k21) * dt
    F[5, 1] += (ve * k11 - vn * k01) * dt
    F[3, 2] += (vn * k22 - vu * k12) * dt
    F[4, 2] += (vu * k02 - ve * k22) * dt
    F[5, 2] += (ve * k12 - vn * k02) * dt
    # gravity g^l = (0, 0, -g(lat, h)): -dg/dlat / (M + h) and -dg/dh (the unstable vertical
    # channel, ~ +2 g / R); Somigliana's gradient for every model (they differ by < 1e-3 of it)
    dg_dlat, dg_dh = gravity_gradient_somigliana(sl, cl, h)
    F[5, 1] -= dg_dlat / Rm * dt
    F[5, 2] -= dg_dh * dt
    _sensor_error_terms(F, dt, C, dth_b, dv_b, i_sg, i_sa)
    # --- attitude rows
    # -[w_il x] phi
    we = wel_e
    wn = wie_n + wel_n
    wu = wie_u + wel_u
    F[6, 7] += wu * dt
    F[6, 8] += -wn * dt
    F[7, 6] += -wu * dt
    F[7, 8] += we * dt
    F[8, 6] += wn * dt
    F[8, 7] += -we * dt
    # -(dW_ie/dr + dW_el/dr) dr
    F[6, 1] -= wel_r01 * dt
    F[6, 2] -= wel_r02 * dt
    F[7, 1] -= (wie_rn1 + wel_r11) * dt
    F[7, 2] -= wel_r12 * dt
    F[8, 1] -= (wie_rn2 + wel_r21) * dt
    F[8, 2] -= wel_r22 * dt
    # -dW_el/dv dv
    F[6, 4] -= wel_v01 * dt
    F[7, 3] -= wel_v10 * dt
    F[8, 3] -= wel_v20 * dt


def error_dynamics(nav_lat: float, nav_h: float, vel, C, f_b, w_ib, layout: StateLayout,
                   decay=None) -> np.ndarray:
    """Continuous-time F (n x n) at a nominal state with specific force ``f_b`` and angular
    rate ``w_ib`` (body frame). Python wrapper of :func:`accumulate_error_dynamics`."""
    F = np.zeros((layout.n, layout.n))
    accumulate_error_dynamics(F, 1.0, float(nav_lat), float(nav_h), np.asarray(vel, float),
                              np.ascontiguousarray(C, dtype=float), np.asarray(w_ib, float),
                              np.asarray(f_b, float), layout.index("gyro_scale"),
                              layout.index("accel_scale"))
    if decay is not None:
        F[np.diag_indices(layout.n)] -= np.asarray(decay, float)
    return F


def gravity_gradient(lat: float, h: float) -> float:
    """Vertical gradient magnitude ``-dg/dh`` used in ``F[vu, ru]`` [1/s^2] (Somigliana's,
    about ``2 g / R`` plus 0.3 %)."""
    return -float(gravity_gradient_somigliana(np.sin(lat), np.cos(lat), h)[1])
