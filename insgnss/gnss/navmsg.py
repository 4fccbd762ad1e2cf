"""Broadcast navigation message decoding: raw data words (UBX-RXM-SFRBX) to ephemeris rows.

Decoded messages
----------------
- GPS / QZSS LNAV (L1 C/A subframes 1-3; subframe 4 page 18 for the Klobuchar parameters):
  IS-GPS-200N 20.3.3.3 - 20.3.3.5, Figures 20-1/20-2, Tables 20-I/20-III.
- GPS CNAV (L2C / L5 message types 10, 11 and 30; 30 also carries the Klobuchar parameters
  and the inter-signal corrections): IS-GPS-200N 30.3.3.1 - 30.3.3.3, IS-GPS-705J.
- Galileo I/NAV (E1-B nominal pages, word types 1-5, CRC-24Q checked): Galileo OS SIS ICD
  Issue 2.1, 4.3.5 and Table 40-47.
- BeiDou D1 (B1I/B3I MEO/IGSO subframes 1-3): BDS-SIS-ICD-B1I 3.0 / B3I 1.0, 5.2.3-5.2.4.
  GEO satellites (D2) are not decoded (none were in view of the test data).

u-blox delivers GPS LNAV words as 30-bit words with the 24 data bits in bits 29..6 (already
polarity-corrected; parity is not re-checked here, the IODE/IODC consistency of the three
subframes is), CNAV and Galileo pages MSB first in consecutive 32-bit words, and BeiDou D1
as 30-bit words (bits 29..0, info bits first, BCH parity after deinterleaving); see the
u-blox interface description, "Broadcast navigation data".

Times: ``toe``/``toc``/``time_received`` are GPS seconds on the GPST scale. Galileo GST is
taken equal to GPST (the broadcast GGTO, tens of ns, is ignored: it is absorbed by the
per-system receiver clock bias); BDT = GPST - 14 s. Week numbers are resolved from the
reception time (nearest week), so the 10-bit GPS week roll-over needs no special case.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import pandas as pd

from .constants import BDT_MINUS_GPST, CNAV_A_REF, CNAV_OMEGA_DOT_REF

#: columns of the ephemeris table (Keplerian broadcast orbits of GPS, Galileo, BeiDou, QZSS)
EPH_COLUMNS = [
    "sat", "system", "prn", "source", "time_received", "toe", "toc", "toe_sow", "iode", "iodc",
    "sqrt_a", "e", "i0", "omega0", "omega", "m0", "delta_n", "omega_dot", "idot",
    "cuc", "cus", "crc", "crs", "cic", "cis", "a_dot", "delta_n_dot",
    "af0", "af1", "af2", "tgd", "tgd2", "isc_1C", "isc_2L", "isc_5I", "isc_5Q", "health", "ura",
]
#: columns of the ionosphere-parameter table
ION_COLUMNS = ["system", "source", "alpha0", "alpha1", "alpha2", "alpha3", "beta0", "beta1",
               "beta2", "beta3", "ai0", "ai1", "ai2"]

SC = np.pi  # semicircles -> rad
WEEK = 604800.0

# GPS URA index -> nominal URA [m] (IS-GPS-200 20.3.3.3.1.3)
_URA_M = np.array([2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0,
                   1536.0, 3072.0, 6144.0, np.inf])


def ura_from_index(n: int) -> float:
    """GPS/BeiDou URA index -> metres (upper value of the range)."""
    return float(_URA_M[int(n)]) if 0 <= n < 16 else np.inf


def cnav_ura_from_index(n: int) -> float:
    """CNAV URA_ED index (-16..15) -> metres (IS-GPS-200 30.3.3.1.1.4)."""
    if n == 15:
        return np.inf
    return float(2.0 ** (1 + n / 2) if n <= 6 else 2.0 ** (n - 2))


def sisa_from_index(n: int) -> float:
    """Galileo SISA index -> metres (OS SIS ICD 5.1.12); 255 (no accuracy prediction) -> inf."""
    if n < 50:
        return n * 0.01
    if n < 75:
        return 0.5 + (n - 50) * 0.02
    if n < 100:
        return 1.0 + (n - 75) * 0.04
    if n < 126:
        return 2.0 + (n - 100) * 0.16
    return np.inf


class Bits:
    """Bit field access on a message given as an integer of ``nbits`` bits (MSB = bit 0)."""

    __slots__ = ("v", "n")

    def __init__(self, value: int, nbits: int):
        self.v = value
        self.n = nbits

    @classmethod
    def from_words(cls, words, bits_per_word: int = 32, shift: int = 0) -> Bits:
        """Concatenate ``bits_per_word`` bits of each word, taken above bit ``shift``."""
        v = 0
        mask = (1 << bits_per_word) - 1
        for w in words:
            v = (v << bits_per_word) | ((int(w) >> shift) & mask)
        return cls(v, bits_per_word * len(words))

    def u(self, pos: int, length: int) -> int:
        """Unsigned field of ``length`` bits starting at bit ``pos``."""
        return (self.v >> (self.n - pos - length)) & ((1 << length) - 1)

    def s(self, pos: int, length: int) -> int:
        """Two's-complement signed field."""
        x = self.u(pos, length)
        return x - (1 << length) if x >> (length - 1) else x

    def u2(self, p1, l1, p2, l2) -> int:
        """Unsigned field split in two parts (MSBs at ``p1``)."""
        return (self.u(p1, l1) << l2) | self.u(p2, l2)

    def s2(self, p1, l1, p2, l2) -> int:
        """Signed field split in two parts."""
        x = self.u2(p1, l1, p2, l2)
        n = l1 + l2
        return x - (1 << n) if x >> (n - 1) else x


