"""Trajectory outputs: native CSV (and its validated reader), scorer CSV, KML and GeoJSON tracks.

All writers are atomic (:func:`insgnss.io.native.atomic_write`: temporary file + rename, so a
crash leaves the previous file or nothing under the final name) and refuse to overwrite any
path listed in ``protect`` (the run's inputs, :func:`insgnss.validate.ensure_not_input`).

- **Trajectory CSV** (native, :mod:`insgnss.io.native`): ``time`` then the table's columns,
  angles in degrees with a ``_deg`` suffix, NaN written as ``nan``; shortest round-trip floats
  (pyarrow writer, :func:`insgnss.io.native.csv_writer`) unless ``float_format`` is given.
- **Scorer CSV** (``shared/eval`` input): ``time_gpst_s lat_deg lon_deg height_m`` and, when the
  table has attitude, ``roll_deg pitch_deg yaw_deg`` (FRD body relative to NED, via
  :func:`insgnss.attitude.euler_to_ned`).
- **KML 2.2**: one placemark per track (``lon,lat,height`` in degrees and metres; KML heights
  are above mean sea level, so the default altitude mode clamps to the ground) and optional
  point placemarks (e.g. GNSS epochs). A track whose times are absolute (time base ``gps``,
  ``unix_gpst``, or ``sow`` with a known week) is a Google ``gx:Track``: a ``<when>`` (UTC,
  ISO 8601) per ``<gx:coord>``, so Google Earth shows the time slider and animates it (and
  GDAL's LIBKML driver, QGIS, read its time stamps); other tracks are a ``LineString``.
- **GeoJSON** (RFC 7946): a FeatureCollection with one ``LineString`` feature per track, whose
  ``properties.times`` holds the time of every vertex [s, the table's time base] and, with
  absolute times, ``properties.coordTimes`` the UTC ISO 8601 time of every vertex (the
  convention of Mapbox's togeojson for ``gx:Track``); then, per track, ``Point`` features at
  ``point_interval`` seconds with a ``time`` property (UTC ISO 8601, else seconds) and ``t``
  [s], which QGIS's temporal controller animates ("single field with date/time": ``time``);
  and an optional ``MultiPoint`` feature; positions ``[lon, lat, height]``.
"""

from __future__ import annotations

import json
import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..attitude import euler_to_ned
from ..errors import ConfigError, InputFormatError, InvalidValueError
from ..validate import (
    check_finite,
    check_range,
    check_time_order,
    ensure_not_input,
    finish_attrs,
    parse_numeric,
    read_rows,
)
from .gpstime import to_gps_seconds
from .native import atomic_write, csv_writer, file_columns_back, to_file_columns

KML_NS = "http://www.opengis.net/kml/2.2"
GX_NS = "http://www.google.com/kml/ext/2.2"
ALTITUDE_MODES = ("clampToGround", "relativeToGround", "absolute")


def _need(df: pd.DataFrame, cols: Sequence[str], what: str) -> None:
    missing = [c for c in cols if c not in df.columns]
    if missing:
        raise InputFormatError(f"table lacks columns for {what}", column=missing[0],
                               expected=", ".join(cols), found=", ".join(map(str, df.columns)))


def _llh_deg(df: pd.DataFrame, name: str) -> np.ndarray:
    """(N, 3) lon, lat [deg], height [m]; refuses non-finite values (row = 1-based sample)."""
    _need(df, ["lat", "lon", "height"], name)
    v = np.column_stack([np.degrees(df["lon"].to_numpy(float)),
                         np.degrees(df["lat"].to_numpy(float)), df["height"].to_numpy(float)])
    if not len(v):
        raise InputFormatError(f"no samples in {name}", expected="at least one sample", found="0")
    ok = np.isfinite(v)
    if not ok.all():
        i, j = np.argwhere(~ok)[0]
        raise InvalidValueError(f"non-finite position in {name}", row=int(i) + 1,
                                column=("lon", "lat", "height")[j],
                                expected="finite values", found=str(v[i, j]))
    return v


def write_trajectory_csv(df: pd.DataFrame, path: str | os.PathLike, *,
                         protect: Sequence[str | os.PathLike] = (),
                         float_format: str | None = None) -> Path:
    """Write a time-indexed table as a native insgnss CSV (atomically); ``float_format=None``
    writes shortest round-trip floats with the fast writer (:func:`~.native.csv_writer`)."""
    ensure_not_input(path, [*protect, df.attrs.get("source")])
    if float_format is None:
        return atomic_write(path, csv_writer(df))
    out = to_file_columns(df)
    out.index = pd.Index(np.asarray(df.index, float), name="time")
    return atomic_write(path, lambda p: out.to_csv(p, float_format=float_format, na_rep="nan"))


