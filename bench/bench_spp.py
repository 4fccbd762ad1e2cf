"""Single-point positioning on the rtklibexplorer walk's raw u-blox stream.

Reads ``walk_0827/gnss_1730.ubx`` (RAWX + SFRBX + NAV-PVT), decodes the broadcast ephemerides,
runs SPP (GPS L1 C/A + Galileo E1 + BeiDou B3I, Klobuchar, Saastamoinen/Niell, FDE) and prints

- timings of reading, decoding and SPP;
- horizontal error against the RTK reference ``gnss_1730_sf.pos``: RMS, the mean offset and the
  scatter about it, for all systems and for each system alone (the offset common to the three
  independent constellations is the reference's, not the SPP's);
- the receiver's own NAV-PVT fix against the reference on the same epochs;
- velocity error against the RTK velocity, residual RMS per system, FDE exclusions.

    python bench/bench_spp.py [--data ../shared/data/gnss-imu-rtklibexplorer/walk_0827]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from insgnss.earth import geodetic_to_enu
from insgnss.gnss import GnssModelConfig, SppConfig, decode_subframes, read_ubx, spp
from insgnss.io import read_rtklib_pos

DEFAULT = Path(__file__).resolve().parents[2] / "shared" / "data" / "gnss-imu-rtklibexplorer" / \
    "walk_0827"


def enu_error(sol, ref, height="height"):
    j = ref.reindex(sol.index, method="nearest", tolerance=0.02)
    ok = np.isfinite(j["lat"].to_numpy())
    lat0, lon0 = float(ref["lat"].iloc[0]), float(ref["lon"].iloc[0])
    e, n, u = geodetic_to_enu(sol["lat"][ok], sol["lon"][ok], sol[height][ok], lat0, lon0, 0.0)
    e2, n2, u2 = geodetic_to_enu(j["lat"][ok], j["lon"][ok], j["height"][ok], lat0, lon0, 0.0)
    return np.column_stack([e - e2, n - n2, u - u2])


def report(name, err):
    h = np.hypot(err[:, 0], err[:, 1])
    off = err[:, :2].mean(axis=0)
    sc = np.sqrt(np.mean(np.sum((err[:, :2] - off) ** 2, axis=1)))
    print(f"  {name:24s} n={len(err):4d}  horizontal RMS {np.sqrt(np.mean(h**2)):6.2f} m  "
          f"mean offset E {off[0]:6.2f} N {off[1]:6.2f} m  scatter about it {sc:5.2f} m  "
          f"95 % {np.percentile(h, 95):6.2f} m")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    ubx = read_ubx(a.data / "gnss_1730.ubx")
    t1 = time.perf_counter()
    eph, ion = decode_subframes(ubx.subframes)
    t2 = time.perf_counter()
    res = spp(ubx.observations, eph, ion)
    t3 = time.perf_counter()
    ref = read_rtklib_pos(a.data / "gnss_1730_sf.pos")
    n_obs = len(ubx.observations)
    print(f"read UBX: {t1 - t0:.2f} s ({len(ubx.epochs)} RAWX epochs, {n_obs} observations, "
          f"{len(ubx.subframes)} SFRBX); decode: {t2 - t1:.3f} s ({len(eph)} ephemerides: "
          + ", ".join(f"{k} {v}" for k, v in eph["source"].value_counts().items())
          + f"); SPP: {t3 - t2:.2f} s ({len(res.solution) / (t3 - t2):.0f} epochs/s)")
    sol = res.solution
    print(f"SPP epochs {len(sol)}, satellites used median {sol['ns'].median():.0f}, "
          f"PDOP median {sol['pdop'].median():.2f}, FDE exclusions {int(sol['n_excluded'].sum())},"
          f" chi-square passed {sol['raim_ok'].mean() * 100:.1f} %")
    print("Horizontal error against the RTK reference (gnss_1730_sf.pos):")
    report("SPP G+E+C", enu_error(sol, ref))
    for s, sig in (("G", "1C"), ("E", "1C"), ("C", "6I")):
        one = spp(ubx.observations, eph, ion, SppConfig(model=GnssModelConfig(
            signals={s: (sig,)}), velocity=False)).solution
        report(f"SPP {s} {sig} alone", enu_error(one, ref))
    causal = spp(ubx.observations, eph, ion, SppConfig(model=GnssModelConfig(
        causal_ephemeris=True))).solution
    report("SPP causal ephemerides", enu_error(causal, ref))
    pvt = ubx.nav_pvt
    e_pvt = enu_error(pvt.assign(height=pvt["height_msl"]), ref)
    report("receiver NAV-PVT", e_pvt)
    q = pvt["q"].value_counts().to_dict()
    print(f"  NAV-PVT solution types {q} (1 = RTK fixed, 2 = float): the .pos file is NAV-PVT "
          f"(height = hMSL; NAV-PVT ellipsoidal height - hMSL = "
          f"{(pvt['height'] - pvt['height_msl']).mean():.2f} m)")
    j = ref.reindex(sol.index, method="nearest", tolerance=0.02)
    dv = sol[["vel_e", "vel_n", "vel_u"]].to_numpy() - j[["vel_e", "vel_n", "vel_u"]].to_numpy()
    print(f"Doppler velocity error RMS E/N/U: {np.sqrt(np.nanmean(dv**2, axis=0)).round(3)} m/s; "
          f"clock drift {sol['clock_drift'].mean():.1f} m/s")
    r = res.residuals[res.residuals["used"]]
    per = r.groupby(r["sat"].str[0])["pr_residual"].agg(lambda x: np.sqrt(np.mean(x**2)))
    print("pseudorange residual RMS per system [m]:", per.round(2).to_dict(),
          f"normalised RMS {np.sqrt(np.mean((r['pr_residual'] / r['pr_std'])**2)):.2f}")


if __name__ == "__main__":
    main()