def _crc24q_table() -> np.ndarray:
    t = np.zeros(256, np.uint32)
    for i in range(256):
        c = i << 16
        for _ in range(8):
            c <<= 1
            if c & 0x1000000:
                c ^= 0x1864CFB
        t[i] = c & 0xFFFFFF
    return t


_CRC24Q = _crc24q_table()


def crc24q(value: int, nbits: int) -> int:
    """CRC-24Q (polynomial 0x1864CFB, initial 0) of the ``nbits``-bit message ``value``
    (leading zero padding to whole bytes does not change a CRC with a zero initial value)."""
    nbytes = (nbits + 7) // 8
    crc = 0
    for b in value.to_bytes(nbytes, "big"):
        crc = ((crc << 8) & 0xFFFFFF) ^ int(_CRC24Q[(crc >> 16) ^ b])
    return crc


def nearest_week_time(sow: float, t_ref: float, offset: float = 0.0) -> float:
    """GPS seconds of the instant with seconds-of-week ``sow`` nearest to ``t_ref``.

    ``offset`` is (system time - GPST), e.g. -14 s for BDT: the week grid of the system
    time is used and the result is converted back to GPST.
    """
    s_ref = t_ref + offset
    week = np.round((s_ref - sow) / WEEK)
    return float(week * WEEK + sow - offset)


def _blank_row(sat, system, prn, source, t_rx) -> dict:
    row = dict.fromkeys(EPH_COLUMNS, 0.0)
    row.update(sat=sat, system=system, prn=int(prn), source=source, time_received=t_rx,
               isc_1C=np.nan, isc_2L=np.nan, isc_5I=np.nan, isc_5Q=np.nan, tgd2=np.nan,
               health=0)
    return row


# --- GPS / QZSS LNAV ---------------------------------------------------------------------------

def _lnav_bits(words) -> Bits:
    return Bits.from_words(words, 24, 6)


