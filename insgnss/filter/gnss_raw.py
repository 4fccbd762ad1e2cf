"""Tightly coupled GNSS measurement models: one pseudorange or one Doppler range rate per
satellite and epoch, with the receiver clock states.

Each row of a prepared measurement table (:func:`insgnss.gnss.prepare_observations`: one
satellite at one epoch) is one event of the model, so the engine evaluates, gates and logs
every satellite separately (``times`` repeats the epoch time for the satellites of the
epoch; :meth:`RawGnssMeasurement.row_label` names the satellite of a row).

Models (``z = h(nominal) - measured``, the convention of :mod:`.measurements`; ENU error
states "nominal minus true"; ``l`` the IMU-to-antenna lever arm in the body frame, ``C`` the
nominal ``C_b^l``, ``u`` the unit line of sight antenna -> satellite in ENU, ``rho`` the range)::

    pseudorange   h = |x_s' - r_ant| + b + isb_S - c dt_s + T + I
                  g = -u + (dT/dh) e_up,  H_pos = g^T,  H_att = -g^T [(C l) x],
                  H_b = 1,  H_isb_S = 1
    range rate    h = u . (v_s' - v_ant) + d - c dt_s_dot,    measured -lambda * Doppler
                  v_ant = v + C (w_ib x l) - w_il x (C l)
                  H_vel = -u^T,  H_att = -u^T ([w_il x][(C l) x] - [(C (w_ib x l)) x]),
                  H_bg = -u^T C [l x],  H_d = 1,
                  H_pos = g^T = -(v_s' - v_ant)^T (I - u u^T) / rho,  H_att += -g^T [(C l) x]

(``r_ant = r + C l`` so ``d r_ant = dr - [(C l) x] phi``; the attitude and gyro-bias rows of
the range rate are the ones of :class:`.measurements.GnssVelocity` projected on ``-u``.)
Sigmas: :func:`insgnss.gnss.observations.pseudorange_variance` (elevation, C/N0, URA,
ionosphere and troposphere residuals) and :func:`~insgnss.gnss.observations.range_rate_variance`.

Receiver clock (:class:`ReceiverClock`): bias ``b`` [m] and drift ``d`` [m/s] of the
reference system, ``x_k+1 = Phi x_k + w``, ``Phi = [[1, dt], [0, 1]]`` and, with the
two-state model of the oscillator's Allan-variance coefficients ``h0`` (white frequency) and
``h_-2`` (random-walk frequency), ``S_f = c^2 h0 / 2``, ``S_g = c^2 2 pi^2 h_-2``::

    Qd = [[S_f dt + S_g dt^3 / 3, S_g dt^2 / 2],
          [S_g dt^2 / 2,          S_g dt      ]]

(Brown & Hwang 2012, 9.3, eqs. 9.3.10-9.3.11; Groves 2013 eq. 14.206). Other systems carry
an inter-system bias ``isb_S`` [m] (random walk: hardware delays and the broadcast system
time offsets drift slowly). The engine discretises the clock block from its continuous
dynamics (:class:`.models.ExtraState` ``dynamics``/``noise``), which gives the ``Phi`` and
``Qd`` above exactly.

References
----------
- Groves, *Principles of GNSS, Inertial, and Multisensor Integrated Navigation Systems*,
  2nd ed., 2013, 14.3.3 (tightly coupled measurement model), 9.4.2.
- Brown, R. G., Hwang, P. Y. C., *Introduction to Random Signals and Applied Kalman
  Filtering*, 4th ed., 2012, 9.3 (receiver clock model), Table 9.1 (h0, h-2 of oscillators).
- Noureldin et al. 2013, 11.4 (tightly coupled INS/GPS).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..earth import OMEGA_E, ecef_to_enu_matrix, geodetic_to_ecef
from ..errors import InputFormatError
from ..gnss.constants import C_LIGHT
from ..gnss.corrections import day_of_year
from ..gnss.observations import (
    PREPARED_COLUMNS,
    GnssModelConfig,
    epoch_arrays,
    epoch_model,
    klobuchar_parameters,
)
from .measurements import Measurement, NominalState, cross3, skew
from .models import ExtraState


@dataclass(frozen=True)
class ReceiverClock:
    """Receiver clock bias/drift states and their process model.

    Parameters
    ----------
    h0, h_m2 : float
        Allan-variance coefficients of the oscillator: white frequency [s] and random-walk
        frequency [1/s]. Default: a temperature-compensated crystal (TCXO), h0 = 2e-19 s,
        h_-2 = 2e-20 1/s (Brown & Hwang Table 9.1), the oscillator of u-blox receivers.
    initial_bias, initial_drift : float
        Initial nominal bias [m] and drift [m/s] (e.g. from :func:`insgnss.gnss.spp`).
    bias_std, drift_std : float
        Their initial sigmas [m, m/s].
    """

    h0: float = 2e-19
    h_m2: float = 2e-20
    initial_bias: float = 0.0
    initial_drift: float = 0.0
    bias_std: float = 10.0
    drift_std: float = 0.5

    name = "clock"

    @property
    def psd(self) -> tuple[float, float]:
        """``(S_f, S_g)``: PSDs of the bias [m^2/s] and drift [m^2/s^3] driving noises."""
        return C_LIGHT**2 * self.h0 / 2.0, C_LIGHT**2 * 2.0 * np.pi**2 * self.h_m2

    def transition(self, dt: float) -> np.ndarray:
        """State transition ``Phi = [[1, dt], [0, 1]]`` of ``(bias, drift)``."""
        return np.array([[1.0, dt], [0.0, 1.0]])

    def process_noise(self, dt: float) -> np.ndarray:
        """Discrete process noise ``Qd(dt)`` of ``(bias, drift)`` (module docstring)."""
        sf, sg = self.psd
        return np.array([[sf * dt + sg * dt**3 / 3.0, sg * dt**2 / 2.0],
                         [sg * dt**2 / 2.0, sg * dt]])

    def extra_state(self) -> ExtraState:
        """The state block ``clock`` = (``clock_bias`` [m], ``clock_drift`` [m/s]): dynamics
        ``[[0, 1], [0, 0]]`` and driving noise ``diag(S_f, S_g)``, which the engine discretises
        into :meth:`transition` and :meth:`process_noise` (exact for this block); the nominal
        bias follows ``b += d dt`` between updates."""
        sf, sg = self.psd
        return ExtraState(self.name, 2, (self.bias_std, self.drift_std), np.inf, self.psd,
                          (self.initial_bias, self.initial_drift), ("clock_bias", "clock_drift"),
                          dynamics=((0.0, 1.0), (0.0, 0.0)), noise=((sf, 0.0), (0.0, sg)))

    @classmethod
    def from_spp(cls, solution: pd.DataFrame, t0: float, reference: str = "G", **kw
                 ) -> ReceiverClock:
        """Initial bias and drift at ``t0`` from the SPP epoch nearest to it
        (:func:`insgnss.gnss.spp`), the bias carried to ``t0`` by the drift (a typical TCXO
        drifts tens of m/s: the epoch one second away would be that far off)."""
        if solution.empty:
            raise InputFormatError("no SPP epoch to initialise the receiver clock")
        ts = np.asarray(solution.index, float)
        k = int(np.argmin(np.abs(ts - t0)))
        row = solution.iloc[k]
        drift = float(row.get("clock_drift", 0.0))
        drift = drift if np.isfinite(drift) else 0.0
        return cls(initial_bias=float(row[f"clock_bias_{reference}"]) + drift * (t0 - ts[k]),
                   initial_drift=drift, **kw)


def inter_system_bias_state(system: str, initial_value: float = 0.0, std: float = 10.0,
                            psd: float = 1e-4) -> ExtraState:
    """Inter-system bias ``isb_<S>`` [m] of system ``S`` relative to the reference system:
    random walk (``psd`` [m^2/s]; default 1 cm/sqrt(s))."""
    return ExtraState(f"isb_{system}", 1, std, np.inf, psd, initial_value)


def antenna_velocity(nav: NominalState, lever_arm) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Antenna velocity (ENU) ``v + C (w_ib x l) - w_il x (C l)`` and its Jacobians with
    respect to the attitude error and the gyro-bias error (the model of
    :class:`.measurements.GnssVelocity`)."""
    l = lever_arm
    u = nav.C @ cross3(nav.omega_ib, l)
    cl = nav.C @ l
    w_il = np.array([
        -nav.vel[1] / (nav.M + nav.height),
        OMEGA_E * np.cos(nav.lat) + nav.vel[0] / (nav.N + nav.height),
        OMEGA_E * np.sin(nav.lat) + nav.vel[0] * np.tan(nav.lat) / (nav.N + nav.height),
    ])
    v_ant = nav.vel + u - cross3(w_il, cl)
    J_att = skew(w_il) @ skew(cl) - skew(u)
    J_bg = nav.C @ skew(l)
    return v_ant, J_att, J_bg


