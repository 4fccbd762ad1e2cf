"""Readers and writers of data formats; every reader returns insgnss-convention DataFrames.

Readers validate their input (:mod:`insgnss.validate`) and raise a subclass of
:class:`insgnss.errors.InsgnssError` naming file, line, column, expected and found; repairs
(dropped duplicates, bridged gaps, skipped lines) are warned with
:class:`insgnss.errors.InsgnssWarning` and recorded in ``df.attrs``. Writers are atomic and
refuse to overwrite the paths passed as ``protect``. Formats: ``docs/formats.md``.
"""

from ..validate import GapPolicy, check_gnss_in_imu_span, ensure_not_input, split_segments
from .imu_csv import (
    ACCEL_UNITS,
    GYRO_UNITS,
    TIME_UNITS,
    axis_map_matrix,
    imu_table_from_arrays,
    mounting_matrix,
    read_imu_csv,
)
from .kfgins import read_kfgins_gnss, read_kfgins_imu, read_kfgins_nav, write_kfgins_nav
from .native import atomic_write, atomic_write_text, read_table, write_table
from .nmea import read_nmea
from .reference import read_reference
from .rtklib import TimeTag, read_rtklib_pos, read_rtklib_tag
from .rtklibexplorer import DRIVE_0708, WALK_0827, read_rtklibexplorer_imu, rtklibexplorer_mounting
from .tracks import read_trajectory_csv, write_eval_csv, write_geojson, write_kml, write_trajectory_csv

__all__ = [
    "ACCEL_UNITS", "DRIVE_0708", "GYRO_UNITS", "TIME_UNITS", "WALK_0827", "GapPolicy", "TimeTag",
    "atomic_write", "atomic_write_text", "axis_map_matrix", "check_gnss_in_imu_span",
    "ensure_not_input", "imu_table_from_arrays", "mounting_matrix", "read_imu_csv",
    "read_kfgins_gnss", "read_kfgins_imu", "read_kfgins_nav", "read_nmea", "read_reference",
    "read_rtklib_pos", "read_rtklib_tag", "read_rtklibexplorer_imu", "read_table",
    "read_trajectory_csv", "rtklibexplorer_mounting", "split_segments", "write_eval_csv",
    "write_geojson", "write_kfgins_nav", "write_kml", "write_table", "write_trajectory_csv",
]