def read_trajectory_csv(path: str | os.PathLike, *, required: Sequence[str] = ("lat", "lon", "height"),
                        duplicates: str = "error", allocate=None) -> pd.DataFrame:
    """Read a native insgnss CSV with full validation (radians inside).

    Empty cells and ``nan`` are NaN; NaN/inf are errors in ``time`` and the ``required``
    columns only. Time must increase strictly. ``allocate``: where the values are made
    (:func:`insgnss.validate.read_rows`; a :class:`insgnss.io.spill.SpillAllocator` holds a
    long table on a memory-mapped file, its pages given back after reading: read them in
    blocks and give them back with :func:`insgnss.io.spill.release_frame`).
    """
    from .spill import release_frame

    rows = read_rows(path, comment=("#",), header=True, delimiter=",", allocate=allocate)
    head = [h.strip() for h in rows.header.split(",")]
    if not head or head[0] != "time":
        raise InputFormatError("first column must be 'time'", file=path, row=rows.header_line,
                               column=head[0] if head else None, expected="'time'",
                               found=", ".join(head))
    if len(set(head)) != len(head):
        dup = next(h for h in head if head.count(h) > 1)
        raise InputFormatError("duplicated column name", file=path, row=rows.header_line,
                               column=dup, expected="unique names", found=", ".join(head))
    file_names = [f"{c}_deg" if f"{c}_deg" in head else c for c in required]
    for want, c in zip(required, file_names, strict=True):
        if c not in head:
            raise InputFormatError("missing column", file=path, row=rows.header_line, column=want,
                                   expected=f"a column {want!r} (or {want + '_deg'!r})",
                                   found=", ".join(head))
    v = parse_numeric(rows, head, delimiter=",", empty_nan=True)
    idx = [0] + [head.index(c) for c in file_names]
    check_finite(v, [head[i] for i in idx], rows.line_no, path, columns=idx)
    for c, lim in (("lat_deg", 90.0), ("lon_deg", 360.0)):
        if c in head:
            check_range(v[:, head.index(c)], -lim, lim, c, rows.line_no, path, unit="deg")
    keep, dropped = check_time_order(v[:, 0], rows.line_no, path, duplicates=duplicates)
    if not keep.all():
        v = v[keep]
    # angle columns to radians in place (file_columns_back), then one table on the parsed
    # values without a copy (pandas copies a 2-D array by default)
    names = file_columns_back(head)
    for i, c in enumerate(head):
        if names[i] != c:
            v[:, i] = np.radians(v[:, i])
    df = pd.DataFrame(v[:, 1:], index=pd.Index(v[:, 0], name="time"), columns=names[1:],
                      copy=False)
    release_frame(df)  # the checks read every row
    return finish_attrs(df, file=path, fmt="native", time_base="unspecified",
                        line_no=rows.line_no[keep], dropped_duplicates=dropped)


def write_eval_csv(df: pd.DataFrame, path: str | os.PathLike, *, week: int | None = None,
                   protect: Sequence[str | os.PathLike] = ()) -> Path:
    """Write the scorer's CSV (``shared/eval/README.md``): GPS seconds, degrees, metres.

    The time is converted from ``attrs["time_base"]`` (``"sow"`` needs ``week=`` or
    ``attrs["gps_week"]``); tables without a declared base are written as they are.
    """
    ensure_not_input(path, [*protect, df.attrs.get("source")])
    llh = _llh_deg(df, "the scorer CSV")
    base = df.attrs.get("time_base", "unspecified")
    t = np.asarray(df.index, float)
    if base in ("gps", "sow", "unix_gpst"):
        wk = week if week is not None else df.attrs.get("gps_week")
        if base == "sow" and wk is None:
            raise ConfigError("seconds-of-week times need the GPS week", column="week",
                              expected="week= or attrs['gps_week']", found="none")
        t = to_gps_seconds(t, base, wk)
    out = pd.DataFrame({"time_gpst_s": t, "lat_deg": llh[:, 1], "lon_deg": llh[:, 0],
                        "height_m": llh[:, 2]})
    if all(c in df.columns for c in ("roll", "pitch", "heading")):
        r, p, y = euler_to_ned(df["roll"].to_numpy(float), df["pitch"].to_numpy(float),
                               df["heading"].to_numpy(float))
        out["roll_deg"], out["pitch_deg"], out["yaw_deg"] = np.degrees(r), np.degrees(p), np.degrees(y)
    out = out.set_index("time_gpst_s")  # the fast writer puts the index first
    return atomic_write(path, csv_writer(out))


