"""Propagation and geometry corrections of single-frequency pseudoranges.

- Earth rotation during signal travel (Sagnac): the satellite position at transmission,
  expressed in the ECEF frame of the transmission time, is rotated into the ECEF frame of the
  reception time, ``x' = Rz(We tau) x`` with ``tau`` the travel time (IS-GPS-200N
  20.3.3.4.3.3.2; Groves 2013 eq. 8.36). The rotation is applied to position and velocity.
- Elevation / azimuth of the line of sight in the receiver's ENU frame.
- Troposphere: Saastamoinen (1972) zenith hydrostatic and wet delays with a standard
  atmosphere (pressure 1013.25 hPa, 15 degC at sea level, -6.5 K/km lapse rate, relative
  humidity 0.7; the model RTKLIB uses), mapped to the line of sight with the Niell (1996)
  hydrostatic (with the height correction) and wet mapping functions.
- Ionosphere: the GPS broadcast Klobuchar model (IS-GPS-200N 20.3.3.5.2.5, Figure 20-4), for
  any signal scaled by ``(f_L1 / f)^2`` (first-order ionospheric delay ~ 1/f^2). It is applied
  to Galileo and BeiDou too: NeQuick-G (Galileo's model) has no Python implementation that
  installs beside numpy 2 (the ``nequick`` package pins numpy < 2), so the Galileo words'
  ``ai0..ai2`` are decoded and kept but not used. The Klobuchar model removes about half of
  the delay (RMS); its residual is carried in the measurement variance
  (:func:`iono_variance`).

References
----------
- Saastamoinen, J., "Atmospheric correction for the troposphere and stratosphere in radio
  ranging of satellites", Geophysical Monograph 15, AGU, 1972.
- Niell, A. E., "Global mapping functions for the atmosphere delay at radio wavelengths",
  J. Geophys. Res. 101(B2), 1996.
- Klobuchar, J. A., "Ionospheric time-delay algorithm for single-frequency GPS users",
  IEEE Trans. AES-23(3), 1987; IS-GPS-200N 20.3.3.5.2.5.
- Takasu, T., RTKLIB 2.4.3 manual, appendix E.5 (error model of single point positioning).
"""

from __future__ import annotations

import numpy as np

from ..earth import ecef_to_enu_vectors
from .constants import C_LIGHT, F_L1, OMEGA_E_WGS84


def sagnac_rotate(pos, vel, tau):
    """Rotate satellite ECEF position/velocity (N, 3) by the Earth rotation during ``tau`` [s]."""
    th = OMEGA_E_WGS84 * np.asarray(tau, float)
    c, s = np.cos(th), np.sin(th)
    p = np.column_stack([c * pos[:, 0] + s * pos[:, 1], -s * pos[:, 0] + c * pos[:, 1], pos[:, 2]])
    v = np.column_stack([c * vel[:, 0] + s * vel[:, 1], -s * vel[:, 0] + c * vel[:, 1], vel[:, 2]])
    return p, v


def geometry(r_rx, sat_pos, sat_vel, lat, lon):
    """Geometric range with Earth rotation, line of sight, elevation and azimuth.

    Parameters
    ----------
    r_rx : (3,) array
        Receiver ECEF position [m].
    sat_pos, sat_vel : (N, 3) arrays
        Satellite ECEF position/velocity at transmission (frame of the transmission time).
    lat, lon : float
        Receiver geodetic coordinates [rad] (for the ENU frame).

    Returns
    -------
    rho : (N,) range [m]; los : (N, 3) unit vectors receiver -> satellite (ECEF, reception
    frame); el, az : (N,) [rad]; pos, vel : (N, 3) satellite state in the reception frame.
    """
    d = sat_pos - r_rx
    rho = np.sqrt(np.einsum("ij,ij->i", d, d))
    for _ in range(2):  # the travel time depends on the rotated position (converges in 2)
        p, v = sagnac_rotate(sat_pos, sat_vel, rho / C_LIGHT)
        d = p - r_rx
        rho = np.sqrt(np.einsum("ij,ij->i", d, d))
    los = d / rho[:, None]
    enu = ecef_to_enu_vectors(los, lat, lon)
    el = np.arcsin(np.clip(enu[:, 2], -1.0, 1.0))
    az = np.arctan2(enu[:, 0], enu[:, 1])
    return rho, los, el, az, p, v


