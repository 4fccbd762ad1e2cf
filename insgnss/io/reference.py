"""Reference trajectories for evaluation: native CSV, KF-GINS ``.nav`` or RTKLIB ``.pos``.

:func:`read_reference` picks the reader from ``format`` or the file suffix (``.csv`` native,
``.nav`` KF-GINS, ``.pos`` RTKLIB) and returns a table with at least ``lat lon height``
[rad, m]; ``.nav`` adds velocity and attitude, ``.pos`` standard deviations and ``q`` (keep
only fixed epochs with ``fix_only=True``, as the drive benchmark does).
"""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd

from ..errors import ConfigError, InputFormatError
from .kfgins import read_kfgins_nav
from .rtklib import read_rtklib_pos
from .tracks import read_trajectory_csv

REFERENCE_FORMATS = {"native": ".csv", "kfgins-nav": ".nav", "rtklib-pos": ".pos"}


def reference_format(path: str | os.PathLike, format: str | None = None) -> str:
    """The reference format named by ``format`` or implied by the suffix of ``path``."""
    if format is not None:
        if format not in REFERENCE_FORMATS:
            raise ConfigError("unknown reference format", column="format",
                              expected=", ".join(REFERENCE_FORMATS), found=repr(format))
        return format
    suffix = Path(path).suffix.lower()
    for name, ext in REFERENCE_FORMATS.items():
        if suffix == ext:
            return name
    raise ConfigError("cannot tell the reference format from the file name", file=path,
                      column="format", expected="a .csv, .nav or .pos file or format=",
                      found=repr(suffix))


def read_reference(path: str | os.PathLike, format: str | None = None, *, fix_only: bool = False,
                   week: int | None = None, time_base: str = "gps", allocate=None
                   ) -> pd.DataFrame:
    """Read a reference trajectory.

    Parameters
    ----------
    path : path
    format : {"native", "kfgins-nav", "rtklib-pos"}, optional
        Default: from the suffix.
    fix_only : bool
        RTKLIB only: keep Q=1 epochs (``attrs["dropped_not_fixed"]`` counts the others).
    week : int, optional
        KF-GINS only: GPS week for seconds-of-week files.
    time_base : {"gps", "sow", "unix_gpst"}
        RTKLIB only: time base of the index.
    allocate : callable, optional
        Native only: where the values are made (:func:`.tracks.read_trajectory_csv`; a
        :class:`insgnss.io.spill.SpillAllocator` holds a long reference on a memory-mapped
        file).
    """
    fmt = reference_format(path, format)
    if fmt == "native":
        return read_trajectory_csv(path, allocate=allocate)
    if fmt == "kfgins-nav":
        return read_kfgins_nav(path, week=week)
    df = read_rtklib_pos(path, time_base=time_base)
    if fix_only:
        keep = (df["q"] == 1).to_numpy() if "q" in df.columns else None
        if keep is None:
            raise InputFormatError("no Q column to select fixed epochs", file=path, column="Q")
        attrs = dict(df.attrs)
        out = df.loc[keep].copy()
        if not len(out):
            raise InputFormatError("no fixed (Q=1) epoch", file=path, column="Q",
                                   expected="at least one Q=1 epoch", found="none")
        attrs["source_rows"] = attrs["source_rows"][keep]
        attrs["dropped_not_fixed"] = int((~keep).sum())
        out.attrs = attrs
        return out
    return df
