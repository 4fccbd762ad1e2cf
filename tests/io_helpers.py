"""Generators of small, exactly known input files for the reader tests (text in, truth out)."""

from __future__ import annotations

import struct

import numpy as np
import pynmea2

from insgnss.earth import ecef_to_enu_matrix, geodetic_to_ecef
from insgnss.io.gpstime import UNIX_GPST_OFFSET, datetime64_from_gps_seconds, week_sow_from_gps_seconds

G0 = 9.80665
#: 2025-07-08T19:34:18.499 GPST, the first epoch of the drive .pos
T0_GPS = 1436038458.499
LAT0, LON0, H0 = np.radians(40.0966268), np.radians(-105.1474483), 1601.474

IMU_HEADER = "time,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z"


def imu_rows(n: int = 50, dt: float = 0.01, t0: float = 100.0, seed: int = 0):
    """Time, gyro [rad/s] and accel [m/s^2] of a still IMU (level, body RFU) with noise."""
    rng = np.random.default_rng(seed)
    t = t0 + dt * np.arange(n)
    gyro = rng.normal(0.0, 0.002, (n, 3))
    accel = np.array([0.0, 0.0, G0]) + rng.normal(0.0, 0.02, (n, 3))
    return t, gyro, accel


def imu_csv_text(t, gyro, accel, header: str = IMU_HEADER, fmt: str = "%.9f") -> str:
    data = np.column_stack([t, gyro, accel])
    lines = [header] + [",".join(fmt % x for x in r) for r in data]
    return "\n".join(lines) + "\n"


def calendar(t_gps) -> list[str]:
    """``yyyy/mm/dd hh:mm:ss.sss`` of GPS seconds."""
    out = []
    for d in datetime64_from_gps_seconds(np.asarray(t_gps, float)):
        s = str(d.astype("datetime64[ms]"))
        out.append(s[:10].replace("-", "/") + " " + s[11:23])
    return out


def trajectory(n: int = 12, dt: float = 0.25, t0: float = T0_GPS):
    """A short straight drive: time, lat, lon [rad], h, vel ENU."""
    t = t0 + dt * np.arange(n)
    ve, vn, vu = 3.0, 4.0, 0.1
    from insgnss.earth import radii

    M, N = radii(LAT0)
    lat = LAT0 + vn * (t - t0) / (M + H0)
    lon = LON0 + ve * (t - t0) / ((N + H0) * np.cos(LAT0))
    h = H0 + vu * (t - t0)
    vel = np.tile([ve, vn, vu], (n, 1))
    return t, lat, lon, h, vel


def pos_text(t, lat, lon, h, *, q=None, vel=None, time_format: str = "calendar",
             pos: str = "llh", system: str = "GPST", header: bool = True, sd=(0.01, 0.02, 0.03),
             vsd=(0.05, 0.06, 0.07)) -> str:
    """An RTKLIB .pos text of the given solution (all layouts the reader supports)."""
    n = len(t)
    q = np.ones(n, int) if q is None else np.asarray(q)
    if time_format == "calendar":
        tt = t - 18.0 if system == "UTC" else (t - 18.0 + 9 * 3600 if system == "JST" else t)
        stamps = calendar(tt)
    else:
        wk, sow = week_sow_from_gps_seconds(t)
        stamps = [f"{w:4d} {s:10.3f}" for w, s in zip(wk, sow, strict=True)]
    if pos == "ecef":
        cols = ["x-ecef(m)", "y-ecef(m)", "z-ecef(m)", "Q", "ns", "sdx(m)", "sdy(m)", "sdz(m)",
                "sdxy(m)", "sdyz(m)", "sdzx(m)", "age(s)", "ratio"]
        if vel is not None:
            cols += ["vx(m/s)", "vy(m/s)", "vz(m/s)", "sdvx", "sdvy", "sdvz", "sdvxy", "sdvyz",
                     "sdvzx"]
    else:
        if pos == "dms":
            cols = ["latitude(d'\")", "longitude(d'\")"]
        else:
            cols = ["latitude(deg)", "longitude(deg)"]
        cols += ["height(m)", "Q", "ns", "sdn(m)", "sde(m)", "sdu(m)", "sdne(m)", "sdeu(m)",
                 "sdun(m)", "age(s)", "ratio"]
        if vel is not None:
            cols += ["vn(m/s)", "ve(m/s)", "vu(m/s)", "sdvn", "sdve", "sdvu", "sdvne", "sdveu",
                     "sdvun"]
    lines = ["% program   : RTKLIB ver.demo5 b34k (test)", "% pos mode  : kinematic"]
    if header:
        lines.append(f"%  {system:<22}" + " ".join(f"{c:>14}" for c in cols))
    for i in range(n):
        if pos == "ecef":
            x, y, z = geodetic_to_ecef(lat[i], lon[i], h[i])
            C = ecef_to_enu_matrix(lat[i], lon[i])
            # ENU diagonal covariance -> ECEF, written as RTKLIB signed roots
            cov = C.T @ np.diag(np.square([sd[1], sd[0], sd[2]])) @ C
            sroot = [np.sqrt(cov[0, 0]), np.sqrt(cov[1, 1]), np.sqrt(cov[2, 2])]
            off = [cov[0, 1], cov[1, 2], cov[2, 0]]
            sroot += [np.sign(c) * np.sqrt(abs(c)) for c in off]
            f = [f"{x:.4f}", f"{y:.4f}", f"{z:.4f}", f"{q[i]:d}", "21"] + \
                [f"{s:.6f}" for s in sroot] + ["0.00", "0.0"]
            if vel is not None:
                v = C.T @ vel[i]
                vc = C.T @ np.diag(np.square([vsd[1], vsd[0], vsd[2]])) @ C
                vr = [np.sqrt(vc[0, 0]), np.sqrt(vc[1, 1]), np.sqrt(vc[2, 2])]
                vr += [np.sign(c) * np.sqrt(abs(c)) for c in (vc[0, 1], vc[1, 2], vc[2, 0])]
                f += [f"{a:.5f}" for a in v] + [f"{s:.6f}" for s in vr]
        else:
            la, lo = np.degrees(lat[i]), np.degrees(lon[i])
            if pos == "dms":
                f = [_dms(la), _dms(lo)]
            else:
                f = [f"{la:.9f}", f"{lo:.9f}"]
            f += [f"{h[i]:.4f}", f"{q[i]:d}", "21", f"{sd[0]:.4f}", f"{sd[1]:.4f}", f"{sd[2]:.4f}",
                  "0.0000", "0.0000", "0.0000", "0.00", "0.0"]
            if vel is not None:
                ve, vn, vu = vel[i]
                f += [f"{vn:.5f}", f"{ve:.5f}", f"{vu:.5f}", f"{vsd[0]:.4f}", f"{vsd[1]:.4f}",
                      f"{vsd[2]:.4f}", "0.0", "0.0", "0.0"]
        lines.append(stamps[i] + "   " + " ".join(f))
    return "\n".join(lines) + "\n"


