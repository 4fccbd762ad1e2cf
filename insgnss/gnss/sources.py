"""Raw GNSS inputs of a job: a UBX stream, or RINEX observation + navigation files, read and
decoded into observations, ephemerides and ionosphere parameters; and the loosely coupled GNSS
table computed from them by single-point positioning (the ``format = "ubx"`` GNSS input)."""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from .navmsg import decode_subframes
from .rinex import read_rinex_nav, read_rinex_obs
from .spp import SppConfig, spp
from .ubx import read_ubx


@dataclass
class RawGnss:
    """Observations, broadcast ephemerides and ionosphere parameters of one receiver
    (plus the receiver's own fix, when the stream has one)."""

    observations: pd.DataFrame
    ephemeris: pd.DataFrame
    ionosphere: pd.DataFrame
    receiver_fix: pd.DataFrame | None = None

    @classmethod
    def from_rinex(cls, obs_path, nav_path) -> RawGnss:
        """From a RINEX 3 observation file and a RINEX 3 navigation file."""
        eph, ion = read_rinex_nav(nav_path)
        return cls(read_rinex_obs(obs_path), eph, ion)


def load_ubx(path) -> RawGnss:
    """Read a UBX stream and decode its navigation words (:func:`~.ubx.read_ubx`,
    :func:`~.navmsg.decode_subframes`)."""
    d = read_ubx(path)
    eph, ion = decode_subframes(d.subframes)
    return RawGnss(d.observations, eph, ion, d.nav_pvt)


def spp_gnss_table(raw: RawGnss, config: SppConfig | None = None) -> pd.DataFrame:
    """The single-point solution of ``raw`` as a GNSS table (``lat lon height``,
    ``east_std north_std up_std``, ``vel_*`` and ``vel_*_std``, ``q = 5``, ``ns``, plus the
    clock, DOP and fault-detection columns of :func:`~.spp.spp`)."""
    sol = spp(raw.observations, raw.ephemeris, raw.ionosphere, config).solution
    sol.attrs["format"] = "spp"
    return sol