# --- troposphere ----------------------------------------------------------------------------

#: standard atmosphere of the Saastamoinen model: relative humidity
REL_HUMIDITY = 0.7


def saastamoinen_zenith(lat, h):
    """Zenith hydrostatic and wet delays [m] of the Saastamoinen model, standard atmosphere.

    ``h`` is the height [m] (ellipsoidal heights are used for orthometric ones: the geoid
    undulation changes the delay by < 1 cm); heights below 0 use 0, above 10 km no delay.
    """
    h = np.clip(np.asarray(h, float), 0.0, None)
    p = 1013.25 * (1.0 - 2.2557e-5 * h) ** 5.2568  # [hPa]
    T = 15.0 - 6.5e-3 * h + 273.16  # [K]
    e = 6.108 * REL_HUMIDITY * np.exp((17.15 * T - 4684.0) / (T - 38.45))  # water vapour [hPa]
    zhd = 0.0022768 * p / (1.0 - 0.00266 * np.cos(2.0 * lat) - 0.00028 * h / 1e3)
    zwd = 0.002277 * (1255.0 / T + 0.05) * e
    high = h > 1e4
    return np.where(high, 0.0, zhd), np.where(high, 0.0, zwd)


_NMF_LAT = np.radians([15.0, 30.0, 45.0, 60.0, 75.0])
# Niell (1996) Table 3: hydrostatic a, b, c averages and amplitudes; wet a, b, c
_NMF_HYD_AVG = np.array([[1.2769934e-3, 1.2683230e-3, 1.2465397e-3, 1.2196049e-3, 1.2045996e-3],
                         [2.9153695e-3, 2.9152299e-3, 2.9288445e-3, 2.9022565e-3, 2.9024912e-3],
                         [62.610505e-3, 62.837393e-3, 63.721774e-3, 63.824265e-3, 64.258455e-3]])
_NMF_HYD_AMP = np.array([[0.0, 1.2709626e-5, 2.6523662e-5, 3.4000452e-5, 4.1202191e-5],
                         [0.0, 2.1414979e-5, 3.0160779e-5, 7.2562722e-5, 11.723375e-5],
                         [0.0, 9.0128400e-5, 4.3497037e-5, 84.795348e-5, 170.37206e-5]])
_NMF_WET = np.array([[5.8021897e-4, 5.6794847e-4, 5.8118019e-4, 5.9727542e-4, 6.1641693e-4],
                     [1.4275268e-3, 1.5138625e-3, 1.4572752e-3, 1.5007428e-3, 1.7599082e-3],
                     [4.3472961e-2, 4.6729510e-2, 4.3908931e-2, 4.4626982e-2, 5.4736038e-2]])
_NMF_HT = (2.53e-5, 5.49e-3, 1.14e-3)


def _marini(sin_el, a, b, c):
    """Continued fraction of Marini (1972) normalised to 1 at the zenith."""
    return (1.0 + a / (1.0 + b / (1.0 + c))) / (sin_el + a / (sin_el + b / (sin_el + c)))


