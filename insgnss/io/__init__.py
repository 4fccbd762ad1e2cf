"""Readers and writers of data formats; every reader returns insgnss-convention DataFrames.

Readers validate their input (:mod:`insgnss.validate`) and raise a subclass of
:class:`insgnss.errors.InsgnssError` naming file, line, column, expected and found; repairs
(dropped duplicates, bridged gaps, skipped lines) are warned with
:class:`insgnss.errors.InsgnssWarning` and recorded in ``df.attrs``. Writers are atomic and
refuse to overwrite the paths passed as ``protect``. Formats: ``docs/formats.md``.

The names are imported on first use (:mod:`insgnss._lazy`): ``from insgnss.io import
read_table`` loads :mod:`insgnss.io.native` only, not every reader.
"""

from .._lazy import lazy_exports

#: module (relative to this package) -> the public names it defines
_MODULES = {
    "..validate": ("GapPolicy", "check_gnss_in_imu_span", "ensure_not_input", "split_segments"),
    ".imu_csv": ("ACCEL_UNITS", "GYRO_UNITS", "TIME_UNITS", "axis_map_matrix",
                 "imu_table_from_arrays", "mounting_matrix", "read_imu_csv"),
    ".kfgins": ("read_kfgins_gnss", "read_kfgins_imu", "read_kfgins_nav", "write_kfgins_nav"),
    ".native": ("atomic_write", "atomic_write_text", "decimate_table", "read_table",
                "select_output_columns", "write_parquet", "write_table"),
    ".nmea": ("read_nmea",),
    ".pyins_frames": ("from_pyins", "to_pyins"),
    ".reference": ("read_reference",),
    ".rtklib": ("TimeTag", "read_rtklib_pos", "read_rtklib_tag"),
    ".rtklibexplorer": ("DRIVE_0708", "WALK_0827", "read_rtklibexplorer_imu",
                        "rtklibexplorer_mounting"),
    ".tracks": ("read_trajectory_csv", "write_eval_csv", "write_geojson", "write_kml",
                "write_trajectory_csv"),
}
__getattr__, __dir__ = lazy_exports(
    __name__, {name: mod for mod, names in _MODULES.items() for name in names}, globals())
__all__ = sorted(name for names in _MODULES.values() for name in names)