def _dms(deg: float) -> str:
    s = "-" if deg < 0 else ""
    a = abs(deg)
    d = int(a)
    m = int((a - d) * 60)
    sec = (a - d - m / 60) * 3600
    return f"{s}{d} {m:02d} {sec:011.8f}"


def tag_bytes(start_gps: float, ticks, fpos=None, *, fpos_size: int = 4, tick_f: int = 12345,
              version: str = "demo5") -> bytes:
    """An RTKLIB time-tag file."""
    ticks = np.asarray(ticks, np.int64)
    fpos = np.arange(ticks.size) * 44 if fpos is None else np.asarray(fpos, np.int64)
    unix = start_gps + UNIX_GPST_OFFSET
    whole = int(np.floor(unix))
    head = f"TIMETAG RTKLIB {version}".encode().ljust(60, b"\x00")
    out = [head, struct.pack("<I", tick_f), struct.pack("<Id", whole, unix - whole)]
    f = "<IQ" if fpos_size == 8 else "<II"
    out += [struct.pack(f, int(a), int(b)) for a, b in zip(ticks, fpos, strict=True)]
    return b"".join(out)


def raw_imu_text(ms, accel_g, gyro_dps) -> str:
    """rtklibexplorer raw IMU lines ``ax,ay,az,wx,wy,wz,t_ms``."""
    lines = [",".join([*(f"{v:.3f}" for v in a), *(f"{v:.3f}" for v in w), f"{int(m)}"])
             for m, a, w in zip(ms, accel_g, gyro_dps, strict=True)]
    return "\n".join(lines) + "\n"


def _nmea_angle(deg: float, lat: bool) -> tuple[str, str]:
    hemi = ("N" if deg >= 0 else "S") if lat else ("E" if deg >= 0 else "W")
    a = abs(deg)
    d = int(a)
    m = (a - d) * 60
    return (f"{d:02d}{m:010.7f}" if lat else f"{d:03d}{m:010.7f}"), hemi


def nmea_hms(tod: float) -> str:
    h = int(tod // 3600)
    m = int(tod % 3600 // 60)
    s = tod - h * 3600 - m * 60
    return f"{h:02d}{m:02d}{s:05.2f}"


def gga(tod, lat_deg, lon_deg, alt, sep=-20.0, quality=4, ns=12, hdop=0.8) -> str:
    la, ns_ = _nmea_angle(lat_deg, True)
    lo, ew = _nmea_angle(lon_deg, False)
    f = (nmea_hms(tod), la, ns_, lo, ew, str(quality), f"{ns:02d}", f"{hdop:.1f}", f"{alt:.3f}",
         "M", "" if sep is None else f"{sep:.3f}", "M", "", "")
    return str(pynmea2.GGA("GN", "GGA", f))


def rmc(tod, date_ddmmyy, lat_deg, lon_deg, speed_kn, course_deg, status="A") -> str:
    la, ns_ = _nmea_angle(lat_deg, True)
    lo, ew = _nmea_angle(lon_deg, False)
    f = (nmea_hms(tod), status, la, ns_, lo, ew, f"{speed_kn:.3f}", f"{course_deg:.2f}",
         date_ddmmyy, "", "", "D")
    return str(pynmea2.RMC("GN", "RMC", f))


def vtg(course_deg, speed_kmh) -> str:
    f = (f"{course_deg:.2f}", "T", "", "M", f"{speed_kmh / 1.852:.3f}", "N", f"{speed_kmh:.3f}",
         "K", "D")
    return str(pynmea2.VTG("GN", "VTG", f))


def gst(tod, sd_lat, sd_lon, sd_alt) -> str:
    f = (nmea_hms(tod), "0.5", "0.1", "0.1", "0.0", f"{sd_lat:.3f}", f"{sd_lon:.3f}", f"{sd_alt:.3f}")
    return str(pynmea2.GST("GN", "GST", f))


def kfgins_imu_text(t, dtheta_frd, dv_frd) -> str:
    data = np.column_stack([t, dtheta_frd, dv_frd])
    return "\n".join(" ".join(f"{x:.12f}" for x in r) for r in data) + "\n"
