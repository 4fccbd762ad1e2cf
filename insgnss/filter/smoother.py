"""Rauch-Tung-Striebel smoother for the closed-loop (feedback) error-state filter.

Why not ``filterpy.kalman.rts_smoother`` as it is
--------------------------------------------------
filterpy's smoother assumes one fixed linear state space: it forms the prediction
``F x(k|k)`` and corrects ``x(k|k) += K (x_s(k+1) - F x(k|k))``. In the closed-loop filter
the state is an *error of a nominal trajectory that changes at every update*: after the
update at epoch k the estimate ``x(k|k)`` (the feedback ``fb_k``) is folded into the
nominal and the state reset to zero, and the prediction to k+1 refers to the nominal
propagated from that *corrected* nominal. Every filtered state handed to filterpy would be
zero and the feedback jumps would be lost; feeding it the feedback vectors instead would mix
two references (pre-feedback at k+1, post-feedback at k) in one equation. The backward pass
is therefore written in error-state form (Shin 2005, sec. 3.6; DESIGN.md section 4):

    xs_minus(k+1) = xs_plus(k+1) + fb(k+1)          smoothed error w.r.t. the pre-feedback
                                                    nominal at k+1 (the prediction's reference)
    A(k)          = P(k|k) Phi(k+1)^T P(k+1|k)^-1
    xs_plus(k)    = A(k) xs_minus(k+1)              (x(k|k) = x(k+1|k) = 0 after the reset)
    Ps(k)         = P(k|k) + A(k) (Ps(k+1) - P(k+1|k)) A(k)^T

with ``xs_plus(N) = 0``, ``Ps(N) = P(N|N)``. The covariance recursion is filterpy's; the
mean recursion differs only by the feedback term. The smoothed state at epoch k is the
post-feedback nominal minus ``xs_plus(k)`` (errors are "nominal minus true").

IMU-rate output
---------------
Between epochs ``k`` and ``k+1`` the stored forward nominal runs from the post-feedback
state at ``k`` to the pre-feedback state at ``k+1``, so its smoothed error goes from
``xs_plus(k)`` to ``xs_minus(k+1)``; both ends and the smoothed variances are interpolated
linearly in time and applied to every stored sample. A sample that sits exactly on an epoch
holds the post-feedback nominal and takes ``xs_plus`` of that epoch. Epochs are at most
``epoch_interval`` (1 s default) apart, over which the error of an aided or briefly coasting
INS is close to linear.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..mechanization.strapdown import NAV_COLS
from . import kernels
from .models import StateLayout

STD_COLS = ["east_std", "north_std", "up_std", "vel_e_std", "vel_n_std", "vel_u_std",
            "roll_std", "pitch_std", "heading_std"]


def rts_error_state(P_filtered, P_predicted, Phi, feedback):
    """Backward pass of the closed-loop error-state RTS smoother.

    Parameters
    ----------
    P_filtered, P_predicted : (E, n, n) arrays
        ``P(k|k)`` and ``P(k|k-1)`` (``P_predicted[0]`` unused).
    Phi : (E, n, n) array
        ``Phi[k]`` propagates the error from epoch k-1 to k (``Phi[0]`` unused).
    feedback : (E, n) array
        Error estimate fed back (removed from the nominal) at each epoch.

    Returns
    -------
    xs_plus, xs_minus : (E, n) arrays
        Smoothed errors relative to the post- and pre-feedback nominal at each epoch.
    Ps : (E, n, n) array
        Smoothed covariances.
    """
    Pf = np.ascontiguousarray(P_filtered, dtype=float)
    E, n = Pf.shape[0], Pf.shape[1]
    xs_plus = np.zeros((E, n))
    xs_minus = np.zeros((E, n))
    Ps = np.empty_like(Pf)
    kernels.rts_backward(Pf, np.ascontiguousarray(P_predicted, dtype=float),
                         np.ascontiguousarray(Phi, dtype=float),
                         np.ascontiguousarray(feedback, dtype=float), E, xs_plus, xs_minus, Ps)
    return xs_plus, xs_minus, Ps


def smooth(store, n_ep: int):
    """Run :func:`rts_error_state` on the engine's stored epochs ``0 .. n_ep-1``."""
    return rts_error_state(store.Pf[:n_ep], store.Pp[:n_ep], store.Phi[:n_ep], store.fb[:n_ep])


def output_columns(layout: StateLayout) -> list[str]:
    """Columns of the IMU-rate tables: NAV_COLS, STD_COLS, parameter values, their stds."""
    par = layout.labels[9:]
    return list(NAV_COLS) + STD_COLS + par + [f"{c}_std" for c in par]


def assemble_table(t, store, ep_t, n_rows: int, layout: StateLayout, smoothed=None) -> pd.DataFrame:
    """IMU-rate forward (``smoothed=None``: completes ``store.nav`` in place) or smoothed
    (``(xs_plus, xs_minus, Ps)``: a new table from the forward nominal) table."""
    n = layout.n
    cols = output_columns(layout)
    if smoothed is None:
        out = store.nav
        if n_rows:
            X = np.zeros((1, n))  # unused: no correction
            kernels.assemble_output(t, store.nav, store.seg, store.post, ep_t, store.Pf, store.Pp,
                                    X, X, store.pnom, n_rows, False, out)
    else:
        out = np.empty((n_rows, len(cols)))
        if n_rows:
            xs_plus, xs_minus, Ps = smoothed
            kernels.assemble_output(t, store.nav, store.seg, store.post, ep_t, Ps, Ps, xs_plus,
                                    xs_minus, store.pnom, n_rows, True, out)
    return pd.DataFrame(out[:n_rows], index=pd.Index(t[:n_rows], name="time"), columns=cols,
                        copy=False)