class RawGnssMeasurement(Measurement):
    """Common part of :class:`Pseudorange` and :class:`Doppler`.

    Parameters
    ----------
    prepared : DataFrame
        Prepared measurement table (:func:`insgnss.gnss.prepare_observations`), index time in
        the IMU's time base.
    ionosphere : DataFrame, optional
        Broadcast ionosphere parameters (:func:`insgnss.gnss.decode_subframes`).
    lever_arm : 3-vector
        IMU to antenna in the body frame (right-forward-up) [m].
    config : GnssModelConfig
        Masks and noise model (the prepared table's signal choice and C/N0 mask are already
        applied; the elevation mask is applied here).
    clock : ReceiverClock
    reference_system : str, optional
        System whose clock is ``clock_bias`` (default: GPS if present, else the first).
    isb_std, isb_psd : float
        Initial sigma [m] and random-walk PSD [m^2/s] of the inter-system biases.
    isb_initial : dict, optional
        Initial nominal inter-system biases ``{system: value [m]}``.
    """

    name = "gnss_raw"
    recoverable = True  # absolute ranges re-anchor the state (gating.py)

    def __init__(self, prepared: pd.DataFrame, ionosphere: pd.DataFrame | None = None,
                 lever_arm=(0.0, 0.0, 0.0), config: GnssModelConfig | None = None,
                 clock: ReceiverClock | None = None, reference_system: str | None = None,
                 isb_std: float = 10.0, isb_psd: float = 1e-4, isb_initial: dict | None = None,
                 gate_probability: float | None = None, name: str | None = None):
        missing = [c for c in PREPARED_COLUMNS if c not in prepared.columns]
        if missing:
            raise InputFormatError("prepared GNSS table lacks columns", column=missing[0],
                                   expected=PREPARED_COLUMNS, found=list(prepared.columns))
        super().__init__(np.asarray(prepared.index, float), gate_probability, name)
        self.config = config or GnssModelConfig()
        self.clock = clock or ReceiverClock()
        self.starts, self.arrays = epoch_arrays(prepared)
        self.epoch_of_row = np.repeat(np.arange(self.starts.size - 1), np.diff(self.starts))
        systems = list(pd.unique(prepared["system"]))
        if reference_system is None:
            reference_system = "G" if "G" in systems or not systems else systems[0]
        self.reference_system = reference_system
        self.other_systems = [s for s in systems if s != reference_system]
        self.isb_std, self.isb_psd = float(isb_std), float(isb_psd)
        self.isb_initial = dict(isb_initial or {})
        self.iono_params = klobuchar_parameters(ionosphere)
        self.lever_arm = np.asarray(lever_arm, float).reshape(3)
        self.doy = day_of_year(self.times[0]) if self.times.size else 0.0
        self._cache_key = None
        self._cache = None

    def extra_states(self) -> list[ExtraState]:
        return [self.clock.extra_state()] + [
            inter_system_bias_state(s, self.isb_initial.get(s, 0.0), self.isb_std, self.isb_psd)
            for s in self.other_systems]

    def row_label(self, i: int) -> str:
        """Satellite of row ``i`` (for the innovation log)."""
        return str(self.arrays["sat"][i])

    def _epoch(self, i: int, nav: NominalState):
        """Antenna ECEF position, ENU rotation and the (cached) epoch model of row ``i``."""
        k = int(self.epoch_of_row[i])
        cl = nav.C @ self.lever_arm
        Cel = ecef_to_enu_matrix(nav.lat, nav.lon)
        r = np.array(geodetic_to_ecef(nav.lat, nav.lon, nav.height)) + Cel.T @ cl
        key = (k, r[0], r[1], r[2])
        if key != self._cache_key:
            a, b = self.starts[k], self.starts[k + 1]
            rows = {c: v[a:b] for c, v in self.arrays.items()}
            # troposphere at the antenna height; ENU axes of the IMU point (|l| << R)
            self._cache = epoch_model(rows, r, nav.lat, nav.lon, nav.height + cl[2], self.times[i],
                                      self.iono_params, self.config, self.doy)
            self._cache_key = key
        return k, int(i - self.starts[k]), r, Cel, cl, self._cache

    def _clock_columns(self, H, nav: NominalState, i: int, drift: bool) -> float:
        """Set the clock columns of H; return the nominal clock term of the model."""
        lay = nav.layout
        c0 = lay[self.clock.name].start
        clk = nav.param(self.clock.name)
        if drift:
            H[0, c0 + 1] = 1.0
            return float(clk[1])
        H[0, c0] = 1.0
        value = float(clk[0])
        s = self.arrays["system"][i]
        if s != self.reference_system:
            name = f"isb_{s}"
            H[0, lay[name].start] = 1.0
            value += float(nav.param(name)[0])
        return value


