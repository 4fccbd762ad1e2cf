"""Raw GNSS: readers (UBX, RINEX 3), broadcast navigation decoding, satellite orbits and
clocks, propagation corrections, single-point positioning, and the measurement rows of the
tightly coupled filter (:mod:`insgnss.filter.gnss_raw`). See docs/tight.md."""

from .navmsg import EPH_COLUMNS, ION_COLUMNS, decode_subframes
from .observations import PREPARED_COLUMNS, GnssModelConfig, prepare_observations
from .rinex import read_rinex_nav, read_rinex_obs
from .sources import RawGnss, load_ubx, spp_gnss_table
from .spp import SppConfig, SppResult, spp
from .ubx import OBS_COLUMNS, UbxData, read_ubx

__all__ = [
    "EPH_COLUMNS", "ION_COLUMNS", "OBS_COLUMNS", "PREPARED_COLUMNS", "GnssModelConfig", "RawGnss",
    "SppConfig", "SppResult", "UbxData", "decode_subframes", "load_ubx", "prepare_observations",
    "read_rinex_nav", "read_rinex_obs", "read_ubx", "spp", "spp_gnss_table",
]