def niell_mapping(el, lat, h, day_of_year):
    """Niell hydrostatic and wet mapping functions (``m_h``, ``m_w``).

    ``el`` [rad] (clipped at 2 deg), ``lat`` [rad], ``h`` [m], ``day_of_year`` (fractional,
    UT); the seasonal term uses day 28 as the phase (southern hemisphere + half a year).
    """
    el = np.maximum(np.asarray(el, float), np.radians(2.0))
    s = np.sin(el)
    alat = abs(float(lat))
    doy = day_of_year + (182.625 if lat < 0 else 0.0)
    cosy = np.cos(2.0 * np.pi * (doy - 28.0) / 365.25)
    ah = [np.interp(alat, _NMF_LAT, _NMF_HYD_AVG[k]) - np.interp(alat, _NMF_LAT, _NMF_HYD_AMP[k])
          * cosy for k in range(3)]
    aw = [np.interp(alat, _NMF_LAT, _NMF_WET[k]) for k in range(3)]
    dm = (1.0 / s - _marini(s, *_NMF_HT)) * max(float(h), 0.0) / 1e3
    return _marini(s, *ah) + dm, _marini(s, *aw)


def tropo_delay(el, lat, h, day_of_year):
    """Slant tropospheric delay [m]: Saastamoinen zenith delays times the Niell mappings."""
    zhd, zwd = saastamoinen_zenith(lat, h)
    mh, mw = niell_mapping(el, lat, h, day_of_year)
    return zhd * mh + zwd * mw


def tropo_variance(el):
    """Variance [m^2] of the residual tropospheric error: ``(0.3 m / (sin el + 0.1))^2``
    (RTKLIB's error model of the Saastamoinen correction)."""
    return (0.3 / (np.sin(np.asarray(el, float)) + 0.1)) ** 2


# --- ionosphere -----------------------------------------------------------------------------

def klobuchar_delay(lat, lon, el, az, tow, alpha, beta, freq=F_L1):
    """Broadcast (Klobuchar) ionospheric group delay [m] on frequency ``freq`` [Hz].

    Parameters
    ----------
    lat, lon : float
        Receiver geodetic coordinates [rad].
    el, az : array_like
        Elevation and azimuth [rad].
    tow : float
        GPS seconds of week of the reception.
    alpha, beta : sequence of 4 floats
        Broadcast coefficients [s, s/sc, s/sc^2, s/sc^3] and [s, s/sc, ...] (as transmitted).
    freq : float or array_like
        Carrier frequency; the L1 delay is scaled by ``(f_L1 / f)^2``.
    """
    el_sc = np.asarray(el, float) / np.pi
    az = np.asarray(az, float)
    psi = 0.0137 / (el_sc + 0.11) - 0.022  # Earth-centred angle [sc]
    phi_i = np.clip(lat / np.pi + psi * np.cos(az), -0.416, 0.416)  # IPP latitude [sc]
    lam_i = lon / np.pi + psi * np.sin(az) / np.cos(phi_i * np.pi)
    phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * np.pi)  # geomagnetic latitude [sc]
    t = np.mod(4.32e4 * lam_i + tow, 86400.0)  # local time at the IPP [s]
    F = 1.0 + 16.0 * (0.53 - el_sc) ** 3  # obliquity factor
    amp = np.maximum(sum(alpha[k] * phi_m**k for k in range(4)), 0.0)
    per = np.maximum(sum(beta[k] * phi_m**k for k in range(4)), 72000.0)
    x = 2.0 * np.pi * (t - 50400.0) / per
    day = 5e-9 + amp * (1.0 - x**2 / 2.0 + x**4 / 24.0)
    delay = F * np.where(np.abs(x) < 1.57, day, 5e-9)
    return C_LIGHT * delay * (F_L1 / np.asarray(freq, float)) ** 2


def iono_variance(delay):
    """Variance [m^2] of the residual error after the broadcast model: 50 % of the delay
    (Klobuchar 1987: the model removes about half of the ionospheric delay RMS)."""
    return (0.5 * np.asarray(delay, float)) ** 2


def day_of_year(t_gps: float) -> float:
    """Fractional day of year (1.0 = 1 January 00:00) of GPS seconds ``t_gps``."""
    from ..io.gpstime import datetime64_from_gps_seconds

    dt = datetime64_from_gps_seconds(np.array([t_gps]))[0]
    year_start = dt.astype("datetime64[Y]")
    return 1.0 + float((dt - year_start) / np.timedelta64(1, "D"))