class Pseudorange(RawGnssMeasurement):
    """Pseudorange of one satellite (one row of the prepared table); see the module docstring."""

    name = "pseudorange"

    def evaluate(self, i, nav):
        _, j, r, Cel, cl, m = self._epoch(i, nav)
        if not m.el[j] >= self.config.elevation_mask:
            return None
        u = Cel @ m.los[j]
        g = -u + np.array([0.0, 0.0, m.tropo_dh[j]])  # d h / d r_ant (ENU)
        H = np.zeros((1, nav.layout.n))
        H[0, 0:3] = g
        H[0, 6:9] = -g @ skew(cl)
        h = m.pr[j] + self._clock_columns(H, nav, i, drift=False)
        z = np.array([h - self.arrays["pr"][i]])
        return z, H, np.array([[m.var_pr[j]]])


class Doppler(RawGnssMeasurement):
    """Doppler range rate ``-lambda D`` of one satellite; see the module docstring."""

    name = "doppler"

    def extra_states(self) -> list[ExtraState]:
        """Only the clock: the range rate does not see the inter-system biases (constant
        offsets), so a Doppler beside a :class:`Pseudorange` declares no second copy of them."""
        return [self.clock.extra_state()]

    def evaluate(self, i, nav):
        dop = self.arrays["doppler"][i]
        if not np.isfinite(dop):
            return None
        _, j, r, Cel, cl, m = self._epoch(i, nav)
        if not m.el[j] >= self.config.elevation_mask:
            return None
        v_ant, J_att, J_bg = antenna_velocity(nav, self.lever_arm)
        v_ecef = Cel.T @ v_ant
        los = m.los[j]
        u = Cel @ los
        dv = m.sat_vel[j] - v_ecef
        H = np.zeros((1, nav.layout.n))
        g = (-(dv - los * (los @ dv)) / m.rho[j]) @ Cel.T  # d h / d r_ant (ENU)
        H[0, 0:3] = g
        H[0, 3:6] = -u
        H[0, 6:9] = -u @ J_att - g @ skew(cl)  # antenna velocity, and position via C l
        H[0, 9:12] = -u @ J_bg
        h = m.rate[j] - u @ v_ant + self._clock_columns(H, nav, i, drift=True)
        lam = C_LIGHT / self.arrays["freq"][i]
        z = np.array([h + lam * dop])
        return z, H, np.array([[m.var_rate[j]]])
