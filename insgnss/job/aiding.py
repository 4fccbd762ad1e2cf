"""Aiding measurements of a job (``[aiding]``, docs/jobs.md): the measurement models the filter
engine applies - GNSS position and velocity (outage windows withheld, quality flags weighted by
``q_scale``), ZUPT and ZARU at the detected or declared still times (speed gated), NHC, CUPT at
control points, odometer speed.

The models themselves (``z, H, R``) are in :mod:`insgnss.filter.measurements`; this module
builds them from the job and the data.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..config import Job
from ..errors import ConfigError, InputFormatError
from ..filter.measurements import BodyVelocity, Cupt, GnssPosition, GnssVelocity, Zaru, Zupt
from ..outages import in_windows
from ..validate import check_gnss_in_imu_span
from .inputs import Inputs


class SpeedGatedZupt(Zupt):
    """ZUPT applied only while the nominal speed is below ``max_speed``.

    An IMU stillness detector cannot tell steady straight motion from rest (both give constant
    specific force and no rotation; only vibration differs), so a vehicle at constant speed can
    be flagged still. The nominal speed of the filter (GNSS-aided, or a short dead-reckoning
    extrapolation during outages) resolves that ambiguity.
    """

    def __init__(self, times, std, max_speed: float, **kw):
        super().__init__(times, std=std, **kw)
        self.max_speed = float(max_speed)

    def evaluate(self, i, nav):
        if np.linalg.norm(nav.vel) > self.max_speed:
            return None
        return super().evaluate(i, nav)


class SpeedGatedZaru(Zaru):
    """ZARU applied only while the nominal speed is below ``max_speed`` (see SpeedGatedZupt)."""

    def __init__(self, times, max_speed: float, **kw):
        super().__init__(times, **kw)
        self.max_speed = float(max_speed)

    def evaluate(self, i, nav):
        if np.linalg.norm(nav.vel) > self.max_speed:
            return None
        return super().evaluate(i, nav)


def stillness_times(job: Job, imu: pd.DataFrame) -> np.ndarray:
    """Times (at the ZUPT interval) when the IMU is still, from the detector and/or declared
    static intervals."""
    a = job["aiding"]
    t = imu.index.to_numpy(float)
    still = np.zeros(t.size, bool)
    if a["detector"] or not a["static_intervals"]:
        from ..detect import DetectorConfig, detect_stillness

        cfg = DetectorConfig.from_dict(a["detector"]) if a["detector"] else \
            DetectorConfig(method="amv", window=0.5, threshold=0.1, min_stance=1.0, margin=0.3)
        still |= detect_stillness(imu, cfg).still.to_numpy(bool)
    for a0, a1 in a["static_intervals"] or []:
        still |= (t >= a0) & (t <= a1)
    ts = t[still]
    if not ts.size:
        return ts
    step = a["zupt_interval"]
    keep = np.concatenate([[True], np.diff(np.floor((ts - ts[0]) / step)) > 0])
    return ts[keep]


def build_measurements(job: Job, inputs: Inputs, windows, imu: pd.DataFrame) -> list:
    """Aiding measurement models of the job (GNSS with outages removed, ZUPT, ZARU, NHC, CUPT,
    odometer)."""
    a = job["aiding"]
    out = []
    gnss = inputs.gnss
    if gnss is not None and len(gnss):
        g = check_gnss_in_imu_span(gnss, imu, policy="trim")  # warns, names the file/lines
        # the initial position comes from the GNSS at the first IMU time: an epoch there would
        # be used twice (initial state and update), with correlated errors
        g = g[g.index > imu.index[0] + 1e-6]
        g = g[~in_windows(g.index.to_numpy(float), windows)]
        scale = {int(float(k)): float(v) for k, v in a["q_scale"].items()}
        use_q = list(scale) if "q" in g.columns else None
        if a["gnss_position"]:
            std = a["gnss_position_std"]
            if std is not None:
                g = g.drop(columns=[c for c in GnssPosition.STD_COLS if c in g.columns])
            kw = {"std": std} if std is not None else {}
            if a["gnss_std_scale"] != 1.0 and std is None:
                g = g.copy()
                for c in GnssPosition.STD_COLS:
                    g[c] = g[c] * a["gnss_std_scale"]
            out.append(GnssPosition(g, lever_arm=inputs.lever_arm, std_scale=scale if use_q
                                    else None, use_q=use_q, min_std=a["gnss_min_std"], **kw))
        if a["gnss_velocity"]:
            if "vel_e" not in g.columns:
                raise InputFormatError("GNSS velocity aiding requested but the GNSS data has no "
                                       "velocity", column="vel_e")
            std = a["gnss_velocity_std"]
            gv = g.drop(columns=[c for c in ("vel_e_std", "vel_n_std", "vel_u_std")
                                 if c in g.columns]) if std is not None else g
            out.append(GnssVelocity(gv, lever_arm=inputs.lever_arm,
                                    std_scale=scale if use_q else None, use_q=use_q,
                                    **({"std": std} if std is not None else {})))
    if a["zupt"] or a["zaru"]:
        ts = stillness_times(job, imu)
        if ts.size:
            vmax = a["zupt_max_speed"]
            if a["zupt"]:
                out.append(SpeedGatedZupt(ts, a["zupt_std"], vmax) if vmax else
                           Zupt(ts, std=a["zupt_std"]))
            if a["zaru"]:
                out.append(SpeedGatedZaru(ts, vmax) if vmax else Zaru(ts))
    if a["nhc"]:
        t = imu.index.to_numpy(float)
        tn = t[0] + np.arange(1, int((t[-1] - t[0]) / a["nhc_interval"])) * a["nhc_interval"]
        out.append(BodyVelocity(tn, 0.0, axes=(0, 2), std=a["nhc_std"], name="nhc",
                                misalignment_state="nhc_misalignment" if a["nhc_misalignment"]
                                else None))
    if a["cupt"]:
        if inputs.control_points is None:
            raise ConfigError("CUPT needs inputs.control_points.path", file=job.path,
                              column="aiding.cupt")
        out.append(Cupt.from_table(inputs.control_points,
                                   **({} if "east_std" in inputs.control_points.columns else
                                      {"std": job["inputs"]["control_points"]["std"]})))
    if a["odometer"]:
        if inputs.odometer is None or "speed" not in inputs.odometer.columns:
            raise ConfigError("odometer aiding needs an odometer speed table", file=job.path,
                              column="aiding.odometer")
        o = inputs.odometer
        o = o[(o.index > imu.index[0]) & (o.index <= imu.index[-1])]
        out.append(BodyVelocity(o.index.to_numpy(float), o["speed"].to_numpy(float), axes=(1,),
                                std=a["odometer_std"], scale_state="odometer_scale",
                                name="odometer"))
    return out


__all__ = ["SpeedGatedZaru", "SpeedGatedZupt", "build_measurements", "stillness_times"]