def _sources(tracks: dict, points) -> list:
    tables = list(tracks.values()) + ([points] if points is not None else [])
    return [t.attrs.get("source") for t in tables]


def _rounded(v: np.ndarray) -> list:
    return np.column_stack([np.round(v[:, :2], 9), np.round(v[:, 2], 3)]).tolist()


def _tracks(tracks) -> dict[str, pd.DataFrame]:
    if isinstance(tracks, pd.DataFrame):
        return {"trajectory": tracks}
    if isinstance(tracks, Mapping) and all(isinstance(v, pd.DataFrame) for v in tracks.values()):
        return {str(k): v for k, v in tracks.items()}
    raise ConfigError("tracks must be a DataFrame or a mapping name -> DataFrame", column="tracks",
                      found=type(tracks).__name__)


def _decimate(v: np.ndarray, every: int) -> np.ndarray:
    return v[_decimated(len(v), every)]


def _decimated(n: int, every: int) -> np.ndarray:
    """Indices of every ``every``-th of ``n`` samples and the last."""
    if not isinstance(every, (int, np.integer)) or every < 1:
        raise ConfigError("decimation must be a positive integer", column="decimate",
                          found=repr(every))
    if every == 1 or n <= 2:
        return np.arange(n)
    return np.unique(np.concatenate([np.arange(0, n, every), [n - 1]]))


def utc_times(df: pd.DataFrame, time_base: str | None = None,
              week: int | None = None) -> np.ndarray | None:
    """UTC ``datetime64[ns]`` of a table's index when its time base is absolute (``gps``,
    ``unix_gpst``, or ``sow`` with ``week`` / ``attrs["gps_week"]``); None otherwise."""
    from .gpstime import utc_from_gps_seconds

    base = time_base or df.attrs.get("time_base")
    week = week if week is not None else df.attrs.get("gps_week")
    if base not in ("gps", "unix_gpst", "sow") or (base == "sow" and week is None):
        return None
    return utc_from_gps_seconds(to_gps_seconds(np.asarray(df.index, float), base,
                                               None if week is None else int(week)))


def _iso(t: np.ndarray) -> list[str]:
    """ISO 8601 UTC strings (rounded to the millisecond, ``Z``)."""
    ms = (np.asarray(t, "datetime64[ns]") + np.timedelta64(500_000, "ns")).astype("datetime64[ms]")
    return [f"{x}Z" for x in np.datetime_as_string(ms, unit="ms")]


def write_kml(tracks: pd.DataFrame | Mapping[str, pd.DataFrame], path: str | os.PathLike, *,
              name: str = "insgnss", points: pd.DataFrame | None = None,
              points_name: str = "GNSS", colors: Sequence[str] = ("ff0000ff", "ffff0000",
                                                                   "ff00ff00", "ff00ffff"),
              width: float = 2.0, altitude_mode: str = "clampToGround", decimate: int = 1,
              protect: Sequence[str | os.PathLike] = (), time_base: str | None = None,
              week: int | None = None) -> Path:
    """Write tracks (and optional points) as a KML 2.2 document (atomically).

    ``colors`` are KML ``aabbggrr`` strings used in turn per track; ``decimate`` keeps every
    n-th sample (and the last). Tracks with absolute times are ``gx:Track`` elements with a
    UTC time per sample (module docstring); ``time_base`` / ``week`` override the tables'
    ``attrs``.
    """
    if altitude_mode not in ALTITUDE_MODES:
        raise ConfigError("unknown altitude mode", column="altitude_mode",
                          expected=", ".join(ALTITUDE_MODES), found=repr(altitude_mode))
    tr = _tracks(tracks)
    ensure_not_input(path, [*protect, *_sources(tr, points)])
    ET.register_namespace("", KML_NS)
    ET.register_namespace("gx", GX_NS)
    q, gx = f"{{{KML_NS}}}", f"{{{GX_NS}}}"
    kml = ET.Element(q + "kml")
    doc = ET.SubElement(kml, q + "Document")
    ET.SubElement(doc, q + "name").text = name
    for k, (tname, df) in enumerate(tr.items()):
        idx = _decimated(len(df), decimate)
        v = _llh_deg(df, f"track {tname!r}")[idx]
        utc = utc_times(df, time_base, week)
        style = ET.SubElement(doc, q + "Style", id=f"track{k}")
        ls = ET.SubElement(style, q + "LineStyle")
        ET.SubElement(ls, q + "color").text = colors[k % len(colors)]
        ET.SubElement(ls, q + "width").text = f"{width:g}"
        pm = ET.SubElement(doc, q + "Placemark")
        ET.SubElement(pm, q + "name").text = tname
        ET.SubElement(pm, q + "styleUrl").text = f"#track{k}"
        if utc is not None:  # a time per sample: Google Earth animates it
            track = ET.SubElement(pm, gx + "Track")
            ET.SubElement(track, q + "altitudeMode").text = altitude_mode
            for w in _iso(utc[idx]):
                ET.SubElement(track, q + "when").text = w
            for a, b, c in v:
                ET.SubElement(track, gx + "coord").text = f"{a:.9f} {b:.9f} {c:.3f}"
            continue
        line = ET.SubElement(pm, q + "LineString")
        ET.SubElement(line, q + "tessellate").text = "1"
        ET.SubElement(line, q + "altitudeMode").text = altitude_mode
        ET.SubElement(line, q + "coordinates").text = " ".join(
            f"{a:.9f},{b:.9f},{c:.3f}" for a, b, c in v)
    if points is not None:
        v = _llh_deg(points, points_name)
        folder = ET.SubElement(doc, q + "Folder")
        ET.SubElement(folder, q + "name").text = points_name
        for t, (a, b, c) in zip(np.asarray(points.index, float), v, strict=True):
            pm = ET.SubElement(folder, q + "Placemark")
            ET.SubElement(pm, q + "name").text = f"{t:.3f}"
            pt = ET.SubElement(pm, q + "Point")
            ET.SubElement(pt, q + "altitudeMode").text = altitude_mode
            ET.SubElement(pt, q + "coordinates").text = f"{a:.9f},{b:.9f},{c:.3f}"
    tree = ET.ElementTree(kml)
    return atomic_write(path, lambda p: tree.write(p, encoding="UTF-8", xml_declaration=True))


