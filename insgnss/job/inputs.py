"""Inputs of a job: read the files a job names (or simulate its scenario) into tables in insgnss
conventions (docs/conventions.md), and build the filter's IMU error model.

Readers live in :mod:`insgnss.io`; this module only picks the reader and its arguments from
the job (``[inputs.*]``) and returns plain data (:class:`Inputs`). No navigation math.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..checks import check_latitude_radians
from ..config import Job
from ..errors import ConfigError, InputFormatError
from ..imu import ImuErrorModel, grade, is_increment_table, triad_blocks
from ..io.spill import SpillAllocator, release_frame, trim_heap
from ..policies import gap_policy
from ..validate import check_time_bases


@dataclass
class Inputs:
    """Data of a job, in insgnss conventions."""

    imu: pd.DataFrame
    gnss: pd.DataFrame | None = None
    #: raw receiver observations (``[inputs.gnss_raw]``, :class:`insgnss.gnss.RawGnss`)
    gnss_raw: object | None = None
    #: their single-point solution (:func:`insgnss.gnss.spp`; clock, positions)
    spp: pd.DataFrame | None = None
    odometer: pd.DataFrame | None = None
    reference: pd.DataFrame | None = None
    reference_point: str = "antenna"
    control_points: pd.DataFrame | None = None
    lever_arm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    imu_model: ImuErrorModel | None = None
    truth: pd.DataFrame | None = None
    sensor_truth: pd.DataFrame | None = None  #: simulated IMU errors (SimulationResult.sensor_errors)
    source: str = "files"
    seed: int | None = None


#: ``[filter.imu_model]`` key -> :class:`~insgnss.imu.ImuErrorModel` field
_MODEL_FIELDS = {"gyro_bias_deg_h": "gyro_bias", "accel_bias_mg": "accel_bias",
                 "gyro_bias_instability_deg_h": "gyro_bias_instability",
                 "accel_bias_instability_ug": "accel_bias_instability",
                 "bias_correlation_time_s": "bias_correlation_time",
                 "gyro_arw_deg_sqrt_h": "gyro_arw", "accel_vrw_m_s_sqrt_h": "accel_vrw",
                 "gyro_scale_ppm": "gyro_scale", "accel_scale_ppm": "accel_scale"}


def imu_model(job: Job, default: ImuErrorModel | None) -> ImuErrorModel:
    """The filter's IMU error model: ``[filter] imu_grade`` (else ``default``, else tactical)
    with the ``[filter.imu_model]`` datasheet overrides."""
    f = job["filter"]
    if f["imu_grade"] is not None:
        base = grade(f["imu_grade"])
    elif default is not None:
        base = default
    else:
        base = grade("tactical")
    over = {k: v for k, v in f["imu_model"].items() if v is not None}
    if not over:
        return base
    ds = ImuErrorModel.from_datasheet(**over)
    changes = {_MODEL_FIELDS[k]: getattr(ds, _MODEL_FIELDS[k]) for k in over}
    return base.scaled(**changes, name=f"{base.name}+overrides")


def input_allocator(job: Job, spill_dir=None) -> SpillAllocator:
    """Where the long input arrays (the IMU triads, a native reference) are made: in memory
    up to ``filter.store_memory_mb`` (the budget of the engine's store, counted separately),
    memory-mapped in ``spill_dir`` beyond it (default: the system's temporary folder;
    :mod:`insgnss.io.spill`). The pages of a mapped table are given back after each stage
    that reads it (:func:`insgnss.io.spill.release_frame`), so the inputs of a long log are
    not resident between the stages that use them."""
    return SpillAllocator(job["filter"]["store_memory_mb"] * 2.0**20, spill_dir)


def read_imu(job: Job, allocate=None) -> pd.DataFrame:
    """The IMU table of ``[inputs.imu]`` (body frame, SI, time in the job's time base), each
    sensor triad held as one (N, 3) array made by ``allocate`` (:func:`insgnss.imu.
    triad_blocks`: the filter uses the increments without a copy)."""
    table = _read_imu_table(job)
    try:
        is_increment_table(table)  # the columns, checked before the triads are made
    except ValueError as exc:
        raise InputFormatError(str(exc), file=job.resolve(job["inputs"]["imu"]["path"]),
                               row=1) from None
    out = triad_blocks(table, allocate)
    del table  # the reader's block of all fields goes before the next input is read
    trim_heap()
    release_frame(out)
    return out


def _read_imu_table(job: Job) -> pd.DataFrame:
    spec = job["inputs"]["imu"]
    path = job.resolve(spec["path"])
    if path is None:
        raise ConfigError("no IMU file given", file=job.path, column="inputs.imu.path")
    fmt = spec["format"]
    if fmt == "rtklibexplorer":
        from ..io.rtklibexplorer import read_rtklibexplorer_imu

        if spec["mounting_deg"] is None:
            raise ConfigError("the rtklibexplorer format needs the declared mounting",
                              file=job.path, column="inputs.imu.mounting_deg")
        return read_rtklibexplorer_imu(path, mounting_rpy_deg=spec["mounting_deg"],
                                       tag_path=job.resolve(spec["tag"]),
                                       time_offset=spec["time_offset"], rate_hz=spec["rate_hz"],
                                       gap_policy=gap_policy(job),
                                       duplicates=spec["duplicates"])
    if fmt == "kfgins":
        from ..io.kfgins import read_kfgins_imu

        return read_kfgins_imu(path, gap_policy=gap_policy(job), duplicates=spec["duplicates"])
    if fmt == "native":
        from ..io.tracks import read_trajectory_csv

        return read_trajectory_csv(path, required=(), duplicates=spec["duplicates"])
    from ..io.imu_csv import read_imu_csv

    return read_imu_csv(path, columns=spec["columns"], gyro_unit=spec["gyro_unit"],
                        accel_unit=spec["accel_unit"], time_unit=spec["time_unit"],
                        time_offset=spec["time_offset"], axis_map=spec["axis_map"],
                        mounting_euler_deg=spec["mounting_deg"], sensor_axes=spec["sensor_axes"],
                        euler_convention=spec["mounting_convention"], rate_hz=spec["rate_hz"],
                        delimiter=spec["delimiter"], header=spec["header"],
                        header_rows=spec["header_rows"], gap_policy=gap_policy(job),
                        duplicates=spec["duplicates"])


def read_gnss(job: Job) -> pd.DataFrame | None:
    """The GNSS table of ``[inputs.gnss]`` (None without a file)."""
    spec = job["inputs"]["gnss"]
    path = job.resolve(spec["path"])
    if path is None:
        return None
    fmt = spec["format"]
    if fmt == "rtklib_pos":
        from ..io.rtklib import read_rtklib_pos

        g = read_rtklib_pos(path, duplicates=spec["duplicates"])
    elif fmt == "nmea":
        from ..io.nmea import read_nmea

        g = read_nmea(path, date=spec["date"], duplicates=spec["duplicates"])
    elif fmt == "kfgins":
        from ..io.kfgins import read_kfgins_gnss

        g = read_kfgins_gnss(path, duplicates=spec["duplicates"])
    else:
        from ..io.tracks import read_trajectory_csv

        g = read_trajectory_csv(path, duplicates=spec["duplicates"])
    if spec["time_offset"]:
        g = g.set_axis(g.index + spec["time_offset"], axis=0)
    return g


def gnss_model_config(job: Job):
    """Masks of the raw GNSS measurements (``[inputs.gnss_raw]``) as a
    :class:`insgnss.gnss.GnssModelConfig`."""
    from ..gnss import GnssModelConfig

    spec = job["inputs"]["gnss_raw"]
    return GnssModelConfig(elevation_mask=float(np.radians(spec["elevation_mask_deg"])),
                           cn0_mask=float(spec["cn0_mask"]))


def read_gnss_raw(job: Job):
    """The raw receiver data of ``[inputs.gnss_raw]`` (:class:`insgnss.gnss.RawGnss`) and its
    single-point solution (a GNSS table, :func:`insgnss.gnss.spp_gnss_table`); ``(None,
    None)`` without a file."""
    spec = job["inputs"]["gnss_raw"]
    path = job.resolve(spec["path"])
    if path is None:
        return None, None
    from ..gnss import RawGnss, SppConfig, load_ubx, spp_gnss_table

    if spec["format"] == "rinex":
        nav = job.resolve(spec["nav_path"])
        if nav is None:
            raise ConfigError("RINEX observations need a navigation file", file=job.path,
                              column="inputs.gnss_raw.nav_path")
        raw = RawGnss.from_rinex(path, nav)
    else:
        raw = load_ubx(path)
    sol = spp_gnss_table(raw, SppConfig(model=gnss_model_config(job)))
    sol.attrs.setdefault("source", str(path))
    sol.attrs.setdefault("time_base", "gps")
    return raw, sol


def read_reference(job: Job, allocate=None) -> pd.DataFrame | None:
    """The reference trajectory of ``[inputs.reference]`` (None without a file). A native
    table is made by ``allocate`` (:func:`input_allocator`: a long one on a memory-mapped
    file): the evaluation reads it in blocks and gives each block's pages back, so the
    reference of a long log (0.6 GB for 10 h at 200 Hz) is not resident at once."""
    spec = job["inputs"]["reference"]
    path = job.resolve(spec["path"])
    if path is None:
        return None
    if spec["format"] == "rtklib_pos":
        from ..io.rtklib import read_rtklib_pos

        ref = read_rtklib_pos(path)
        if spec["q"] is not None:
            ref = ref[ref["q"].isin([float(q) for q in spec["q"]])]
    else:
        from ..io.reference import read_reference as read

        ref = read(path, "kfgins-nav" if spec["format"] == "kfgins_nav" else "native",
                   allocate=allocate)
    return ref


def load_inputs(job: Job, seed: int | None = None, spill_dir=None) -> Inputs:
    """Read (or simulate, for a job that carries a scenario) all inputs of a job;
    ``spill_dir``: where long input arrays are memory-mapped (:func:`input_allocator`)."""
    la = np.asarray(job["inputs"]["gnss"]["lever_arm"], float)  # 3 finite numbers (config)
    if job.simulation and job["inputs"]["imu"]["path"] is None:
        from ..simulate.scenario import simulate_scenario

        sim = simulate_scenario(dict(job.simulation), seed=seed)
        sim_la = np.asarray(job.simulation.get("gnss", {}).get("lever_arm", la), float)
        truth = sim.truth
        step = max(1, int(round(0.1 / np.median(np.diff(truth.index.to_numpy()[:100])))))
        sim_grade = job.simulation.get("imu", {}).get("grade")
        return Inputs(imu=sim.imu, gnss=sim.gnss, odometer=sim.odometer,
                      reference=truth.iloc[::step], reference_point="imu",
                      lever_arm=sim_la, truth=truth, sensor_truth=sim.sensor_errors(),
                      source="simulation", seed=sim.seed,
                      imu_model=imu_model(job, grade(sim_grade) if sim_grade else None))
    allocate = input_allocator(job, spill_dir)
    imu = read_imu(job, allocate)
    gnss = read_gnss(job)
    raw, sol = read_gnss_raw(job)
    if gnss is None:
        gnss = sol  # the loosely coupled input (and the initialization's) from the raw data
    odo = None
    o = job["inputs"]["odometer"]
    if o["path"] is not None:
        from ..io.odometer import read_odometer
        from ..preprocess import shift_time

        odo = read_odometer(job.resolve(o["path"]), kind=o["kind"], format=o["format"],
                            unit=o["unit"])
        odo = shift_time(odo, o["time_offset"]) if o["time_offset"] else odo
    cp = None
    if job["inputs"]["control_points"]["path"] is not None:
        from ..io.native import read_table

        cp = read_table(job.resolve(job["inputs"]["control_points"]["path"]),
                        required=["lat", "lon", "height"])
    ref = read_reference(job, allocate)
    check_time_bases({"IMU": imu, "GNSS": gnss, "odometer": odo, "reference": ref,
                      "control points": cp}, job["job"]["time_base"], file=job.path)
    for table, what in ((gnss, "GNSS table"), (ref, "reference"), (cp, "control points")):
        check_latitude_radians(table, what=what)  # degrees in a radians column
    if ref is not None:
        release_frame(ref)  # a mapped reference: the pages the checks read go back
    return Inputs(imu=imu, gnss=gnss, gnss_raw=raw, spp=sol, odometer=odo, reference=ref,
                  reference_point=job["inputs"]["reference"]["point"], control_points=cp,
                  lever_arm=la, imu_model=imu_model(job, None))


__all__ = ["Inputs", "gnss_model_config", "imu_model", "input_allocator", "load_inputs",
           "read_gnss", "read_gnss_raw", "read_imu", "read_reference"]
