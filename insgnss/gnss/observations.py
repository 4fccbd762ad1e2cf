"""From raw observations to per-satellite measurement rows, and the measurement model that
single-point positioning (:mod:`.spp`) and the tightly coupled filter
(:mod:`insgnss.filter.gnss_raw`) share.

Pseudorange and range rate of satellite s at receiver (antenna) position ``r``, velocity ``v``
(ECEF), receiver clock bias ``b`` [m] of the satellite's system and drift ``d`` [m/s]::

    P    = |x_s' - r| + b - c dt_s + T(el) + I(el, az) + e_P
    rdot = u . (v_s' - v) + d - c dt_s_dot + e_D            (rdot = -lambda * Doppler)

``x_s', v_s'`` are the satellite state at transmission rotated into the ECEF frame of the
reception (Earth rotation during the travel time, :func:`.corrections.geometry`), ``u`` the
unit line of sight receiver -> satellite, ``dt_s`` the satellite clock with the relativistic
term and the signal's group delay (:mod:`.ephemeris`), ``T`` the troposphere and ``I`` the
broadcast ionosphere (:mod:`.corrections`). The transmission time ``t_tx = t_rx - P / c - dt_s``
does not depend on the receiver clock (``P`` contains it), so the satellite states are computed
once per row (:func:`prepare_observations`).

Variances (:func:`pseudorange_variance`, :func:`range_rate_variance`)::

    sigma_P^2 = a^2 + b^2 / sin^2(el) + c^2 10^((cn0_ref - cn0) / 10) + URA^2 + var_I + var_T
    sigma_D^2 = a_d^2 + b_d^2 / sin^2(el) + c_d^2 10^((cn0_ref - cn0) / 10)

(elevation term as RTKLIB's; the C/N0 term follows the code-tracking noise, whose variance is
proportional to ``1 / (C/N0)``, Kaplan & Hegarty 2017 eq. 8.84 / SIGMA-epsilon, Hartinger &
Brunner 1999).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..earth import geodetic_to_ecef
from ..errors import InputFormatError
from .constants import C_LIGHT
from .corrections import day_of_year, geometry, iono_variance, klobuchar_delay, tropo_delay, tropo_variance
from .ephemeris import assign_ephemeris, group_delay, satellite_states

#: columns of the prepared measurement table (one row per epoch and satellite)
PREPARED_COLUMNS = ["sat", "system", "signal", "freq", "pr", "doppler", "cn0", "pr_std",
                    "doppler_std", "lock_time", "eph_row", "t_tx", "sat_x", "sat_y", "sat_z",
                    "sat_vx", "sat_vy", "sat_vz", "sat_clock", "sat_clock_rate", "ura"]

#: default signal of each system, in order of preference (single frequency; BeiDou B3I is the
#: reference signal of the broadcast BDS clock, so needs no group delay)
DEFAULT_SIGNALS = {"G": ("1C",), "E": ("1C",), "C": ("6I", "2I"), "J": ("1C",)}


@dataclass
class GnssModelConfig:
    """Selection, masks and noise model of the raw GNSS measurements.

    Parameters
    ----------
    signals : dict
        ``{system: (signal, ...)}``: systems used and their signals in order of preference.
    elevation_mask : float
        [rad] (default 10 deg).
    cn0_mask : float
        Minimum C/N0 [dB-Hz] (default 25: below it code tracking of a handheld antenna is
        dominated by multipath and cross-correlation).
    code_a, code_b, code_c : float
        Pseudorange noise terms [m]: constant, elevation-dependent (``/ sin el``) and C/N0
        dependent (``10^((cn0_ref - cn0)/20)``).
    doppler_a, doppler_b, doppler_c : float
        The same for the range rate [m/s].
    cn0_ref : float
        C/N0 of the C/N0 term's unit amplitude [dB-Hz].
    causal_ephemeris : bool
        Use only ephemerides received before each epoch.
    iono : {"klobuchar", "none"}
        Broadcast ionosphere model (``"none"``: no correction, variance ``(5 m)^2``).
    """

    signals: dict = field(default_factory=lambda: dict(DEFAULT_SIGNALS))
    elevation_mask: float = np.radians(10.0)
    cn0_mask: float = 25.0
    code_a: float = 0.3
    code_b: float = 0.3
    code_c: float = 1.0
    doppler_a: float = 0.02
    doppler_b: float = 0.02
    doppler_c: float = 0.05
    cn0_ref: float = 45.0
    causal_ephemeris: bool = False
    iono: str = "klobuchar"


def prepare_observations(obs: pd.DataFrame, eph: pd.DataFrame,
                         config: GnssModelConfig | None = None) -> pd.DataFrame:
    """One measurement row per (epoch, satellite): the preferred signal with a valid
    pseudorange and a usable ephemeris, and the satellite state at transmission time.

    Parameters
    ----------
    obs : DataFrame
        Observation table (:func:`insgnss.gnss.read_ubx`, :func:`insgnss.gnss.read_rinex_obs`).
    eph : DataFrame
        Ephemeris table (:func:`insgnss.gnss.decode_subframes`, :func:`~.rinex.read_rinex_nav`).

    Returns
    -------
    DataFrame
        Index ``time`` [GPS s] (repeated per satellite), columns :data:`PREPARED_COLUMNS`
        (satellite position/velocity ECEF at ``t_tx`` in the frame of ``t_tx`` [m, m/s],
        ``sat_clock`` [s] with relativistic term and group delay, ``sat_clock_rate`` [s/s],
        ``ura`` [m]). Rows below the C/N0 mask are dropped; the elevation mask needs the
        receiver position and is applied by the users of the table.
    """
    cfg = config or GnssModelConfig()
    for c in ("sat", "system", "signal", "pr", "doppler", "cn0", "freq"):
        if c not in obs.columns:
            raise InputFormatError("observation table lacks a column", column=c,
                                   file=obs.attrs.get("source"))
    t = np.asarray(obs.index, float)
    keep = np.zeros(len(obs), bool)
    rank = np.full(len(obs), 99)
    sig = obs["signal"].to_numpy(object)
    sysl = obs["system"].to_numpy(object)
    for s, sigs in cfg.signals.items():
        for k, g in enumerate(sigs):
            m = (sysl == s) & (sig == g)
            rank[m] = k
            keep |= m
    pr = obs["pr"].to_numpy(float)
    valid = keep & np.isfinite(pr) & (pr > 1e7) & (pr < 5e7)
    if "pr_valid" in obs.columns:
        valid &= obs["pr_valid"].to_numpy(bool)
    valid &= obs["cn0"].to_numpy(float) >= cfg.cn0_mask
    sub = obs[valid].copy()
    sub["_rank"] = rank[valid]
    sub["_t"] = t[valid]
    sub["eph_row"] = assign_ephemeris(eph, sub["_t"], sub["sat"], sub["signal"],
                                      causal=cfg.causal_ephemeris)
    sub = sub[sub["eph_row"] >= 0]
    # preferred signal per epoch and satellite
    sub = sub.sort_values(["_t", "sat", "_rank"], kind="stable")
    sub = sub[~sub.duplicated(["_t", "sat"])]
    rows = sub["eph_row"].to_numpy(np.int64)
    tt = sub["_t"].to_numpy(float)
    pr = sub["pr"].to_numpy(float)
    gd = np.empty(rows.size)
    for s in pd.unique(sub["system"]):
        m = (sub["system"] == s).to_numpy()
        for g in pd.unique(sub["signal"][m]):
            mm = m & (sub["signal"] == g).to_numpy()
            gd[mm] = group_delay(s, eph.iloc[rows[mm]], g)
    # transmission time: t_tx = t_rx - P/c - dt_s(t_tx) (one fixed-point step is exact to ps)
    t_tx = tt - pr / C_LIGHT
    st = satellite_states(eph, rows, t_tx)
    t_tx = t_tx - (st["clock"] - gd)
    st = satellite_states(eph, rows, t_tx)
    out = pd.DataFrame({
        "sat": sub["sat"].to_numpy(object), "system": sub["system"].to_numpy(object),
        "signal": sub["signal"].to_numpy(object), "freq": sub["freq"].to_numpy(float),
        "pr": pr, "doppler": sub["doppler"].to_numpy(float), "cn0": sub["cn0"].to_numpy(float),
        "pr_std": _col(sub, "pr_std"), "doppler_std": _col(sub, "doppler_std"),
        "lock_time": _col(sub, "lock_time"), "eph_row": rows, "t_tx": t_tx,
        "sat_x": st["pos"][:, 0], "sat_y": st["pos"][:, 1], "sat_z": st["pos"][:, 2],
        "sat_vx": st["vel"][:, 0], "sat_vy": st["vel"][:, 1], "sat_vz": st["vel"][:, 2],
        "sat_clock": st["clock"] - gd, "sat_clock_rate": st["clock_rate"],
        "ura": eph["ura"].to_numpy(float)[rows],
    }, index=pd.Index(tt, name="time"))
    out.attrs.update(obs.attrs)
    out.attrs["format"] = "gnss_prepared"
    return out


def _col(df, name):
    return df[name].to_numpy(float) if name in df.columns else np.full(len(df), np.nan)


def klobuchar_parameters(ion: pd.DataFrame | None):
    """(alpha, beta) of the latest GPS broadcast Klobuchar set in an ionosphere table
    (LNAV or CNAV), or None."""
    if ion is None or len(ion) == 0:
        return None
    g = ion[(ion["system"] == "G") & ion["alpha0"].notna()]
    if g.empty:
        return None
    r = g.iloc[-1]
    return (tuple(float(r[f"alpha{k}"]) for k in range(4)),
            tuple(float(r[f"beta{k}"]) for k in range(4)))


@dataclass
class EpochModel:
    """Predicted measurements of the satellites of one epoch at a receiver state (ECEF)."""

    rho: np.ndarray  #: geometric range [m]
    los: np.ndarray  #: (N, 3) unit line of sight receiver -> satellite (ECEF)
    el: np.ndarray  #: elevation [rad]
    az: np.ndarray  #: azimuth [rad]
    tropo: np.ndarray  #: slant tropospheric delay [m]
    tropo_dh: np.ndarray  #: its derivative with the receiver height [m/m]
    iono: np.ndarray  #: ionospheric delay [m]
    pr: np.ndarray  #: predicted pseudorange without the receiver clock [m]
    rate: np.ndarray  #: predicted range rate without receiver velocity and drift [m/s]
    sat_vel: np.ndarray  #: (N, 3) satellite velocity in the reception frame
    var_pr: np.ndarray  #: pseudorange variance [m^2]
    var_rate: np.ndarray  #: range-rate variance [m^2/s^2]


def epoch_model(rows, r_rx, lat: float, lon: float, h: float, t: float,
                iono_params, config: GnssModelConfig, doy: float | None = None,
                atmosphere: bool = True) -> EpochModel:
    """Evaluate the measurement model for the rows of one epoch (see the module docstring).

    ``rows`` maps the :data:`PREPARED_COLUMNS` to arrays (a slice of the prepared table, or
    the dict of :func:`epoch_arrays`).

    ``atmosphere=False`` skips troposphere and ionosphere (first iterations of a position
    solution started far from the truth, where elevations are meaningless).
    """
    sp = np.column_stack([np.asarray(rows[c], float) for c in ("sat_x", "sat_y", "sat_z")])
    sv = np.column_stack([np.asarray(rows[c], float) for c in ("sat_vx", "sat_vy", "sat_vz")])
    rho, los, el, az, _, v_rot = geometry(np.asarray(r_rx, float), sp, sv, lat, lon)
    if atmosphere:
        doy = doy if doy is not None else day_of_year(t)
        tr = tropo_delay(el, lat, h, doy)
        tr_dh = tropo_delay(el, lat, h + 1.0, doy) - tr
        if iono_params is not None and config.iono == "klobuchar":
            io = klobuchar_delay(lat, lon, el, az, np.mod(t, 604800.0), iono_params[0],
                                 iono_params[1], np.asarray(rows["freq"], float))
            vio = iono_variance(io)
        else:
            io = np.zeros(rho.size)
            vio = np.full(rho.size, 25.0)
        vtr = tropo_variance(el)
    else:
        tr = io = tr_dh = np.zeros(rho.size)
        vio = vtr = np.zeros(rho.size)
    clk = np.asarray(rows["sat_clock"], float)
    pr = rho - C_LIGHT * clk + tr + io
    rate = np.einsum("ij,ij->i", los, v_rot) - C_LIGHT * np.asarray(rows["sat_clock_rate"], float)
    cn0 = np.asarray(rows["cn0"], float)
    ura = np.asarray(rows["ura"], float)
    var_pr = pseudorange_variance(el, cn0, config) + np.where(np.isfinite(ura), ura, 10.0) ** 2 \
        + vio + vtr
    var_rate = range_rate_variance(el, cn0, config)
    return EpochModel(rho, los, el, az, tr, tr_dh, io, pr, rate, v_rot, var_pr, var_rate)


def epoch_arrays(prepared: pd.DataFrame) -> tuple[np.ndarray, dict]:
    """Epoch start indices (with the end appended) and the prepared table as a dict of numpy
    arrays, for fast per-epoch slicing (``{c: a[i0:i1] for c, a in arrays.items()}``)."""
    times = np.asarray(prepared.index, float)
    starts = np.r_[0, np.nonzero(np.diff(times))[0] + 1, times.size] if times.size else \
        np.zeros(1, np.int64)
    arrays = {c: prepared[c].to_numpy() for c in prepared.columns}
    arrays["time"] = times
    return starts, arrays


def _el_cn0_variance(el, cn0, a, b, c, cn0_ref):
    s = np.maximum(np.sin(np.asarray(el, float)), 0.05)
    return a**2 + (b / s) ** 2 + c**2 * 10.0 ** ((cn0_ref - np.asarray(cn0, float)) / 10.0)


def pseudorange_variance(el, cn0, config: GnssModelConfig) -> np.ndarray:
    """Receiver noise + multipath variance of a pseudorange [m^2] (elevation and C/N0 terms)."""
    return _el_cn0_variance(el, cn0, config.code_a, config.code_b, config.code_c, config.cn0_ref)


def range_rate_variance(el, cn0, config: GnssModelConfig) -> np.ndarray:
    """Variance of a Doppler range rate [m^2/s^2] (elevation and C/N0 terms)."""
    return _el_cn0_variance(el, cn0, config.doppler_a, config.doppler_b, config.doppler_c,
                            config.cn0_ref)


def keep_highest_satellites(prepared: pd.DataFrame, windows, n: int,
                            positions: pd.DataFrame) -> pd.DataFrame:
    """Inside the time ``windows`` keep only the ``n`` highest satellites of each epoch (the
    partial-outage experiment: a tight filter sees a few satellites where a loose
    one has no fix).

    Parameters
    ----------
    prepared : DataFrame
        :func:`prepare_observations` output.
    windows : sequence of (start, end)
        Times in the prepared table's time base; rows with ``start <= t < end`` are thinned.
    n : int
        Satellites kept per epoch inside the windows (highest elevation first).
    positions : DataFrame
        Receiver ``lat lon height`` [rad, m] by time (e.g. the SPP solution), used at the
        nearest time for the elevations.

    Returns
    -------
    DataFrame
        The rows kept; ``attrs["thinned_rows"]`` counts the rows removed.
    """
    if n < 0:
        raise ValueError("n must be >= 0")
    times = np.asarray(prepared.index, float)
    inside = np.zeros(times.size, bool)
    for a, b in windows:
        inside |= (times >= a) & (times < b)
    keep = np.ones(times.size, bool)
    if inside.any():
        if positions.empty:
            raise InputFormatError("no receiver positions to rank the satellites by elevation")
        pt = np.asarray(positions.index, float)
        starts, arr = epoch_arrays(prepared)
        for k in range(starts.size - 1):
            i0, i1 = starts[k], starts[k + 1]
            if not inside[i0]:
                continue
            j = int(np.argmin(np.abs(pt - times[i0])))
            lat, lon, h = (float(positions[c].iloc[j]) for c in ("lat", "lon", "height"))
            r = np.array(geodetic_to_ecef(lat, lon, h))
            sp = np.column_stack([arr[c][i0:i1] for c in ("sat_x", "sat_y", "sat_z")])
            el = geometry(r, sp, np.zeros_like(sp), lat, lon)[2]
            order = np.argsort(-el)
            keep[i0:i1] = False
            keep[i0 + order[:n]] = True
    out = prepared[keep]
    out.attrs.update(prepared.attrs)
    out.attrs["thinned_rows"] = int((~keep).sum())
    return out