def write_geojson(tracks: pd.DataFrame | Mapping[str, pd.DataFrame], path: str | os.PathLike, *,
                  points: pd.DataFrame | None = None, points_name: str = "GNSS",
                  decimate: int = 1, point_interval: float | None = 1.0,
                  protect: Sequence[str | os.PathLike] = (), time_base: str | None = None,
                  week: int | None = None) -> Path:
    """Write tracks (and optional points) as a GeoJSON FeatureCollection (atomically).

    Every vertex has its time (module docstring); ``point_interval`` [s] is the spacing of the
    timed ``Point`` features per track (None: none); ``time_base`` / ``week`` override the
    tables' ``attrs``.
    """
    tr = _tracks(tracks)
    ensure_not_input(path, [*protect, *_sources(tr, points)])
    features, timed = [], []
    for tname, df in tr.items():
        idx = _decimated(len(df), decimate)
        v = _llh_deg(df, f"track {tname!r}")[idx]
        t = np.asarray(df.index, float)
        utc = utc_times(df, time_base, week)
        props = {"name": tname, "start_time": float(t[0]) if t.size else None,
                 "end_time": float(t[-1]) if t.size else None,
                 "time_base": time_base or df.attrs.get("time_base", "unspecified"),
                 "times": np.round(t[idx], 6).tolist()}
        if utc is not None:
            props["coordTimes"] = _iso(utc[idx])
        features.append({"type": "Feature", "properties": props,
                         "geometry": {"type": "LineString", "coordinates": _rounded(v)}})
        if point_interval is not None and t.size:
            if not point_interval > 0:
                raise ConfigError("point interval must be > 0 s", column="point_interval",
                                  found=repr(point_interval))
            k = idx[np.concatenate([[True], np.diff(np.floor((t[idx] - t[0]) /
                                                             point_interval)) > 0])]
            stamps = _iso(utc[k]) if utc is not None else [float(x) for x in t[k]]
            xyz = _rounded(_llh_deg(df, f"track {tname!r}")[k])
            timed += [{"type": "Feature",
                       "properties": {"track": tname, "time": s, "t": float(tk)},
                       "geometry": {"type": "Point", "coordinates": c}}
                      for s, tk, c in zip(stamps, t[k], xyz, strict=True)]
    features += timed
    if points is not None:
        v = _llh_deg(points, points_name)
        features.append({
            "type": "Feature",
            "properties": {"name": points_name,
                           "times": np.asarray(points.index, float).tolist()},
            "geometry": {"type": "MultiPoint", "coordinates": _rounded(v)},
        })
    doc = {"type": "FeatureCollection", "features": features}
    text = json.dumps(doc, allow_nan=False, separators=(",", ":"))
    return atomic_write(path, lambda p: p.write_text(text))