def decode_lnav(sf1: Bits, sf2: Bits, sf3: Bits, t_ref: float, sat: str, system: str,
                prn: int) -> dict | None:
    """Ephemeris row from LNAV subframes 1-3 (240 data bits each), or None if inconsistent."""
    if sf1.u(43, 3) != 1 or sf2.u(43, 3) != 2 or sf3.u(43, 3) != 3:
        return None
    iodc = (sf1.u(70, 2) << 8) | sf1.u(168, 8)
    iode2, iode3 = sf2.u(48, 8), sf3.u(216, 8)
    if not (iode2 == iode3 == (iodc & 0xFF)):
        return None
    r = _blank_row(sat, system, prn, "lnav", t_ref)
    r["ura"] = ura_from_index(sf1.u(60, 4))
    r["health"] = sf1.u(64, 6)
    tgd = sf1.s(160, 8)
    r["tgd"] = 0.0 if tgd == -128 else tgd * 2.0**-31  # -128: not available (IS-QZSS)
    toc_sow = sf1.u(176, 16) * 16.0
    r["af2"] = sf1.s(192, 8) * 2.0**-55
    r["af1"] = sf1.s(200, 16) * 2.0**-43
    r["af0"] = sf1.s(216, 22) * 2.0**-31
    r["iode"], r["iodc"] = iode2, iodc
    r["crs"] = sf2.s(56, 16) * 2.0**-5
    r["delta_n"] = sf2.s(72, 16) * 2.0**-43 * SC
    r["m0"] = sf2.s2(88, 8, 96, 24) * 2.0**-31 * SC
    r["cuc"] = sf2.s(120, 16) * 2.0**-29
    r["e"] = sf2.u2(136, 8, 144, 24) * 2.0**-33
    r["cus"] = sf2.s(168, 16) * 2.0**-29
    r["sqrt_a"] = sf2.u2(184, 8, 192, 24) * 2.0**-19
    toe_sow = sf2.u(216, 16) * 16.0
    r["cic"] = sf3.s(48, 16) * 2.0**-29
    r["omega0"] = sf3.s2(64, 8, 72, 24) * 2.0**-31 * SC
    r["cis"] = sf3.s(96, 16) * 2.0**-29
    r["i0"] = sf3.s2(112, 8, 120, 24) * 2.0**-31 * SC
    r["crc"] = sf3.s(144, 16) * 2.0**-5
    r["omega"] = sf3.s2(160, 8, 168, 24) * 2.0**-31 * SC
    r["omega_dot"] = sf3.s(192, 24) * 2.0**-43 * SC
    r["idot"] = sf3.s(224, 14) * 2.0**-43 * SC
    r["toe_sow"] = toe_sow
    r["toe"] = nearest_week_time(toe_sow, t_ref)
    r["toc"] = nearest_week_time(toc_sow, t_ref)
    return r


def decode_lnav_iono(sf4: Bits) -> dict | None:
    """Klobuchar parameters of LNAV subframe 4 page 18 (SV ID 56), or None."""
    if sf4.u(43, 3) != 4 or sf4.u(50, 6) != 56:
        return None
    return dict(alpha0=sf4.s(56, 8) * 2.0**-30, alpha1=sf4.s(64, 8) * 2.0**-27,
                alpha2=sf4.s(72, 8) * 2.0**-24, alpha3=sf4.s(80, 8) * 2.0**-24,
                beta0=sf4.s(88, 8) * 2.0**11, beta1=sf4.s(96, 8) * 2.0**14,
                beta2=sf4.s(104, 8) * 2.0**16, beta3=sf4.s(112, 8) * 2.0**16)


# --- GPS CNAV ------------------------------------------------------------------------------------

def cnav_message(words) -> Bits | None:
    """The 300-bit CNAV message of 10 UBX words if its preamble and CRC-24Q are right."""
    b = Bits.from_words(words, 32)
    b = Bits(b.v >> (b.n - 300), 300)
    if b.u(0, 8) != 0x8B or crc24q(b.v >> 24, 276) != b.u(276, 24):
        return None
    return b


