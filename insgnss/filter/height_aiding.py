"""Height aiding for pedestrians: a level-floor constraint between stances and barometric height.

Both are measurement models in the style of :mod:`.measurements`: given the nominal state at
one of their epochs they return ``(z, H, R)`` (or ``None``), with ``z = h(nominal) - measured``
and the nominal-minus-true error convention, so ``z = H dx + noise``; the up position error is
state 2 of the core layout.

Level floor (:class:`LevelFloor`)
---------------------------------
A foot-mounted INS is released into every swing from a stance and lands in the next one; on a
flat floor the two stances are at the same height. At the end of stance ``j-1`` the model
records the nominal height ``h_ref``; at the first epoch of stance ``j``::

    z = h_nom - h_ref,   H = [0 0 1 0 ...],   R = sigma_floor^2

unless the change is a stair step: ``|z| > max_step`` **and** ``|z| > max_slope L``, with ``L``
the horizontal distance between the two stances. Then the foot went up or down a step (stairs,
a kerb), nothing is applied and stance ``j`` becomes the new reference. The slope separates a
stair from the INS's own height error on a long stride: every stair rises at least ``0.36 L``
(riser/tread of building-code stairs, 10-20 cm over 25-28 cm; 0.22 for shallow garden steps),
while a running foot INS loses up to 0.15 L (up to 24 cm over 1.6-1.9 m strides on the PyShoe
running trials, docs/zupt.md section 7); ``max_slope = 0.2`` lies between them and above the
steepest walkable ramps (1:12, 1:8 for a short kerb ramp). ``h_ref`` is an earlier estimate of
the same trajectory, so the constraint is relative (Groves 2013 section 16.2.5, "height
constraints"; Park and Suh 2011 estimate the floor inclination instead). Ramps are flattened:
the constraint is for walks known to be on one level (off by default in a job).

Barometric height (:class:`BaroHeight`)
--------------------------------------
``z = h_nom + b_nom - h_baro``, ``H_up = 1``, ``H_b = 1`` with ``b`` the barometer offset
(pressure altitude minus ellipsoidal height plus weather drift), a random-walk extra state.
A pressure ``p`` [Pa] becomes the ISA pressure altitude (:func:`insgnss.earth.pressure_altitude`,
ICAO standard atmosphere, troposphere)::

    h_baro = T0 / L (1 - (p / p0) ** (R L / (g0 M)))   T0 = 288.15 K, L = 0.0065 K/m,
                                                      p0 = 101325 Pa, exponent 0.190263

Only height differences matter (the offset state absorbs the rest), for which the ISA formula
is accurate to about 1 % of the height change at moderate temperatures.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from ..earth import PRESSURE_RANGE, pressure_altitude
from ..errors import InputFormatError, InvalidValueError
from .measurements import Measurement
from .models import ExtraState

#: IMU-table columns a barometer may come in: height [m] or static pressure [Pa]
BARO_COLUMNS = ("baro_height", "pressure")


class LevelFloor(Measurement):
    """Successive stances at the same height (see the module docstring).

    Parameters
    ----------
    stances : sequence of (t_start, t_end)
        Stance intervals [s] in time order (e.g. ``Stillness.intervals()``).
    std : float
        Floor flatness plus stance repeatability from one stance to the next [m]: a few mm on
        a flat floor. It must be small against the INS's real per-stride height error (mm to
        cm): the filter's own height variance grows far less per stride, so a loose
        constraint barely moves it (a 100 Hz simulated walk with 0.5 % climb: 94 mm without,
        41 mm with 5 mm, 18 mm with 2 mm after 28 m).
    max_step : float
        Height change between two stances below which the constraint always applies [m].
    max_slope : float
        Height change per metre of horizontal stance-to-stance distance below which it also
        applies (a change above both is a stair step and is skipped). ``inf``: only
        ``max_step`` decides.
    """

    name = "level_floor"

    def __init__(self, stances: Sequence[tuple[float, float]], std: float = 0.002,
                 max_step: float = 0.05, max_slope: float = 0.2,
                 gate_probability: float | None = 0.0, name: str | None = None):
        st = np.asarray(stances, float).reshape(-1, 2)
        if st.size and (not np.all(np.isfinite(st)) or np.any(st[:, 1] < st[:, 0])
                        or np.any(st[1:, 0] < st[:-1, 1])):
            raise InvalidValueError("LevelFloor: stances must be finite, ordered intervals")
        if not (np.isfinite(std) and std > 0 and np.isfinite(max_step) and max_step > 0
                and max_slope >= 0 and not np.isnan(max_slope)):
            raise InvalidValueError("LevelFloor: std and max_step must be positive, max_slope"
                                    " not negative")
        # epochs: the end of each stance (record) and the start of the next ones (compare)
        super().__init__(np.unique(np.concatenate([st[:, 1], st[1:, 0]])), gate_probability,
                         name)
        self._is_end = np.isin(self.times, st[:, 1])
        self._is_start = np.isin(self.times, st[1:, 0])
        self.std = float(std)
        self.max_step = float(max_step)
        self.max_slope = float(max_slope)
        self._ref: tuple[float, float, float] | None = None  # lat, lon, height at stance end
        self.applied = 0
        self.skipped = 0

    def evaluate(self, i, nav):
        out = None
        if self._is_start[i] and self._ref is not None:
            d = nav.enu_offset(*self._ref)
            z = d[2]
            if abs(z) <= self.max_step or abs(z) <= self.max_slope * np.hypot(d[0], d[1]):
                H = np.zeros((1, nav.layout.n))
                H[0, 2] = 1.0
                out = (np.array([z]), H, np.array([[self.std**2]]))
                self.applied += 1
            else:
                self.skipped += 1
        if self._is_end[i]:
            self._ref = (float(nav.lat), float(nav.lon), float(nav.height))
        return out


class BaroHeight(Measurement):
    """Barometric height with an offset state (see the module docstring).

    Parameters
    ----------
    data : DataFrame
        Indexed by time [s] with ``baro_height`` [m] or ``pressure`` [Pa].
    std : float
        Height noise of one reading [m].
    interval : float
        Use one reading per this many seconds (0: every reading); barometer noise is
        time-correlated, so fast updates over-weight it.
    offset_std : float
        Initial sigma of the offset state [m] (the first update fixes it).
    offset_psd : float
        Random-walk PSD of the offset [m^2/s]: 1e-5 lets it wander 0.19 m in an hour, 2 cm in
        a minute (weather trends are of the order of 1 hPa, 8 m, in 3 h). The INS must admit
        its own height drift for the barometer to correct it: ZUPT alone keeps the filter's
        height variance at mm level while a foot INS drifts by ~1 % of the distance, so the
        foot filter needs a per-stride height noise of that size (see docs/zupt.md).
    """

    name = "baro"
    state = "baro_offset"

    def __init__(self, data: pd.DataFrame, std: float = 0.2, interval: float = 0.5,
                 offset_std: float = 1.0e3, offset_psd: float = 1.0e-5,
                 gate_probability: float | None = None, name: str | None = None):
        if "baro_height" in data.columns:
            h = data["baro_height"].to_numpy(float)
            col = "baro_height"
        elif "pressure" in data.columns:
            p = data["pressure"].to_numpy(float)
            bad = np.flatnonzero(~((p >= PRESSURE_RANGE[0]) & (p <= PRESSURE_RANGE[1])))
            if bad.size:
                raise InvalidValueError(f"implausible pressure at t = {data.index[bad[0]]} s",
                                        column="pressure", expected="20-110 kPa, in Pa",
                                        found=repr(float(p[bad[0]])))
            h = pressure_altitude(p)
            col = "pressure"
        else:
            raise InputFormatError("no barometer column", expected="baro_height or pressure",
                                   found=", ".join(map(str, data.columns)))
        t = np.asarray(data.index, float)
        ok = np.isfinite(h) & np.isfinite(t)
        t, h = t[ok], h[ok]
        if interval > 0 and t.size:
            keep = np.concatenate([[True], np.diff(np.floor((t - t[0]) / interval)) > 0])
            t, h = t[keep], h[keep]
        super().__init__(t, gate_probability, name)
        self.height = h
        self.source_column = col
        self.std = float(std)
        self.offset_std = float(offset_std)
        self.offset_psd = float(offset_psd)

    def extra_states(self):
        return [ExtraState(self.state, 1, self.offset_std, np.inf, self.offset_psd)]

    def evaluate(self, i, nav):
        s = nav.layout[self.state]
        b = nav.param(self.state)[0]
        H = np.zeros((1, nav.layout.n))
        H[0, 2] = 1.0
        H[0, s.start] = 1.0
        return (np.array([nav.height + b - self.height[i]]), H, np.array([[self.std**2]]))


__all__ = ["BARO_COLUMNS", "BaroHeight", "LevelFloor"]
