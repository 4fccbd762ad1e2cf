"""Writers: native trajectory CSV, scorer CSV, KML, GeoJSON (parsed back); reference reader."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pandas as pd
import pytest
from io_helpers import T0_GPS, pos_text, trajectory

from insgnss.errors import ConfigError, InputFormatError, InvalidValueError, TimeOrderError
from insgnss.io import (
    read_reference,
    read_table,
    read_trajectory_csv,
    write_eval_csv,
    write_geojson,
    write_kml,
    write_trajectory_csv,
)

KML = "{http://www.opengis.net/kml/2.2}"
GX = "{http://www.google.com/kml/ext/2.2}"


def traj(n=40):
    t, lat, lon, h, vel = trajectory(n, dt=0.01)
    rng = np.random.default_rng(5)
    df = pd.DataFrame({"lat": lat, "lon": lon, "height": h, "vel_e": vel[:, 0], "vel_n": vel[:, 1],
                       "vel_u": vel[:, 2], "roll": rng.uniform(-0.1, 0.1, n),
                       "pitch": rng.uniform(-0.1, 0.1, n), "heading": rng.uniform(0, 6.28, n),
                       "east_std": np.full(n, 0.02)}, index=pd.Index(t, name="time"))
    df.attrs["time_base"] = "gps"
    return df


def test_trajectory_csv_round_trip(tmp_path):
    df = traj()
    df.loc[df.index[3], "east_std"] = np.nan
    p = write_trajectory_csv(df, tmp_path / "traj.csv")
    assert p.read_text().splitlines()[0].startswith("time,lat_deg,lon_deg,height,")
    back = read_trajectory_csv(p)
    np.testing.assert_allclose(back.index, df.index, rtol=0, atol=1e-5)  # 15 digits of GPS s
    np.testing.assert_allclose(back[["lat", "lon"]], df[["lat", "lon"]], rtol=1e-14)
    np.testing.assert_allclose(back.drop(columns=["lat", "lon"]), df.drop(columns=["lat", "lon"]),
                               rtol=1e-13)
    assert np.isnan(back["east_std"].iloc[3])
    # the lead's native reader reads it too
    np.testing.assert_allclose(read_table(p)["heading"], df["heading"], rtol=1e-13)


def test_trajectory_csv_reader_validates(tmp_path):
    df = traj(10)
    p = write_trajectory_csv(df, tmp_path / "t.csv")
    lines = p.read_text().splitlines()
    bad = lines.copy()
    bad[4] = bad[4].replace(bad[4].split(",")[1], "nan", 1)
    (tmp_path / "b.csv").write_text("\n".join(bad))
    with pytest.raises(InvalidValueError) as e:
        read_trajectory_csv(tmp_path / "b.csv")
    assert (e.value.row, e.value.column) == (5, "lat_deg")
    bad = lines[:3] + [lines[4], lines[3]] + lines[5:]
    (tmp_path / "b.csv").write_text("\n".join(bad))
    with pytest.raises(TimeOrderError) as e:
        read_trajectory_csv(tmp_path / "b.csv")
    assert e.value.row == 5
    (tmp_path / "b.csv").write_text("\n".join([lines[0].replace("height", "h")] + lines[1:]))
    with pytest.raises(InputFormatError) as e:
        read_trajectory_csv(tmp_path / "b.csv")
    assert (e.value.row, e.value.column) == (1, "height")


def test_eval_csv(tmp_path):
    df = traj(5)
    sow = df.copy()
    sow.index = df.index - 2374 * 604800.0
    sow.attrs = {"time_base": "sow", "gps_week": 2374}
    for table in (df, sow):
        p = write_eval_csv(table, tmp_path / "sol.csv")
        out = pd.read_csv(p)
        assert list(out.columns) == ["time_gpst_s", "lat_deg", "lon_deg", "height_m", "roll_deg",
                                     "pitch_deg", "yaw_deg"]
        np.testing.assert_allclose(out["time_gpst_s"], df.index, atol=1e-6)
        np.testing.assert_allclose(out["lat_deg"], np.degrees(df["lat"]), atol=1e-10)
        yaw = np.degrees(np.angle(np.exp(1j * df["heading"].to_numpy())))
        np.testing.assert_allclose(out["yaw_deg"], yaw, atol=1e-8)
    sow.attrs = {"time_base": "sow"}
    with pytest.raises(ConfigError, match="week"):
        write_eval_csv(sow, tmp_path / "x.csv")


def test_kml_parses_back(tmp_path):
    fwd, smo = traj(30), traj(30)
    smo["height"] += 1.0
    gnss = traj(30).iloc[::10]
    p = write_kml({"forward": fwd, "smoothed <&>": smo}, tmp_path / "track.kml", points=gnss,
                  decimate=4)
    root = ET.parse(p).getroot()
    assert root.tag == KML + "kml"
    pms = root.findall(f".//{KML}Placemark")
    names = [pm.find(KML + "name").text for pm in pms]
    assert names[:2] == ["forward", "smoothed <&>"] and len(names) == 2 + 3
    # GPS time stamps: a gx:Track with a UTC time per sample
    coords = [[float(x) for x in c.text.split()] for c in pms[1].findall(f".//{GX}coord")]
    idx = [0, 4, 8, 12, 16, 20, 24, 28, 29]
    np.testing.assert_allclose(np.array(coords)[:, 0], np.degrees(smo["lon"].to_numpy()[idx]), atol=1e-9)
    np.testing.assert_allclose(np.array(coords)[:, 1], np.degrees(smo["lat"].to_numpy()[idx]), atol=1e-9)
    np.testing.assert_allclose(np.array(coords)[:, 2], smo["height"].to_numpy()[idx], atol=1e-3)
    pt = [float(x) for x in pms[3].find(f".//{KML}coordinates").text.split(",")]
    assert pt[1] == pytest.approx(np.degrees(gnss["lat"].iloc[1]), abs=1e-9)


def test_geojson_parses_back(tmp_path):
    df = traj(25)
    gnss = df.iloc[::5]
    p = write_geojson(df, tmp_path / "track.geojson", points=gnss)
    doc = json.loads(p.read_text())
    # the line, one timed point per second of the track (0.25 s: one), the GNSS points
    assert doc["type"] == "FeatureCollection" and len(doc["features"]) == 3
    line = doc["features"][0]
    assert line["geometry"]["type"] == "LineString"
    xyz = np.array(line["geometry"]["coordinates"])
    np.testing.assert_allclose(xyz[:, 0], np.degrees(df["lon"]), atol=1e-9)
    np.testing.assert_allclose(xyz[:, 1], np.degrees(df["lat"]), atol=1e-9)
    np.testing.assert_allclose(xyz[:, 2], df["height"], atol=1e-3)
    assert line["properties"]["start_time"] == pytest.approx(T0_GPS)
    pts = doc["features"][2]
    assert pts["geometry"]["type"] == "MultiPoint" and len(pts["geometry"]["coordinates"]) == 5
    assert pts["properties"]["times"] == pytest.approx(gnss.index.tolist())


def test_writers_refuse_bad_input_and_input_paths(tmp_path):
    df = traj(5)
    src = tmp_path / "in.csv"
    src.write_text("x")
    for writer in (write_trajectory_csv, write_eval_csv, write_kml, write_geojson):
        with pytest.raises(ConfigError):
            writer(df, src, protect=[src])
        assert src.read_text() == "x"
    bad = df.copy()
    bad.loc[bad.index[2], "lat"] = np.nan
    for writer in (write_kml, write_geojson, write_eval_csv):
        with pytest.raises(InvalidValueError) as e:
            writer(bad, tmp_path / "o.out")
        assert (e.value.row, e.value.column) == (3, "lat")
    assert not (tmp_path / "o.out").exists()
    with pytest.raises(ConfigError):
        write_kml(df, tmp_path / "o.kml", altitude_mode="sea")
    with pytest.raises(ConfigError):
        write_geojson(df, tmp_path / "o.json", decimate=0)


def test_reference_reader_formats(tmp_path):
    t, lat, lon, h, vel = trajectory(8)
    q = np.array([1, 1, 2, 1, 1, 5, 1, 1])
    p = tmp_path / "ref.pos"
    p.write_text(pos_text(t, lat, lon, h, q=q, vel=vel))
    ref = read_reference(p)
    assert len(ref) == 8 and ref.attrs["format"] == "rtklib-pos"
    fixed = read_reference(p, fix_only=True)
    assert len(fixed) == 6 and fixed.attrs["dropped_not_fixed"] == 2
    assert fixed.attrs["source_rows"].tolist() == [4, 5, 7, 8, 10, 11]
    csv = write_trajectory_csv(traj(6), tmp_path / "ref.csv")
    assert read_reference(csv).attrs["format"] == "native"
    with pytest.raises(ConfigError):
        read_reference(tmp_path / "ref.txt")
    with pytest.raises(ConfigError):
        read_reference(p, format="gpx")


def test_real_reference_fixed_epochs(drive_dir):
    ref = read_reference(drive_dir / "gnss_1934_sf.pos", fix_only=True)
    assert len(ref) == 2189 and (ref["q"] == 1).all()


def test_a_table_is_never_written_over_its_own_source(tmp_path):
    p = write_trajectory_csv(traj(5), tmp_path / "a.csv")
    before = p.read_bytes()
    back = read_trajectory_csv(p)
    for writer in (write_trajectory_csv, write_eval_csv, write_kml, write_geojson):
        with pytest.raises(ConfigError, match="overwrite an input"):
            writer(back, p)
    with pytest.raises(ConfigError):
        write_kml(traj(5), p, points=back)
    assert p.read_bytes() == before


def _utc_iso(t_gps):
    """ISO UTC of GPS seconds, computed independently: GPS - UTC = 18 s since 2017."""
    d = np.datetime64("1980-01-06T00:00:00", "ms") + np.round(
        (np.asarray(t_gps, float) - 18.0) * 1000).astype("timedelta64[ms]")
    return [f"{x}Z" for x in np.datetime_as_string(d, unit="ms")]


def test_kml_and_geojson_tracks_carry_utc_times(tmp_path):
    """Google Earth animates a gx:Track by its <when> (UTC), QGIS's temporal controller the
    Point features by their time; both from the GPS time stamps, leap seconds removed."""
    t0 = T0_GPS  # 2025-07-08 19:34:18.499 GPST = 19:34:00.499 UTC
    df = traj(400).iloc[::10]  # 0.1 s apart, 4 s
    root = ET.parse(write_kml({"forward": df}, tmp_path / "t.kml")).getroot()
    track = root.find(f".//{GX}Track")
    when = [w.text for w in track.findall(f"{KML}when")]
    assert when[0] == "2025-07-08T19:34:00.499Z"
    assert when == _utc_iso(df.index)
    assert len(track.findall(f"{GX}coord")) == len(df)
    doc = json.loads(write_geojson({"forward": df}, tmp_path / "t.geojson").read_text())
    line = doc["features"][0]
    assert line["properties"]["coordTimes"] == _utc_iso(df.index)
    assert line["properties"]["times"] == pytest.approx(df.index.tolist())
    pts = [f for f in doc["features"] if f["geometry"]["type"] == "Point"]
    assert [p["properties"]["t"] for p in pts] == pytest.approx(t0 + np.arange(4.0), abs=1e-6)
    assert pts[1]["properties"]["time"] == "2025-07-08T19:34:01.499Z"
    assert pts[1]["geometry"]["coordinates"][1] == pytest.approx(
        np.degrees(df["lat"].iloc[10]), abs=1e-9)
    # seconds of week with the week known; and a relative clock: no calendar time
    sow = df.set_axis(df.index - 2374 * 604800.0, axis=0)
    sow.attrs = {"time_base": "sow", "gps_week": 2374}
    root = ET.parse(write_kml(sow, tmp_path / "s.kml")).getroot()
    assert root.find(f".//{KML}when").text == "2025-07-08T19:34:00.499Z"
    rel = df.set_axis(df.index - t0, axis=0)
    rel.attrs = {"time_base": "unspecified"}
    root = ET.parse(write_kml(rel, tmp_path / "r.kml")).getroot()
    assert root.find(f".//{GX}Track") is None and root.find(f".//{KML}LineString") is not None
    doc = json.loads(write_geojson(rel, tmp_path / "r.geojson").read_text())
    assert "coordTimes" not in doc["features"][0]["properties"]
    assert doc["features"][1]["properties"]["time"] == pytest.approx(0.0)


def test_job_outputs_timed_tracks(tmp_path):
    """A job on GPS-time data writes animated tracks: forward.kml's gx:Track and
    forward.geojson's coordTimes hold the UTC times of the written samples."""
    from example_data import T0, generate_for

    from insgnss.config import load_job_dict
    from insgnss.pipeline import run_job, write_outputs

    job, _ = generate_for({"job": {"time_base": "gps"},
                           "inputs": {"imu": {"format": "native", "path": "imu.csv"},
                                      "gnss": {"format": "rtklib_pos", "path": "gnss.pos"}},
                           "initialization": {"static_duration": 20.0},
                           "outputs": {"report": False, "progress": False,
                                       "formats": ["csv", "kml", "geojson"]}}, tmp_path)
    res = run_job(load_job_dict(job, tmp_path / "job.toml"), progress=False)
    write_outputs(res, tmp_path / "out")
    root = ET.parse(tmp_path / "out" / "forward.kml").getroot()
    when = [w.text for w in root.iter(f"{KML}when")]
    csv = read_table(tmp_path / "out" / "forward.csv")
    assert len(when) == len(csv) and when == _utc_iso(csv.index)
    assert when[0].startswith("2025-07-08T19:33:42")  # T0 = 19:34:00 GPST, UTC 18 s earlier
    doc = json.loads((tmp_path / "out" / "smoothed.geojson").read_text())
    assert doc["features"][0]["properties"]["coordTimes"][0] == when[0]
    assert T0 <= csv.index[0] < T0 + 30