def decode_cnav(mt10: Bits, mt11: Bits, mt30: Bits, t_ref: float, sat: str, system: str,
                prn: int) -> dict | None:
    """Ephemeris row from CNAV message types 10, 11 and a clock message 30 with equal toe/toc."""
    toe10, toe11 = mt10.u(70, 11) * 300.0, mt11.u(38, 11) * 300.0
    toc = mt30.u(60, 11) * 300.0
    if toe10 != toe11 or toc != toe10:
        return None
    r = _blank_row(sat, system, prn, "cnav", t_ref)
    r["health"] = mt10.u(51, 3)  # L1, L2, L5 health bits
    r["ura"] = cnav_ura_from_index(mt10.s(65, 5))
    a0 = CNAV_A_REF + mt10.s(81, 26) * 2.0**-9
    r["sqrt_a"] = np.sqrt(a0)
    r["a_dot"] = mt10.s(107, 25) * 2.0**-21
    r["delta_n"] = mt10.s(132, 17) * 2.0**-44 * SC
    r["delta_n_dot"] = mt10.s(149, 23) * 2.0**-57 * SC
    r["m0"] = mt10.s(172, 33) * 2.0**-32 * SC
    r["e"] = mt10.u(205, 33) * 2.0**-34
    r["omega"] = mt10.s(238, 33) * 2.0**-32 * SC
    r["omega0"] = mt11.s(49, 33) * 2.0**-32 * SC
    r["i0"] = mt11.s(82, 33) * 2.0**-32 * SC
    r["omega_dot"] = (CNAV_OMEGA_DOT_REF + mt11.s(115, 17) * 2.0**-44) * SC
    r["idot"] = mt11.s(132, 15) * 2.0**-44 * SC
    r["cis"] = mt11.s(147, 16) * 2.0**-30
    r["cic"] = mt11.s(163, 16) * 2.0**-30
    r["crs"] = mt11.s(179, 24) * 2.0**-8
    r["crc"] = mt11.s(203, 24) * 2.0**-8
    r["cus"] = mt11.s(227, 21) * 2.0**-30
    r["cuc"] = mt11.s(248, 21) * 2.0**-30
    r["af0"] = mt30.s(71, 26) * 2.0**-35
    r["af1"] = mt30.s(97, 20) * 2.0**-48
    r["af2"] = mt30.s(117, 10) * 2.0**-60

    def gd(pos):  # group delays: -4096 (1000000000000b) means "not available"
        v = mt30.s(pos, 13)
        return np.nan if v == -4096 else v * 2.0**-35

    r["tgd"] = gd(127)
    r["isc_1C"], r["isc_2L"], r["isc_5I"], r["isc_5Q"] = gd(140), gd(153), gd(166), gd(179)
    r["toe_sow"] = toe10
    r["toe"] = nearest_week_time(toe10, t_ref)
    r["toc"] = nearest_week_time(toc, t_ref)
    # CNAV has no IODE: the toe identifies the data set
    r["iode"] = r["iodc"] = int(toe10 // 300)
    return r


def decode_cnav_iono(mt30: Bits) -> dict:
    """Klobuchar parameters of CNAV message type 30."""
    return dict(alpha0=mt30.s(192, 8) * 2.0**-30, alpha1=mt30.s(200, 8) * 2.0**-27,
                alpha2=mt30.s(208, 8) * 2.0**-24, alpha3=mt30.s(216, 8) * 2.0**-24,
                beta0=mt30.s(224, 8) * 2.0**11, beta1=mt30.s(232, 8) * 2.0**14,
                beta2=mt30.s(240, 8) * 2.0**16, beta3=mt30.s(248, 8) * 2.0**16)


# --- Galileo I/NAV -------------------------------------------------------------------------------

def inav_word(words) -> tuple[int, Bits] | None:
    """(word type, 128-bit word) of a UBX I/NAV page pair (8 words: even then odd part), or
    None for alert pages, wrong even/odd order or a CRC failure."""
    if len(words) < 8:
        return None
    b = Bits.from_words(words[:8], 32)
    if b.u(0, 1) != 0 or b.u(128, 1) != 1 or b.u(1, 1) or b.u(129, 1):
        return None
    # CRC-24Q over the even part (114 bits) and the odd part's first 82 bits
    msg = (b.u(0, 114) << 82) | b.u(128, 82)
    if crc24q(msg, 196) != b.u(128 + 82, 24):
        return None
    w = Bits((b.u(2, 112) << 16) | b.u(130, 16), 128)
    return w.u(0, 6), w


def decode_inav(w: dict, t_ref: float, sat: str, prn: int) -> dict | None:
    """Ephemeris row from I/NAV word types 1-5 (``w[k]`` the 128-bit word of type k)."""
    w1, w2, w3, w4, w5 = (w[k] for k in (1, 2, 3, 4, 5))
    iods = {w1.u(6, 10), w2.u(6, 10), w3.u(6, 10), w4.u(6, 10)}
    if len(iods) != 1 or w4.u(16, 6) != prn:
        return None
    r = _blank_row(sat, "E", prn, "inav", t_ref)
    r["iode"] = r["iodc"] = iods.pop()
    toe_sow = w1.u(16, 14) * 60.0
    r["m0"] = w1.s(30, 32) * 2.0**-31 * SC
    r["e"] = w1.u(62, 32) * 2.0**-33
    r["sqrt_a"] = w1.u(94, 32) * 2.0**-19
    r["omega0"] = w2.s(16, 32) * 2.0**-31 * SC
    r["i0"] = w2.s(48, 32) * 2.0**-31 * SC
    r["omega"] = w2.s(80, 32) * 2.0**-31 * SC
    r["idot"] = w2.s(112, 14) * 2.0**-43 * SC
    r["omega_dot"] = w3.s(16, 24) * 2.0**-43 * SC
    r["delta_n"] = w3.s(40, 16) * 2.0**-43 * SC
    r["cuc"] = w3.s(56, 16) * 2.0**-29
    r["cus"] = w3.s(72, 16) * 2.0**-29
    r["crc"] = w3.s(88, 16) * 2.0**-5
    r["crs"] = w3.s(104, 16) * 2.0**-5
    r["ura"] = sisa_from_index(w3.u(120, 8))
    r["cic"] = w4.s(22, 16) * 2.0**-29
    r["cis"] = w4.s(38, 16) * 2.0**-29
    toc_sow = w4.u(54, 14) * 60.0
    r["af0"] = w4.s(68, 31) * 2.0**-34
    r["af1"] = w4.s(99, 21) * 2.0**-46
    r["af2"] = w4.s(120, 6) * 2.0**-59
    r["tgd"] = w5.s(47, 10) * 2.0**-32  # BGD(E1, E5a)
    r["tgd2"] = w5.s(57, 10) * 2.0**-32  # BGD(E1, E5b)
    e5b_hs, e1b_hs, e5b_dvs, e1b_dvs = w5.u(67, 2), w5.u(69, 2), w5.u(71, 1), w5.u(72, 1)
    r["health"] = (e1b_hs << 1) | e1b_dvs | (e5b_hs << 3) | (e5b_dvs << 2)
    r["toe_sow"] = toe_sow
    r["toe"] = nearest_week_time(toe_sow, t_ref)
    r["toc"] = nearest_week_time(toc_sow, t_ref)
    return r


def decode_inav_iono(w5: Bits) -> dict:
    """NeQuick-G effective ionisation level coefficients of word type 5 (ai0 [sfu], ai1
    [sfu/deg], ai2 [sfu/deg^2])."""
    return dict(ai0=w5.u(6, 11) * 2.0**-2, ai1=w5.s(17, 11) * 2.0**-8, ai2=w5.s(28, 14) * 2.0**-15)


# --- BeiDou D1 -----------------------------------------------------------------------------------

def _d1_bits(words) -> Bits:
    return Bits.from_words(words, 30, 0)


def decode_d1(s1: Bits, s2: Bits, s3: Bits, t_ref: float, sat: str, prn: int) -> dict | None:
    """Ephemeris row from BeiDou D1 subframes 1-3 (300 bits each, parity bits in place)."""
    if s1.u(15, 3) != 1 or s2.u(15, 3) != 2 or s3.u(15, 3) != 3:
        return None
    sow = [s.u2(18, 8, 30, 12) for s in (s1, s2, s3)]
    if sow[1] != sow[0] + 6 or sow[2] != sow[1] + 6:
        return None
    toc = s1.u2(73, 9, 90, 8) * 8.0
    toe = ((s2.u(290, 2) << 15) | s3.u2(42, 10, 60, 5)) * 8.0
    if toc != toe:
        return None
    r = _blank_row(sat, "C", prn, "d1", t_ref)
    r["health"] = s1.u(42, 1)
    r["iodc"] = s1.u(43, 5)  # AODC
    r["ura"] = ura_from_index(s1.u(48, 4))
    r["tgd"] = s1.s(98, 10) * 0.1e-9  # TGD1 (B1I)
    r["tgd2"] = s1.s2(108, 4, 120, 6) * 0.1e-9  # TGD2 (B2I)
    r["af2"] = s1.s(214, 11) * 2.0**-66
    r["af0"] = s1.s2(225, 7, 240, 17) * 2.0**-33
    r["af1"] = s1.s2(257, 5, 270, 17) * 2.0**-50
    r["iode"] = s1.u(287, 5)  # AODE
    r["delta_n"] = s2.s2(42, 10, 60, 6) * 2.0**-43 * SC
    r["cuc"] = s2.s2(66, 16, 90, 2) * 2.0**-31
    r["m0"] = s2.s2(92, 20, 120, 12) * 2.0**-31 * SC
    r["e"] = s2.u2(132, 10, 150, 22) * 2.0**-33
    r["cus"] = s2.s(180, 18) * 2.0**-31
    r["crc"] = s2.s2(198, 4, 210, 14) * 2.0**-6
    r["crs"] = s2.s2(224, 8, 240, 10) * 2.0**-6
    r["sqrt_a"] = s2.u2(250, 12, 270, 20) * 2.0**-19
    r["i0"] = s3.s2(65, 17, 90, 15) * 2.0**-31 * SC
    r["cic"] = s3.s2(105, 7, 120, 11) * 2.0**-31
    r["omega_dot"] = s3.s2(131, 11, 150, 13) * 2.0**-43 * SC
    r["cis"] = s3.s2(163, 9, 180, 9) * 2.0**-31
    r["idot"] = s3.s2(189, 13, 210, 1) * 2.0**-43 * SC
    r["omega0"] = s3.s2(211, 21, 240, 11) * 2.0**-31 * SC
    r["omega"] = s3.s2(251, 11, 270, 21) * 2.0**-31 * SC
    r["toe_sow"] = toe  # BDT seconds of week
    r["toe"] = nearest_week_time(toe, t_ref, BDT_MINUS_GPST)
    r["toc"] = nearest_week_time(toc, t_ref, BDT_MINUS_GPST)
    return r


def decode_d1_iono(s1: Bits) -> dict:
    """BeiDou Klobuchar parameters of D1 subframe 1 (for the BDS variant of the model)."""
    return dict(alpha0=s1.s(126, 8) * 2.0**-30, alpha1=s1.s(134, 8) * 2.0**-27,
                alpha2=s1.s(150, 8) * 2.0**-24, alpha3=s1.s(158, 8) * 2.0**-24,
                beta0=s1.s2(166, 6, 180, 2) * 2.0**11, beta1=s1.s(182, 8) * 2.0**14,
                beta2=s1.s(190, 8) * 2.0**16, beta3=s1.s2(198, 4, 210, 4) * 2.0**16)


# --- stream ------------------------------------------------------------------------------------

def decode_subframes(subframes: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Decode a subframe table (:func:`insgnss.gnss.ubx.read_ubx`) into ephemerides.

    Returns
    -------
    ephemeris : DataFrame
        One row per distinct broadcast data set (:data:`EPH_COLUMNS`), in reception order.
    ionosphere : DataFrame
        Broadcast ionosphere parameters (:data:`ION_COLUMNS`), index = reception time.
    """
    eph_rows: list[dict] = []
    ion_rows: list[tuple[float, dict]] = []
    seen: set = set()
    lnav: dict = defaultdict(dict)
    cnav: dict = defaultdict(dict)
    inav: dict = defaultdict(dict)
    d1: dict = defaultdict(dict)

    def emit(row):
        if row is None:
            return
        key = (row["sat"], row["source"], row["iode"], row["toe"], row["toc"])
        if key not in seen:
            seen.add(key)
            eph_rows.append(row)

    times = subframes.index.to_numpy(float)
    for t, sat, system, prn, signal, words in zip(
            times, subframes["sat"], subframes["system"], subframes["prn"], subframes["signal"],
            subframes["words"], strict=True):
        if not np.isfinite(t):
            continue  # before the first epoch: no time to resolve the week
        if system in ("G", "J") and signal == "1C" and len(words) >= 10:
            b = _lnav_bits(words[:10])
            sfid = b.u(43, 3)
            if sfid == 4:
                ion = decode_lnav_iono(b)
                if ion:
                    ion_rows.append((t, dict(system=system, source="lnav", **ion)))
                continue
            if sfid not in (1, 2, 3):
                continue
            lnav[sat][sfid] = b
            if sfid == 3 and 1 in lnav[sat] and 2 in lnav[sat]:
                emit(decode_lnav(lnav[sat][1], lnav[sat][2], b, t, sat, system, prn))
        elif system in ("G", "J") and signal[:1] in ("2", "5") and len(words) >= 10:
            b = cnav_message(words[:10])
            if b is None or b.u(8, 6) != prn % 64:
                continue
            mt = b.u(14, 6)
            if mt == 30:
                ion_rows.append((t, dict(system=system, source="cnav", **decode_cnav_iono(b))))
            if mt in (10, 11, 30):  # clock and group delays from type 30 only
                cnav[sat][mt] = b
                m = cnav[sat]
                if len(m) == 3:
                    emit(decode_cnav(m[10], m[11], m[30], t, sat, system, prn))
        elif system == "E" and signal == "1B":
            res = inav_word(words)
            if res is None:
                continue
            wt, w = res
            if 1 <= wt <= 5:
                inav[sat][wt] = w
                if wt == 5:
                    ion_rows.append((t, dict(system="E", source="inav", **decode_inav_iono(w))))
                if all(k in inav[sat] for k in (1, 2, 3, 4, 5)):
                    emit(decode_inav(inav[sat], t, sat, prn))
        elif system == "C" and signal in ("2I", "6I") and len(words) >= 10 and 6 <= prn <= 58:
            b = _d1_bits(words[:10])
            sfid = b.u(15, 3)
            if sfid == 1:
                ion_rows.append((t, dict(system="C", source="d1", **decode_d1_iono(b))))
            if sfid in (1, 2, 3):
                d1[sat][sfid] = b
                if sfid == 3 and 1 in d1[sat] and 2 in d1[sat]:
                    emit(decode_d1(d1[sat][1], d1[sat][2], b, t, sat, prn))
    eph = pd.DataFrame(eph_rows, columns=EPH_COLUMNS)
    ion = pd.DataFrame([r for _, r in ion_rows], columns=ION_COLUMNS,
                       index=pd.Index([t for t, _ in ion_rows], name="time", dtype=float))
    for df in (eph, ion):
        df.attrs.update(subframes.attrs)
        df.attrs["format"] = "broadcast_ephemeris"
    return eph, ion
