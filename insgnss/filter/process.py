"""The process-model plug point of the filter engine.

A process model owns the *nominal* state (the mechanized trajectory and the nominal values of
the parameter states: biases, scale factors, extra states) and the linearised error dynamics
around it. The engine (:mod:`.engine`) owns everything else: the epoch schedule, the covariance,
the updates, gating and recovery, health checks, feedback bookkeeping, the smoother's storage and
the backward pass. Between the two there are the calls of :class:`ProcessModelBase`:

============================  ===================================================================
``layout``                    the error-state blocks (``n``, ``labels``, named slices)
``initial_covariance()``      ``P(0|0)``
``prepare(epochs)``           allocate for the epoch schedule
``propagate(t_end, node)``    advance the nominal to ``t_end``; return ``Phi, Qd`` of the interval
``nominal(time)``             the nominal as the measurement models see it
                              (:class:`~.measurements.NominalState`, strapdown-like)
``observe(m, z, H, R)``       map a measurement's ``(z, H, R)`` onto this error state
``feedback(x)``               correct the nominal by the error estimate ``x`` (closed loop)
``params()``                  nominal parameter values stored with each smoother node
``close_epoch(node, t)``      the epoch's post-feedback nominal belongs to smoother ``node``
``output(store, ...)``        assemble the IMU-rate forward / smoothed table
``final_state()``             the nominal at the last processed epoch (:class:`NavState`)
============================  ===================================================================

and, for models with a compiled high-rate path (:mod:`.highrate`), ``high_rate_args()``: the
arrays and the model id the compiled per-sample loop advances.

Augmenting states (a GNSS receiver clock: bias and drift with ``Phi = [[1, dt], [0, 1]]``,
lever arms, odometer scale, ...) are declared by the measurement models as
:class:`~.models.ExtraState` blocks with their own continuous dynamics and noise; the process
model appends them to its layout, discretises them with the rest and feeds them back like any
parameter state.

Implementations: :class:`.strapdown_model.StrapdownModel` (LLF strapdown),
:class:`.wander_model.WanderModel` (wander-azimuth strapdown with an ECEF error state, valid over
the poles; its own nominal representation, ``observe`` mapping and output assembly) and
:class:`.riss_model.RissModel` (3D RISS).
"""

from __future__ import annotations

import numpy as np


class ProcessModelBase:
    """Interface of the process models (see the module docstring). (:class:`.models.ProcessModel` is
    the strapdown model's noise description, not this interface.)

    Attributes
    ----------
    layout : NamedBlocks
        Error-state layout (``n``, ``labels``, named slices).
    t : (N,) array
        IMU sample times.
    n_nav : int
        Number of leading navigation states (the block a gate recovery inflates).
    split : bool
        Epochs may fall between IMU samples (the model splits an IMU interval); otherwise they
        sit on samples and measurements see the nominal extrapolated to their time.
    n_par : int
        Length of :meth:`params`.
    noise_blocks : tuple of 3 slices
        The position, velocity and attitude states that extra process noise
        (``FilterConfig.extra_noise``: bridged IMU gaps) is added to.
    timing : dict
        Seconds spent in ``mechanization`` and ``covariance`` (filled by :meth:`propagate`).
    """

    layout = None
    t: np.ndarray
    n_nav: int = 9
    split: bool = True
    n_par: int = 0
    high_rate: bool = False
    noise_blocks = (slice(0, 3), slice(3, 6), slice(6, 9))

    def initial_covariance(self) -> np.ndarray:
        raise NotImplementedError

    def prepare(self, epochs: np.ndarray, dense=None) -> None:
        """Allocate what the propagation and the output need for the epoch times (``dense``:
        the segments run by the compiled high-rate path)."""
        raise NotImplementedError

    def propagate(self, t_end: float, node: int):
        """Advance the nominal to ``t_end`` (the IMU rows passed belong to smoother ``node``);
        return ``(Phi, Qd)`` from the previous call."""
        raise NotImplementedError

    def nominal_finite(self) -> bool:
        raise NotImplementedError

    def nominal(self, time: float):
        raise NotImplementedError

    def observe(self, m, z, H, R):
        """Map ``(z, H, R)`` of measurement ``m`` onto the model's error state (default: as is)."""
        return z, H, R

    def feedback(self, x: np.ndarray) -> None:
        raise NotImplementedError

    def params(self) -> np.ndarray:
        raise NotImplementedError

    def close_epoch(self, node: int, time: float) -> None:
        raise NotImplementedError

    def release_rows(self) -> None:
        """After an epoch: give back memory of output rows already written (a memory-mapped
        table, :func:`insgnss.io.spill.release`); nothing by default."""

    def output(self, store, n_nodes: int, n_rows: int, smoothed=None):
        raise NotImplementedError

    def rows_done(self, time: float) -> int:
        """Number of IMU-rate output rows up to ``time`` (the last completed epoch)."""
        return int(np.searchsorted(self.t, time, side="right"))

    def final_state(self, time: float):
        """The nominal (:class:`NavState`) at the last processed epoch ``time``."""
        raise NotImplementedError

    def high_rate_args(self):
        """Arrays of the compiled high-rate path (models with ``high_rate = True``)."""
        raise NotImplementedError
