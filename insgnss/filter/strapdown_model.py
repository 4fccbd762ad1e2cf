"""LLF (ENU) strapdown INS as a process model of the filter engine.

The nominal state is the strapdown mechanization (:func:`insgnss.mechanization.strapdown.
strapdown_step`) of the IMU increments compensated with the nominal bias and scale-factor
estimates; the error state and its continuous dynamics are those of :mod:`.models`
(position, velocity, attitude misalignment, biases, optional scale factors and augmenting extra
states, all "nominal minus true").

Propagation over an interval (:meth:`StrapdownModel.propagate`):

1. :func:`.kernels.propagate_nominal` (numba) mechanizes over the IMU samples up to ``t_end``,
   stores the nominal at the IMU rate and integrates ``F`` and the noise over covariance
   sub-intervals of ``propagation_interval`` seconds. An IMU interval that straddles ``t_end``
   is split (linear share of its increments).
2. :func:`.kernels.discretize` (numba) turns each sub-interval into ``Phi, Qd`` (second order
   or van Loan) and composes them over the interval (exactly what propagating P over every
   sub-interval in turn would give).

Feedback: ``lat, lon, h`` from the ENU position error, ``v <- v - dv``, ``C <- exp(-[phi x]) C``
and the parameters ``p <- p - dp`` (:func:`.kernels.apply_feedback`). A Gauss-Markov parameter's
nominal follows its mean between epochs (``b' = -b / tau``), a coupled augmenting block its
dynamics (``p' = F_x p``: a receiver clock's bias grows by ``drift dt``).

The compiled high-rate path (:mod:`.highrate`) advances the same nominal arrays sample by sample
(:meth:`StrapdownModel.high_rate_args`).
"""

from __future__ import annotations

import time as _time

import numpy as np
import pandas as pd

from .. import earth
from ..columns import STD_COLS
from ..errors import InvalidValueError
from ..imu import coning_sculling, grade, increments
from ..io import spill
from ..mechanization.strapdown import NAV_COLS, STEP_WORK_SHAPE, NavState, attitude_update_id
from . import kernels
from .health import finite_navigation
from .measurements import NominalState
from .models import ERROR_DYNAMICS, StateLayout, process_model
from .process import ProcessModelBase
from .store import AssembledTable, RowSegments, Table

__all__ = ["StrapdownModel", "STD_COLS", "output_columns", "levelling_covariance",
           "DISCRETIZATIONS"]

DISCRETIZATIONS = {"second_order": kernels.DISC_SECOND_ORDER, "vanloan": kernels.DISC_VANLOAN}

#: compiled high-rate path: model id of this nominal representation (see :mod:`.highrate`)
MODEL_LLF = 0

#: :meth:`StrapdownModel.f_pattern` per model structure (the arrays are never written)
_PATTERNS: dict = {}


#: the columns the assembly of a row can form alone (``kernels.assemble_output``,
#: ``position_only``): what the evaluation of the positions reads
POSITION_COLUMNS = ("lat", "lon", "height", "east_std", "north_std", "up_std")


def output_columns(layout: StateLayout) -> list[str]:
    """Columns of the IMU-rate tables: NAV_COLS, STD_COLS, parameter values, their stds."""
    par = layout.labels[9:]
    return list(NAV_COLS) + STD_COLS + par + [f"{c}_std" for c in par]


def levelling_covariance(P, C, att: slice, accel_bias: slice, g: float) -> np.ndarray:
    """``P`` with the tilt / horizontal accelerometer-bias correlation of a levelled start.

    Levelling sets ``C`` so that ``C^T (0, 0, g) = f_mean``; with an accelerometer bias error
    ``db`` (nominal minus true) the misalignment is ``phi x g^l = C db``, i.e. ``phi = J db`` with
    ``J = [[0, -1, 0], [1, 0, 0], [0, 0, 0]] C / g``. Adds ``J P_b J^T`` to the attitude block
    and ``J P_b`` as the cross-covariance (errors "nominal minus true", ``C = (I + [phi x])
    C_true``).
    """
    P = P.copy()
    J = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]) @ C / g
    Pb = P[accel_bias, accel_bias]
    cross = J @ Pb
    P[att, att] += cross @ J.T
    P[att, accel_bias] = cross
    P[accel_bias, att] = cross.T
    return P


