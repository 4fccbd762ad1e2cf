"""GNSS constants: speed of light, carrier frequencies, system identifiers and the per-system
orbit constants of the broadcast ephemeris.

Systems are named by their RINEX 3 letter: ``G`` GPS, ``E`` Galileo, ``C`` BeiDou, ``J`` QZSS,
``R`` GLONASS, ``S`` SBAS, ``I`` NavIC. Signals are named by their RINEX 3 observation code
without the type letter (``"1C"`` GPS L1 C/A, ``"6I"`` BeiDou B3I, ...).

References
----------
- IS-GPS-200N (2022), Table 20-IV (mu, Omega_e, F) and 30.3.3.1.3 (CNAV A_ref, Omega_dot_ref).
- Galileo OS SIS ICD Issue 2.1 (2023), 5.1.1 (mu, Omega_e).
- BeiDou SIS ICD B3I 1.0 (2018), 5.2.4.10 (CGCS2000 mu, Omega_e).
- RINEX 3.05, 5.1 (observation codes).
"""

from __future__ import annotations

import numpy as np

#: speed of light [m/s]
C_LIGHT = 299792458.0

#: UBX gnssId -> RINEX system letter
UBX_SYSTEMS = {0: "G", 1: "S", 2: "E", 3: "C", 5: "J", 6: "R", 7: "I"}

#: (UBX gnssId, sigId) -> RINEX 3 signal code (frequency band + attribute)
UBX_SIGNALS = {
    (0, 0): "1C", (0, 3): "2L", (0, 4): "2S", (0, 6): "5I", (0, 7): "5Q",
    (1, 0): "1C",
    (2, 0): "1C", (2, 1): "1B", (2, 3): "5I", (2, 4): "5Q", (2, 5): "7I", (2, 6): "7Q",
    (2, 8): "6B", (2, 9): "6C",
    (3, 0): "2I", (3, 1): "2I", (3, 2): "7I", (3, 3): "7I", (3, 4): "6I", (3, 5): "1P",
    (3, 6): "1D", (3, 7): "5P", (3, 8): "5D", (3, 10): "6I",
    (5, 0): "1C", (5, 1): "1Z", (5, 4): "2S", (5, 5): "2L", (5, 8): "5I", (5, 9): "5Q",
    (6, 0): "1C", (6, 2): "2C",
    (7, 0): "5A",
}

F_L1 = 1575.42e6  #: GPS L1, Galileo E1, BeiDou B1C, QZSS L1 [Hz]
F_L2 = 1227.60e6  #: GPS/QZSS L2 [Hz]
F_L5 = 1176.45e6  #: GPS/QZSS L5, Galileo E5a, BeiDou B2a [Hz]
F_E5B = 1207.14e6  #: Galileo E5b, BeiDou B2I/B2b [Hz]
F_E6 = 1278.75e6  #: Galileo E6, QZSS L6 [Hz]
F_B1I = 1561.098e6  #: BeiDou B1I [Hz]
F_B3I = 1268.52e6  #: BeiDou B3I [Hz]

#: (system, band digit) -> carrier frequency [Hz] (GLONASS FDMA handled in :func:`carrier_frequency`)
_BANDS = {
    ("G", "1"): F_L1, ("G", "2"): F_L2, ("G", "5"): F_L5,
    ("J", "1"): F_L1, ("J", "2"): F_L2, ("J", "5"): F_L5, ("J", "6"): F_E6,
    ("S", "1"): F_L1, ("S", "5"): F_L5,
    ("E", "1"): F_L1, ("E", "5"): F_L5, ("E", "7"): F_E5B, ("E", "6"): F_E6,
    ("E", "8"): 1191.795e6,
    ("C", "2"): F_B1I, ("C", "1"): F_L1, ("C", "5"): F_L5, ("C", "7"): F_E5B,
    ("C", "6"): F_B3I, ("C", "8"): 1191.795e6,
    ("I", "5"): F_L5, ("I", "9"): 2492.028e6,
}


def carrier_frequency(system: str, signal: str, glonass_k: int | float = np.nan) -> float:
    """Carrier frequency [Hz] of a signal (``system`` letter, RINEX code such as ``"1C"``).

    GLONASS FDMA bands need the frequency channel ``glonass_k`` (-7..6). Returns NaN for an
    unknown band.
    """
    band = signal[:1]
    if system == "R":
        if band == "1":
            return 1602.0e6 + glonass_k * 0.5625e6
        if band == "2":
            return 1246.0e6 + glonass_k * 0.4375e6
        return {"3": 1202.025e6, "4": 1600.995e6, "6": 1248.06e6}.get(band, np.nan)
    return _BANDS.get((system, band), np.nan)


#: Earth gravitational constant used by each system's ephemeris [m^3/s^2]
MU = {"G": 3.986005e14, "J": 3.986005e14, "E": 3.986004418e14, "C": 3.986004418e14,
      "I": 3.986005e14}
#: Earth rotation rate used by each system's ephemeris [rad/s]
OMEGA_E = {"G": 7.2921151467e-5, "J": 7.2921151467e-5, "E": 7.2921151467e-5,
           "C": 7.2921150e-5, "I": 7.2921151467e-5}
#: WGS84 Earth rotation rate for the Sagnac correction (Earth rotation during signal travel)
OMEGA_E_WGS84 = 7.2921151467e-5
#: relativistic clock constant ``F = -2 sqrt(mu) / c^2`` [s/m^0.5] (IS-GPS-200 20.3.3.3.3.1)
F_REL = {s: -2.0 * np.sqrt(mu) / C_LIGHT**2 for s, mu in MU.items()}

#: BeiDou time (BDT) = GPST - 14 s
BDT_MINUS_GPST = -14.0
#: BeiDou GEO satellites (PRNs), which use the rotated-frame orbit of BDS-SIS-ICD 5.2.4.12
BDS_GEO_PRNS = frozenset({1, 2, 3, 4, 5, 59, 60, 61, 62, 63})

#: GPS CNAV reference semi-major axis [m] and rate of right ascension [semicircles/s]
CNAV_A_REF = 26559710.0
CNAV_OMEGA_DOT_REF = -2.6e-9

#: largest |t - toe| for which a broadcast ephemeris is used [s] (half the fit interval, or
#: the validity the system's ICD states: GPS 4 h fit, Galileo 4 h, BeiDou 1 h updates)
MAX_EPHEMERIS_AGE = {"G": 7200.0, "J": 7200.0, "E": 14400.0, "C": 21600.0, "I": 7200.0}


def satellite_name(system: str, prn: int) -> str:
    """RINEX satellite name, e.g. ``G05``, ``E11``, ``C21``; SBAS PRN 120-158 -> ``S20``-``S58``,
    QZSS PRN 193-202 -> ``J01``-``J10``."""
    if system == "S" and prn >= 100:
        prn -= 100
    if system == "J" and prn >= 193:
        prn -= 192
    return f"{system}{prn:02d}"
