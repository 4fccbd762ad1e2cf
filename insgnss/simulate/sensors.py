"""IMU sensor error synthesis: from ideal increments to the output of a real IMU.

Model
-----
For every interval k (length ``dt``, ending at sample k) the simulated increments are::

    dtheta_m = (I + S_g + N_g) dtheta + G_g dv + b_g(t_k) dt + n_g        n_g ~ N(0, ARW^2 dt)
    dv_m     = (I + S_a + N_a) dv              + b_a(t_k) dt + n_a        n_a ~ N(0, VRW^2 dt)

followed by saturation (``|x| <= range dt``) and quantization to the output resolution with the
residual carried over (``Q_k = q round(sum_{j<=k} x_j / q)``, output ``Q_k - Q_{k-1}``, so that
quantization does not accumulate; Savage 1998). This is the inverse of the deterministic
compensation :func:`insgnss.imu.compensate` ``x = (I + S + N)^-1 (x_m - b)``.

- ``S = diag(s)``: scale-factor errors, ``s_i ~ N(0, sigma_s^2)``, drawn once (turn-on);
- ``N``: non-orthogonality / misalignment, off-diagonal ``N_ij ~ N(0, sigma_m^2)``, zero diagonal;
- ``G_g``: gyro g-sensitivity, every element ``~ N(0, sigma_G^2)`` (optional);
- ``b(t) = b_0 + b_BI(t) + b_RRW(t)`` (this series is returned as truth):

  * ``b_0 ~ N(0, sigma_b^2)``: turn-on (run-to-run) bias, constant during the run;
  * ``b_BI``: bias instability. ``"gauss_markov"`` (default, the filter's model): a first-order
    Gauss-Markov process ``b_k = phi b_{k-1} + w_k``, ``phi = exp(-dt/T)``,
    ``var(w) = sigma_BI^2 (1 - phi^2)``, started from its stationary distribution.
    ``"flicker"``: the IEEE Std 952 bias instability (flicker, 1/f) noise whose Allan deviation
    is the flat floor ``sqrt(2 ln 2 / pi) B = 0.664 B``, approximated by a bank of Gauss-Markov
    processes with correlation times spaced ``per_decade`` per decade over ``flicker_band``:
    with ``n = per_decade / ln 10`` processes per unit of ``ln T`` each of variance
    ``sigma_i^2``, the sum has the one-sided PSD ``n sigma_i^2 / f`` inside the band, and the
    flicker PSD of coefficient B is ``B^2 / (pi f)``, so ``sigma_i^2 = B^2 ln 10 / (pi per_decade)``
    (Kasdin 1995; IEEE Std 952-1997 annex C). In this mode ``gyro_bias_instability`` and
    ``accel_bias_instability`` are read as the Allan-floor coefficient B, which is what an Allan
    analysis recovers (a single Gauss-Markov process has no flat floor: its Allan deviation
    peaks at ~0.62 sigma_BI near tau = 1.9 T);
  * ``b_RRW``: rate random walk ``b_k = b_{k-1} + K sqrt(dt) xi_k``, ``b_0 = 0``.

All recursions are vectorised (``scipy.signal.lfilter`` for the Gauss-Markov processes,
``cumsum`` for random walks and the quantizer). Every component draws from its own child of the
seeded generator (``Generator.spawn``), so that switching one component on or off leaves the
others' realisations unchanged.

References
----------
- IEEE Std 952-1997 (R2008), *IEEE Standard Specification Format Guide and Test Procedure for
  Single-Axis Interferometric Fiber Optic Gyros*, annex C (Allan variance noise terms).
- Groves 2013, sections 4.4 (IMU error characteristics) and 14.2.6 (IMU error simulation).
- Savage, "Strapdown inertial navigation integration algorithm design", JGCD 21 (1998)
  (quantization residual carry).
- Kasdin, "Discrete simulation of colored noise and stochastic processes and 1/f^alpha power law
  noise generation", Proc. IEEE 83 (1995).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.signal import lfilter

from ..imu import ImuErrorModel, increments, increments_table, rates_table

BIAS_COLS = ["gyro_bias_x", "gyro_bias_y", "gyro_bias_z",
             "accel_bias_x", "accel_bias_y", "accel_bias_z"]
BIAS_INSTABILITY_MODELS = ("gauss_markov", "flicker")
OUTPUTS = ("increments", "rates")
_COMPONENTS = ("turn_on", "scale", "nonorth", "g_sensitivity", "instability", "rrw", "noise")


@dataclass
class ImuErrors:
    """Result of :func:`simulate_imu`.

    Attributes
    ----------
    imu : DataFrame
        Simulated IMU table (increments ``dtheta_* dv_*`` or rates ``gyro_* accel_*``).
    bias : DataFrame
        Total bias at each sample (turn-on + instability + rate random walk), columns
        :data:`BIAS_COLS` [rad/s, m/s^2]: the truth for bias estimation.
    params : dict
        The drawn constant parameters (numpy arrays, SI): ``gyro_bias_turn_on``,
        ``accel_bias_turn_on`` (3,), ``gyro_scale``, ``accel_scale`` (3,), ``gyro_nonorth``,
        ``accel_nonorth``, ``gyro_g_sensitivity`` (3, 3).
    model : ImuErrorModel
    settings : dict
        Bias-instability model and band, output type, seed entropy.
    """

    imu: pd.DataFrame
    bias: pd.DataFrame
    params: dict
    model: ImuErrorModel
    settings: dict = field(default_factory=dict)

    def params_as_lists(self) -> dict:
        """``params`` with arrays as nested lists (for JSON metadata)."""
        return {k: np.asarray(v).tolist() for k, v in self.params.items()}


def gauss_markov(rng: np.random.Generator, n: int, dt: float, sigma, tau, size: int = 3):
    """Stationary first-order Gauss-Markov sequences, shape (n, size).

    ``x_k = exp(-dt/tau) x_{k-1} + w_k`` with ``var(x) = sigma^2``; ``sigma`` and ``tau`` may be
    scalars or per-column arrays.
    """
    sigma = np.broadcast_to(np.asarray(sigma, float), (size,))
    tau = np.broadcast_to(np.asarray(tau, float), (size,))
    w = rng.standard_normal((size, n)).T  # column-contiguous: lfilter runs along memory
    phi = np.exp(-dt / tau)
    w[1:] *= sigma * np.sqrt(1.0 - phi * phi)
    w[0] *= sigma  # stationary start
    out = np.empty((n, size))
    for p in np.unique(phi):  # usually one value; lfilter runs the recursion in C
        cols = np.flatnonzero(phi == p)
        out[:, cols] = lfilter([1.0], [1.0, -p], w[:, cols], axis=0)
    return out


def flicker_bank(rng: np.random.Generator, n: int, dt: float, B, band: tuple[float, float],
                 per_decade: int = 3, size: int = 3, decimate: bool = True) -> np.ndarray:
    """Flicker (bias instability) noise of Allan floor ``0.664 B`` by a bank of Gauss-Markov
    processes with correlation times log-spaced over ``band`` [s] (see module docstring).

    With ``decimate`` a process of correlation time T is generated on a coarse grid of step
    ``h = m dt <= T / 40`` (``m`` a power of 4; processes sharing ``m`` are summed there) and
    linearly interpolated to the sample times. This costs one interpolation per group instead of
    a full-rate recursion per process, and changes the statistics by less than 1 % in variance
    (``1 - var(mid-point) / sigma^2 ~ h / 2T``, and the missing content above ``1/h`` of the slow
    processes is < 1.2 % of the Allan variance at any tau).
    """
    lo, hi = band
    if not 0 < lo < hi:
        raise ValueError(f"flicker band must satisfy 0 < low < high; got {band}")
    n_tau = max(int(np.ceil(per_decade * np.log10(hi / lo))), 1) + 1
    taus = np.geomspace(lo, hi, n_tau)
    B = np.broadcast_to(np.asarray(B, float), (size,))
    sig = B * np.sqrt(np.log(10.0) / (np.pi * per_decade))
    if decimate:
        ratio = np.maximum(taus / (40.0 * dt), 1.0)
        m = (4 ** np.floor(np.log(ratio) / np.log(4.0))).astype(int)
        m = np.minimum(m, max(1, 4 ** int(np.floor(np.log(max(n - 1, 1)) / np.log(4.0)))))
    else:
        m = np.ones(taus.size, int)
    out = np.zeros((n, size))
    k = np.arange(n)
    for mj in np.unique(m):
        group = taus[m == mj]
        if mj == 1:
            for T in group:
                out += gauss_markov(rng, n, dt, sig, T, size)
            continue
        nc = (n - 1) // mj + 2  # coarse samples covering the run
        coarse = np.zeros((nc, size))
        for T in group:
            coarse += gauss_markov(rng, nc, mj * dt, sig, T, size)
        j = k // mj
        frac = ((k - j * mj) / mj)[:, None]
        out += coarse[j] * (1.0 - frac) + coarse[j + 1] * frac
    return out


def random_walk(rng: np.random.Generator, n: int, dt: float, K, size: int = 3) -> np.ndarray:
    """Random walk starting at zero with density ``K`` [unit/sqrt(s)], shape (n, size)."""
    steps = rng.standard_normal((n, size)) * (np.asarray(K, float) * np.sqrt(dt))
    steps[0] = 0.0
    return np.cumsum(steps, axis=0)


def quantize(x: np.ndarray, q: float) -> np.ndarray:
    """Quantize increments to resolution ``q`` with the residual carried over (no drift)."""
    if q <= 0:
        return x
    Q = np.round(np.cumsum(x, axis=0) / q) * q
    out = np.empty_like(Q)
    out[0] = Q[0]
    out[1:] = np.diff(Q, axis=0)
    return out


def _offdiag(rng, sigma: float) -> np.ndarray:
    m = rng.standard_normal((3, 3)) * sigma
    np.fill_diagonal(m, 0.0)
    return m


def simulate_imu(
    ideal: pd.DataFrame,
    model: ImuErrorModel,
    rng: np.random.Generator | int | None = None,
    *,
    bias_instability: str = "gauss_markov",
    flicker_band: tuple[float, float] | None = None,
    flicker_per_decade: int = 3,
    output: str = "increments",
) -> ImuErrors:
    """Add the errors of ``model`` to an ideal IMU table.

    Parameters
    ----------
    ideal : DataFrame
        Ideal IMU (increments, e.g. from :func:`insgnss.mechanization.inverse.inverse_mechanize`,
        or rates) at a uniform rate.
    model : ImuErrorModel
        Error parameters (SI); see :data:`insgnss.imu.GRADES`.
    rng : numpy Generator or int seed
    bias_instability : {"gauss_markov", "flicker"}
        Bias-instability process (see module docstring).
    flicker_band : (float, float), optional
        Correlation-time band of the flicker bank [s]; default ``(2 dt, 10 T_run)`` (the Allan
        floor is flat from ~10 times the lower to ~1/10 of the upper edge).
    flicker_per_decade : int
        Gauss-Markov processes per decade of the flicker bank.
    output : {"increments", "rates"}
        Output table type. Rates are the interval means ``dtheta / dt`` (row 0 repeats row 1);
        a trapezoidal re-integration of them is not exact, prefer increments.

    Returns
    -------
    ImuErrors
    """
    if bias_instability not in BIAS_INSTABILITY_MODELS:
        raise ValueError(f"bias_instability must be one of {BIAS_INSTABILITY_MODELS}; "
                         f"got {bias_instability!r}")
    if output not in OUTPUTS:
        raise ValueError(f"output must be one of {OUTPUTS}; got {output!r}")
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(rng)
    t, dth, dv = increments(ideal)
    n = t.size
    if n < 2:
        raise ValueError("the IMU table needs at least two samples")
    dts = np.diff(t)
    dt = float(np.median(dts))
    if np.max(np.abs(dts - dt)) > 1e-6 * dt + 1e-9:
        raise ValueError("simulate_imu needs a uniform sample rate")
    sub = dict(zip(_COMPONENTS, rng.spawn(len(_COMPONENTS)), strict=True))
    m = model

    params = {
        "gyro_bias_turn_on": sub["turn_on"].standard_normal(3) * m.gyro_bias,
        "accel_bias_turn_on": sub["turn_on"].standard_normal(3) * m.accel_bias,
        "gyro_scale": sub["scale"].standard_normal(3) * m.gyro_scale,
        "accel_scale": sub["scale"].standard_normal(3) * m.accel_scale,
        "gyro_nonorth": _offdiag(sub["nonorth"], m.gyro_misalignment),
        "accel_nonorth": _offdiag(sub["nonorth"], m.accel_misalignment),
        "gyro_g_sensitivity": sub["g_sensitivity"].standard_normal((3, 3)) * m.gyro_g_sensitivity,
    }

    # bias time series [rad/s, m/s^2]
    bias = np.empty((n, 6))
    bias[:, :3] = params["gyro_bias_turn_on"]
    bias[:, 3:] = params["accel_bias_turn_on"]
    bi = np.array([m.gyro_bias_instability] * 3 + [m.accel_bias_instability] * 3)
    settings = {"bias_instability": bias_instability, "output": output, "dt": dt}
    if np.any(bi > 0):
        if bias_instability == "gauss_markov":
            bias += gauss_markov(sub["instability"], n, dt, bi, m.bias_correlation_time, 6)
            settings["bias_correlation_time"] = m.bias_correlation_time
        else:
            band = flicker_band or (2.0 * dt, 10.0 * (t[-1] - t[0]))
            bias += flicker_bank(sub["instability"], n, dt, bi, band, flicker_per_decade, 6)
            settings["flicker_band"] = [float(band[0]), float(band[1])]
            settings["flicker_per_decade"] = int(flicker_per_decade)
    rrw = np.array([m.gyro_rrw] * 3 + [m.accel_rrw] * 3)
    if np.any(rrw > 0):
        bias += random_walk(sub["rrw"], n, dt, rrw, 6)

    # deterministic errors, bias and white noise on the increments
    dtv = np.empty(n)
    dtv[0] = dt
    dtv[1:] = dts
    Mg = np.eye(3) + np.diag(params["gyro_scale"]) + params["gyro_nonorth"]
    Ma = np.eye(3) + np.diag(params["accel_scale"]) + params["accel_nonorth"]
    out_th = dth @ Mg.T + dv @ params["gyro_g_sensitivity"].T + bias[:, :3] * dtv[:, None]
    out_dv = dv @ Ma.T + bias[:, 3:] * dtv[:, None]
    noise = sub["noise"].standard_normal((n, 6)) * np.sqrt(dtv)[:, None]
    if m.gyro_arw > 0:
        out_th += noise[:, :3] * m.gyro_arw
    if m.accel_vrw > 0:
        out_dv += noise[:, 3:] * m.accel_vrw
    # saturation, then quantization
    if m.gyro_range > 0:
        lim = m.gyro_range * dtv[:, None]
        out_th = np.clip(out_th, -lim, lim)
    if m.accel_range > 0:
        lim = m.accel_range * dtv[:, None]
        out_dv = np.clip(out_dv, -lim, lim)
    out_th = quantize(out_th, m.gyro_quantization)
    out_dv = quantize(out_dv, m.accel_quantization)

    if output == "increments":
        table = increments_table(t, out_th, out_dv)
    else:
        w = out_th / dtv[:, None]
        f = out_dv / dtv[:, None]
        w[0], f[0] = w[1], f[1]
        table = rates_table(t, w, f)
    bias_df = pd.DataFrame(bias, index=pd.Index(t, name="time"), columns=BIAS_COLS)
    return ImuErrors(imu=table, bias=bias_df, params=params, model=model, settings=settings)


__all__ = ["BIAS_COLS", "ImuErrors", "simulate_imu", "gauss_markov", "flicker_bank",
           "random_walk", "quantize"]