class StrapdownModel(ProcessModelBase):
    """LLF strapdown process model (module docstring).

    Parameters
    ----------
    imu : DataFrame
        IMU table (rates or increments) indexed by time [s]; its first row is the epoch of
        ``initial``.
    initial : NavState
    extras : list of ExtraState
        Augmenting states requested by the measurement models.
    config : FilterConfig
        IMU and bias models, initial stds, scale factors, mechanization and discretisation
        options (:class:`insgnss.filter.engine.FilterConfig`).
    """

    n_nav = 9
    split = True
    high_rate = True
    heading_reset = True  # the engine may rotate the heading (.heading_reinit)

    def __init__(self, imu: pd.DataFrame, initial: NavState, extras, config):
        t, dth, dv = increments(imu)
        self._setup(t, dth, dv, initial, extras, config)

    @classmethod
    def from_increments(cls, t, dth, dv, initial: NavState, extras, config) -> StrapdownModel:
        """The model on increment arrays (``t`` (N,), ``dth``, ``dv`` (N, 3) over
        ``(t[k-1], t[k]]``) instead of an IMU table."""
        self = cls.__new__(cls)
        self._setup(np.asarray(t, float), dth, dv, initial, extras, config)
        return self

    def _setup(self, t, dth, dv, initial, extras, config):
        imu_model = grade(config.imu_model) if isinstance(config.imu_model, str) \
            else config.imu_model
        if t.size < 2:
            raise InvalidValueError("IMU table needs at least two samples", found=t.size)
        if not np.all(np.diff(t) > 0):
            raise InvalidValueError("IMU times must be strictly increasing")
        if config.coning:
            dth, dv = coning_sculling(dth, dv)
        self.t = t
        self.dth = np.ascontiguousarray(dth, dtype=float)
        self.dv = np.ascontiguousarray(dv, dtype=float)
        self.layout = layout = StateLayout(config.scale_factors, extras)
        pm = process_model(
            layout, imu_model, config.bias_model, config.initial_pos_std, config.initial_vel_std,
            config.initial_att_std, config.initial_gyro_bias_std, config.initial_accel_bias_std,
            config.initial_gyro_scale_std, config.initial_accel_scale_std, config.gyro_bias,
            config.accel_bias)
        pm.dyn_noise = np.array([config.accel_dynamic_noise, config.gyro_dynamic_noise], float)
        self.noise = pm
        self.n_par = layout.n - 9
        self.i_sg, self.i_sa = layout.index("gyro_scale"), layout.index("accel_scale")
        self.method = DISCRETIZATIONS[config.discretization]
        self.gmodel = earth.gravity_model_id(config.gravity_model)
        self.aupd = attitude_update_id(config.attitude_update)
        self.sub_T = float(config.propagation_interval)
        self.dynamics = ERROR_DYNAMICS[config.error_dynamics]
        self.levelling = bool(config.levelling_correlation)
        self.gravity_model = config.gravity_model
        self.pos = np.array([initial.lat, initial.lon, initial.height], float)
        self.vel = np.array(initial.vel, float).copy()
        self.C = np.ascontiguousarray(initial.C, dtype=float).copy()
        self.pnom = pm.initial_values.copy()
        index = {label: i for i, label in enumerate(layout.labels)}
        for label, value in (config.initial_parameters or {}).items():
            if index.get(label, -1) >= 9:  # parameter states follow the 9 navigation errors
                self.pnom[index[label] - 9] = float(value)
        self.par_decay = pm.decay[9:].copy()
        self.has_decay = bool(np.any(self.par_decay > 0))
        # coupled augmenting states: their nominal follows p' = (Fx - diag(decay)) p
        self.par_dyn = None
        if pm.Fx is not None:
            self.par_dyn = pm.Fx[9:, 9:] - np.diag(self.par_decay)
        self.j, self.frac = 1, 0.0
        self.rates = np.zeros((4, 3))
        self.seg_dur = 0.0
        self.t_last = float(t[0])
        self.timing = {"mechanization": 0.0, "covariance": 0.0}
        self._nav = NominalState()
        self._nav.layout = layout
        self._nav.gyro_psd = pm.gyro_psd
        self._nav_time = None
        # the IMU-rate tables: in memory up to the job's budget, else mapped (io/spill.py)
        self._allocate = np.empty if config.store_allocate is None else config.store_allocate
        self._released = 0  # forward-table rows whose pages were given back

    # --- engine calls -------------------------------------------------------------------------
    def prepare(self, epochs: np.ndarray, dense=None) -> None:
        """Allocate the output table and the propagation buffers for the epoch schedule
        (``dense``: segments the compiled high-rate path runs, which leave at most one IMU
        interval to :meth:`propagate`)."""
        t = self.t
        n = self.layout.n
        self.table = self._allocate((t.size, len(output_columns(self.layout))), float)
        self._released = 0
        # rows written between two releases of a mapped table's pages (:meth:`release_rows`)
        self._release_step = (max(1, spill.BLOCK_BYTES // self.table[:1].nbytes)
                              if spill.is_mapped(self.table) else t.size + 1)
        # the node (or -1 - high-rate sample) of each row: int32 halves what the smoothed
        # table's assembly keeps after the run (29 MiB at 10 h / 200 Hz); int64 only for
        # logs beyond 2^31 rows
        self.seg = np.zeros(t.size, np.int32 if t.size < 2**31 - 1 else np.int64)
        self.post = np.zeros(t.size, np.bool_)
        gaps = np.diff(epochs)
        if dense is not None and gaps.size:
            gaps = np.where(np.asarray(dense)[1:], 2.0 * float(np.max(np.diff(t))), gaps)
        max_gap = float(np.max(gaps)) if gaps.size else 0.0
        max_sub = min(int(np.ceil(max_gap / self.sub_T)),
                      int(np.ceil(max_gap / np.min(np.diff(t))))) + 3
        self.Fint = np.zeros((max_sub, n, n))
        self.Qint = np.zeros((max_sub, 2, 3, 3))
        self.sub_dt = np.zeros(max_sub)
        self.Phi = np.eye(n)
        self.Qd = np.zeros((n, n))
        kernels.store_nav(self.table, 0, self.pos, self.vel, self.C)
        self.seg[0], self.post[0] = 0, True

    def initial_covariance(self) -> np.ndarray:
        P = np.diag(self.noise.p0**2)
        if self.levelling:
            g = earth.normal_gravity(self.pos[0], self.pos[2], self.gravity_model)
            P = levelling_covariance(P, self.C, self.layout["att"], self.layout["accel_bias"], g)
        return P

    def propagate(self, t_end: float, node: int):
        perf = _time.perf_counter
        c0 = perf()
        pm = self.noise
        self.j, self.frac, n_sub = self._propagate_nominal(t_end, node)
        dur = t_end - self.t_last
        if self.par_dyn is not None:
            # coupled blocks (a receiver clock: bias += drift dt) and decays, exactly
            self.pnom[:] = kernels.expm_nb(self.par_dyn * dur) @ self.pnom
        elif self.has_decay:
            # the nominal of a Gauss-Markov parameter follows its mean, b' = -b / tau
            self.pnom *= np.exp(-self.par_decay * dur)
        self.seg_dur = dur
        self.t_last = t_end
        c1 = perf()
        kernels.discretize(self.Fint, self.Qint, self.sub_dt, n_sub, pm.decay, pm.qdiag,
                           self.method, self.Phi, self.Qd, pm.Fx, pm.Qx)
        self.timing["mechanization"] += c1 - c0
        self.timing["covariance"] += perf() - c1
        return self.Phi, self.Qd

    def _propagate_nominal(self, t_end: float, node: int):
        """The compiled mechanization and F, Q accumulation up to ``t_end``:
        ``(j, frac, n_sub)`` (:func:`.kernels.propagate_nominal`)."""
        pm = self.noise
        return kernels.propagate_nominal(
            self.t, self.dth, self.dv, self.j, self.frac, t_end, self.pos, self.vel, self.C,
            self.pnom, self.i_sg, self.i_sa, self.gmodel, self.aupd, self.sub_T, self.Fint,
            self.Qint, self.sub_dt, pm.gyro_psd, pm.accel_psd, self.table, self.seg, node,
            self.rates, pm.dyn_noise, self.dynamics)

    def advance_to(self, t_last: float) -> None:
        """The compiled high-rate path moved the nominal to its node at ``t_last``."""
        self.t_last = t_last
        self._nav_time = None

    def nominal_finite(self) -> bool:
        return finite_navigation(self.pos, self.vel, self.C)

    def nominal(self, time: float) -> NominalState:
        nav = self._nav
        if self._nav_time == time:
            return nav
        pos, rates = self.pos, self.rates
        nav.time = time
        nav.lat, nav.lon, nav.height = pos[0], pos[1], pos[2]
        nav.vel, nav.C = self._nominal_velocity_attitude()
        nav.omega_ib, nav.omega_ib_mean = rates[0], rates[1]
        nav.f_ib, nav.f_ib_mean = rates[2], rates[3]
        nav.segment_duration = self.seg_dur
        nav.params = self.pnom
        nav.M, nav.N = earth.radii(pos[0])
        self._complete_nominal(nav)
        self._nav_time = time
        return nav

    def _nominal_velocity_attitude(self) -> tuple[np.ndarray, np.ndarray]:
        """ENU velocity and body-to-ENU DCM of the nominal state (views)."""
        return self.vel, self.C

    def _complete_nominal(self, nav: NominalState) -> None:
        """Fields a derived frame adds to the nominal state (none for the LLF)."""

    def feedback(self, x: np.ndarray) -> None:
        kernels.apply_feedback(self.pos, self.vel, self.C, self.pnom, x)
        self._nav_time = None

    def params(self) -> np.ndarray:
        return self.pnom

    def close_epoch(self, node: int, time: float) -> None:
        # the IMU sample that sits on this epoch holds the post-feedback state
        j = self.j
        if self.frac == 0.0 and self.t[j - 1] == time:
            kernels.store_nav(self.table, j - 1, self.pos, self.vel, self.C)
            self.seg[j - 1], self.post[j - 1] = node, True
        self._nav_time = None

    def release_rows(self) -> None:
        """Give back the pages of the forward-table rows written so far when the table is
        memory-mapped (:func:`insgnss.io.spill.release`; the contents stay in the file): the
        resident part of a long log's table stays at about one block during the pass."""
        j = self.j - 1
        if j - self._released >= self._release_step:
            spill.release(self.table, self._released, j)
            self._released = j

    def output(self, store, n_nodes: int, n_rows: int, smoothed=None) -> Table:
        """IMU-rate forward table (``smoothed=None``: completes the stored nominal table in
        place) or smoothed table (``(xs_plus, xs_minus, Ps or None, xs_hr)``: a new table; the
        smoothed std columns are NaN without smoothed covariances), as a :class:`.store.Table`
        (arrays; its DataFrame is built when asked for)."""
        cols = output_columns(self.layout)
        t = self.t
        n_hr = store.hr_count
        hr_node = np.searchsorted(store.seg1[:n_nodes], np.arange(n_hr), side="right")
        ep_t, par, table, seg, post = store.t[:n_nodes], store.par, self.table, self.seg, self.post
        if smoothed is None:  # P(e|e) at the start of a segment, P(e|e-1) at its end
            none = np.zeros((1, self.layout.n))  # unused: no correction
            # in row blocks: a block's pages of a mapped table are given back after it
            for i, j in spill.blocks(n_rows, table[:1].nbytes):
                kernels.assemble_output(t[i:j], table[i:j], seg[i:j], post[i:j], ep_t,
                                        store.Pf, store.Pp, none, none, par, j - i, False,
                                        table[i:j], none, hr_node, True, False)
                spill.release(table, i, j)
            return Table(t[:n_rows], table[:n_rows], cols)
        Xp, Xm, Ps, xs_hr = smoothed
        P = store.Pf if Ps is None else Ps
        stds = Ps is not None  # without smoothed covariances the std columns are NaN
        segments = RowSegments(seg, post, n_rows)  # not the per-row arrays (store.py)

        position = {cols.index(c) for c in POSITION_COLUMNS}

        def assemble(rows, out, columns=None):
            seg_r, post_r = segments.rows(rows)
            kernels.assemble_output(t[rows], table[rows], seg_r, post_r, ep_t, P, P, Xp, Xm,
                                    par, out.shape[0], True, out, xs_hr, hr_node, stds,
                                    columns is not None and set(columns) <= position)

        def release(i, j):
            """Give back the pages of mapped inputs that rows ``i .. j-1`` read: their
            forward rows and the nodes (and high-rate samples) they lie between (the job
            released the node store after the smoother, processes.py)."""
            spill.release(table, i, j)
            s = segments.rows(segments.edges(i, j))[0]  # the extremes, not every row
            hr = -1 - s[s < 0]
            nodes = np.concatenate([s[s >= 0], hr_node[hr]])
            if nodes.size:
                lo, hi = max(int(nodes.min()) - 1, 0), int(nodes.max()) + 1
                for a in (P, Xp, Xm, par):
                    spill.release(a, lo, hi)
            if hr.size:
                spill.release(xs_hr, int(hr.min()), int(hr.max()) + 1)

        # formed where read (store.AssembledTable): the evaluation reads the reference
        # epochs' rows, the writers the output rate's; nothing writes a whole-log table
        return AssembledTable(t[:n_rows], cols, assemble, allocate=self._allocate,
                              release=release)

    def final_state(self, time: float) -> NavState:
        return NavState(self.pos[0], self.pos[1], self.pos[2], self.vel.copy(), self.C.copy(),
                        float(time))

    def f_pattern(self):
        """Structural non-zeros of the per-interval ``F dt`` and ``Qd`` of this model:
        ``(f_ptr, f_col, f_act, q_row, q_col)`` for :func:`insgnss.filter.highrate.
        _first_order_propagation` (rows ``f_act`` of F with the columns
        ``f_col[f_ptr[a]:f_ptr[a+1]]``; the entries ``(q_row, q_col)`` of Qd).

        Found by evaluating the interval step at a random, generic nominal (every term that
        can be non-zero is, with probability one) plus the parameter decays and the constant
        blocks of coupled augmenting states. The pattern depends only on the model's structure
        (kept per structure: the foot profile builds a model per walk)."""
        n = self.layout.n
        pm = self.noise
        key = (type(self), n, self.n_par, self.i_sg, self.i_sa, self.gmodel, self.aupd,
               self.dynamics, (pm.decay > 0.0).tobytes(),
               None if pm.Fx is None else (pm.Fx != 0.0).tobytes(),
               None if pm.Qx is None else (pm.Qx != 0.0).tobytes())
        pattern = _PATTERNS.get(key)
        if pattern is None:
            pattern = _PATTERNS[key] = self._f_pattern()
        return pattern

    def _f_pattern(self):
        n = self.layout.n
        rng = np.random.default_rng(12345)
        F = np.zeros((n, n))
        Qg, Qa = np.zeros((3, 3)), np.zeros((3, 3))
        C = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        kernels.interval_step(np.array([0.7, 0.2, 150.0]), rng.normal(size=3) * 5, C,
                              rng.normal(size=self.n_par) * 1e-3, rng.normal(size=3) * 1e-2,
                              rng.normal(size=3) * 1e-1, 1.0, 0.01, self.i_sg, self.i_sa,
                              self.gmodel, self.aupd, F, Qg, Qa, np.ones(3), np.ones(3),
                              np.ones(2), np.empty(3), np.empty(3),
                              np.empty(STEP_WORK_SHAPE), self.dynamics)
        mask = F != 0.0
        mask[np.diag_indices(n)] |= self.noise.decay > 0.0
        if self.noise.Fx is not None:
            mask |= self.noise.Fx != 0.0
        rows = np.flatnonzero(mask.any(axis=1))
        f_ptr = np.concatenate([[0], np.cumsum(mask[rows].sum(axis=1))]).astype(np.int64)
        f_col = np.concatenate([np.flatnonzero(mask[r]) for r in rows]).astype(np.int64)
        qm = np.zeros((n, n), bool)
        qm[np.diag_indices(n)] = True
        qm[3:9, 3:9] |= np.kron(np.eye(2, dtype=bool), np.ones((3, 3), bool))
        if self.noise.Qx is not None:
            qm |= self.noise.Qx != 0.0
        q_row, q_col = (a.astype(np.int64) for a in np.nonzero(qm))
        return f_ptr, f_col, rows.astype(np.int64), q_row, q_col

    def high_rate_args(self):
        """``(model id, error-dynamics id, t, dth, dv, pos, vel, C, pnom, i_sg, i_sa, gravity
        model, attitude update, gyro PSD, accel PSD, dynamic noise, decay, qdiag, Fx, Qx,
        table, seg, post, rates)`` for :func:`insgnss.filter.highrate.dense_segment`."""
        pm = self.noise
        n = self.layout.n
        Fx = pm.Fx if pm.Fx is not None else np.zeros((0, n))
        Qx = pm.Qx if pm.Qx is not None else np.zeros((0, n))
        return (MODEL_LLF, self.dynamics, self.t, self.dth, self.dv, self.pos, self.vel, self.C,
                self.pnom, self.i_sg, self.i_sa, self.gmodel, self.aupd, pm.gyro_psd, pm.accel_psd,
                pm.dyn_noise, pm.decay, pm.qdiag, Fx, Qx, self.table, self.seg, self.post,
                self.rates)
