"""IMU data conventions, deterministic error compensation, increments, grade presets.

IMU tables
----------
An IMU table is a pandas DataFrame indexed by time [s] in the body frame (right-forward-up),
holding either

- **rates**: ``gyro_x gyro_y gyro_z`` [rad/s] and ``accel_x accel_y accel_z`` [m/s^2], samples
  taken at the index time (an instantaneous, possibly low-pass filtered, reading); or
- **increments**: ``dtheta_x dtheta_y dtheta_z`` [rad] and ``dv_x dv_y dv_z`` [m/s], each row
  holding the integral over the interval that *ends* at its time stamp.

:func:`increments` turns either into the per-interval increments the mechanization consumes:
rates are integrated with the trapezoidal rule (the classic LLF mechanization's rule applied to
angular rate and specific force), increments are taken as they are.

Error model
-----------
Deterministic compensation (Noureldin et al. 2013, ch. 4)::

    x_hat = (I + S + N)^-1 (x - b)

with bias ``b``, scale-factor matrix ``S = diag(s)`` and non-orthogonality matrix ``N``
(off-diagonal, rad). Grade presets describe the stochastic errors in SI units; the
datasheet-unit conversions are all in :class:`ImuErrorModel.from_datasheet`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np
import pandas as pd

GYRO_COLS = ["gyro_x", "gyro_y", "gyro_z"]
ACCEL_COLS = ["accel_x", "accel_y", "accel_z"]
DTHETA_COLS = ["dtheta_x", "dtheta_y", "dtheta_z"]
DV_COLS = ["dv_x", "dv_y", "dv_z"]
RATE_COLS = GYRO_COLS + ACCEL_COLS
INCREMENT_COLS = DTHETA_COLS + DV_COLS

# --- units: one place for every datasheet conversion -----------------------------------------
DEG = np.pi / 180.0
G0 = 9.80665  #: standard gravity used by datasheets for "g", "mg", "ug" [m/s^2]
DEG_PER_HOUR = DEG / 3600.0  #: deg/h -> rad/s
DEG_PER_SQRT_HOUR = DEG / 60.0  #: deg/sqrt(h) -> rad/sqrt(s)   (ARW)
M_S_PER_SQRT_HOUR = 1.0 / 60.0  #: m/s/sqrt(h) -> m/s/sqrt(s)    (VRW)
MG = 1e-3 * G0  #: mg -> m/s^2
UG = 1e-6 * G0  #: ug -> m/s^2
PPM = 1e-6  #: ppm -> fraction
DEG_PER_HOUR_PER_SQRT_HOUR = DEG / 3600.0 / 60.0  #: deg/h/sqrt(h) -> rad/s/sqrt(s) (RRW)
UG_PER_SQRT_HZ = UG  #: ug/sqrt(Hz) -> m/s^2/sqrt(Hz) = m/s/sqrt(s)
DEG_PER_S_PER_SQRT_HZ = DEG  #: deg/s/sqrt(Hz) -> rad/s/sqrt(Hz) = rad/sqrt(s)


def is_increment_table(imu: pd.DataFrame) -> bool:
    """True if ``imu`` holds increments (``dtheta_*``, ``dv_*``), False if rates."""
    if all(c in imu.columns for c in INCREMENT_COLS):
        return True
    if all(c in imu.columns for c in RATE_COLS):
        return False
    raise ValueError(
        "IMU table needs columns "
        f"{RATE_COLS} (rates) or {INCREMENT_COLS} (increments); found {list(imu.columns)}"
    )


def increments(imu: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time, angular increments and velocity increments of an IMU table.

    Returns
    -------
    t : (N,) array
        Sample times [s].
    dtheta, dv : (N, 3) arrays
        Increment over ``(t[k-1], t[k]]`` in row k [rad, m/s]; row 0 is zero for rate tables
        (the interval before the first sample is unknown) and as given for increment tables.
    """
    t = np.asarray(imu.index, dtype=float)
    if is_increment_table(imu):
        return t, imu[DTHETA_COLS].to_numpy(float), imu[DV_COLS].to_numpy(float)
    w = imu[GYRO_COLS].to_numpy(float)
    f = imu[ACCEL_COLS].to_numpy(float)
    return t, trapezoid_increments(t, w), trapezoid_increments(t, f)


def triad_blocks(imu: pd.DataFrame, allocate=None) -> pd.DataFrame:
    """The IMU table ``imu`` with each sensor triad (``dtheta_*`` / ``dv_*``, or ``gyro_*`` /
    ``accel_*``) held as one C-contiguous (N, 3) array, the index and any other column as
    their own arrays (same values, names, order and ``attrs``).

    A reader's table is one column-major block of all its fields: the (N, 3) triads that
    :func:`increments` hands to the filter are then strided and its process model copies them
    (two tables of the increments, 48 bytes per sample more: 0.35 GB for 10 h at 200 Hz).
    On this layout :func:`increments` returns views of the triads, used without a copy. The
    table's old arrays are released when the caller drops it. ``allocate(shape)`` makes the
    triad arrays (default ``numpy.empty``; an :class:`insgnss.io.spill.SpillAllocator` puts a
    long log's on a memory-mapped file, whose pages :func:`insgnss.io.spill.release_frame`
    gives back when the data are not in use).
    """
    first, second = (DTHETA_COLS, DV_COLS) if is_increment_table(imu) else \
        (GYRO_COLS, ACCEL_COLS)
    index = pd.Index(np.array(imu.index, dtype=float), name=imu.index.name)
    parts = []
    for cols in (first, second):
        a = (np.empty if allocate is None else allocate)((len(imu), 3))
        a[:] = imu[cols].to_numpy(float)
        parts.append(pd.DataFrame(a, index=index, columns=cols, copy=False))
    for c in imu.columns:
        if c not in first and c not in second:
            parts.append(pd.DataFrame({c: np.array(imu[c].to_numpy())}, index=index))
    out = pd.concat(parts, axis=1)[list(imu.columns)]
    out.attrs = dict(imu.attrs)
    return out


def trapezoid_increments(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Trapezoidal integral of samples ``x`` over each interval; row 0 is zero."""
    out = np.zeros_like(x, dtype=float)
    dt = np.diff(t)[:, None]
    out[1:] = 0.5 * (x[1:] + x[:-1]) * dt
    return out


def rates_table(t, gyro, accel) -> pd.DataFrame:
    """Build a rate IMU table (rad/s, m/s^2) indexed by time."""
    data = np.column_stack([np.asarray(gyro, float), np.asarray(accel, float)])
    return pd.DataFrame(data, index=pd.Index(np.asarray(t, float), name="time"), columns=RATE_COLS)


def increments_table(t, dtheta, dv) -> pd.DataFrame:
    """Build an increment IMU table (rad, m/s) indexed by time."""
    data = np.column_stack([np.asarray(dtheta, float), np.asarray(dv, float)])
    return pd.DataFrame(
        data, index=pd.Index(np.asarray(t, float), name="time"), columns=INCREMENT_COLS
    )


def _as_matrix(x, name: str, diag: bool) -> np.ndarray:
    """Scalar, per-axis 3-vector or full 3x3 matrix parameter as a 3x3 matrix."""
    a = np.asarray(x, dtype=float)
    if a.ndim == 0:
        return np.eye(3) * a if diag else np.full((3, 3), 0.0) + a * (1 - np.eye(3))
    if a.shape == (3,):
        return np.diag(a)
    if a.shape == (3, 3):
        return a
    raise ValueError(f"{name} must be a scalar, a 3-vector or a 3x3 matrix; got shape {a.shape}")


def _as_vector(x, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim == 0:
        return np.full(3, float(a))
    if a.shape == (3,):
        return a
    raise ValueError(f"{name} must be a scalar or a 3-vector; got shape {a.shape}")


def compensation_matrix(scale=0.0, nonorth=None) -> np.ndarray:
    """``(I + S + N)^-1`` for scale factor(s) ``scale`` and non-orthogonality matrix ``nonorth``.

    ``scale`` may be a scalar, a 3-vector (diagonal) or a 3x3 matrix; ``nonorth`` a 3x3 matrix
    with zero diagonal (a scalar fills all off-diagonal terms).
    """
    S = _as_matrix(scale, "scale factor", diag=True)
    N = np.zeros((3, 3)) if nonorth is None else _as_matrix(nonorth, "non-orthogonality", False)
    return np.linalg.inv(np.eye(3) + S + N)


def compensate(measurement, bias=0.0, scale=0.0, nonorth=None) -> np.ndarray:
    """Deterministic compensation ``(I + S + N)^-1 (x - b)`` (Noureldin et al. 2013, ch. 4).

    Parameters
    ----------
    measurement : (..., 3) array
        Raw rates or increments. For increments pass ``bias * dt`` as the bias.
    bias : scalar or 3-vector
    scale : scalar, 3-vector or 3x3 matrix
        Scale factor(s) as fractions (1000 ppm = 1e-3).
    nonorth : scalar or 3x3 matrix, optional
        Non-orthogonality / misalignment [rad].
    """
    x = np.asarray(measurement, dtype=float)
    return (x - _as_vector(bias, "bias")) @ compensation_matrix(scale, nonorth).T


# --- coning and sculling ------------------------------------------------------------------------
def coning_sculling(dtheta: np.ndarray, dv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two-sample (previous + current interval) coning and sculling corrections.

    ``phi_k = dtheta_k + 1/12 dtheta_{k-1} x dtheta_k`` and
    ``dv_k' = dv_k + 1/2 dtheta_k x dv_k + 1/12 (dtheta_{k-1} x dv_k + dv_{k-1} x dtheta_k)``
    (Savage 1998; Groves eqs. 5.97-5.98, single-sample-per-interval form). The rotation
    compensation term ``1/2 dtheta x dv`` is *not* included here because the mechanization
    already rotates dv with the mid-interval attitude.
    """
    dth = np.asarray(dtheta, float)
    dvv = np.asarray(dv, float)
    prev_th = np.vstack([dth[:1] * 0.0, dth[:-1]])
    prev_dv = np.vstack([dvv[:1] * 0.0, dvv[:-1]])
    phi = dth + np.cross(prev_th, dth) / 12.0
    dvc = dvv + (np.cross(prev_th, dvv) + np.cross(prev_dv, dth)) / 12.0
    return phi, dvc


# --- stochastic error model and grade presets ---------------------------------------------------
@dataclass(frozen=True)
class ImuErrorModel:
    """IMU error parameters in SI units.

    Attributes
    ----------
    gyro_bias, accel_bias : float
        Turn-on bias (1-sigma) [rad/s], [m/s^2].
    gyro_bias_instability, accel_bias_instability : float
        Bias instability (1-sigma of the first-order Gauss-Markov process) [rad/s], [m/s^2].
    bias_correlation_time : float
        Gauss-Markov correlation time [s].
    gyro_arw : float
        Angle random walk [rad/sqrt(s)] (= white rate noise density in rad/s/sqrt(Hz)).
    accel_vrw : float
        Velocity random walk [m/s/sqrt(s)].
    gyro_rrw, accel_rrw : float
        Rate random walk of the bias [rad/s/sqrt(s)], [m/s^2/sqrt(s)].
    gyro_scale, accel_scale : float
        Scale-factor error (1-sigma, fraction).
    gyro_misalignment, accel_misalignment : float
        Non-orthogonality (1-sigma) [rad].
    gyro_quantization, accel_quantization : float
        Output resolution of the increments [rad], [m/s] (0: none).
    gyro_range, accel_range : float
        Measurement range (saturation) [rad/s], [m/s^2] (0: unlimited).
    gyro_g_sensitivity : float
        g-sensitivity of the gyros (1-sigma of each element of the 3x3 matrix) [rad/s per m/s^2].
    """

    gyro_bias: float = 0.0
    accel_bias: float = 0.0
    gyro_bias_instability: float = 0.0
    accel_bias_instability: float = 0.0
    bias_correlation_time: float = 3600.0
    gyro_arw: float = 0.0
    accel_vrw: float = 0.0
    gyro_rrw: float = 0.0
    accel_rrw: float = 0.0
    gyro_scale: float = 0.0
    accel_scale: float = 0.0
    gyro_misalignment: float = 0.0
    accel_misalignment: float = 0.0
    gyro_quantization: float = 0.0
    accel_quantization: float = 0.0
    gyro_range: float = 0.0
    accel_range: float = 0.0
    gyro_g_sensitivity: float = 0.0
    name: str = "custom"
    source: str = field(default="", compare=False)

    @classmethod
    def from_datasheet(
        cls,
        *,
        gyro_bias_deg_h: float = 0.0,
        accel_bias_mg: float = 0.0,
        gyro_bias_instability_deg_h: float = 0.0,
        accel_bias_instability_ug: float = 0.0,
        bias_correlation_time_s: float = 3600.0,
        gyro_arw_deg_sqrt_h: float = 0.0,
        accel_vrw_m_s_sqrt_h: float = 0.0,
        gyro_rrw_deg_h_sqrt_h: float = 0.0,
        accel_rrw_ug_sqrt_s: float = 0.0,
        gyro_scale_ppm: float = 0.0,
        accel_scale_ppm: float = 0.0,
        gyro_misalignment_mrad: float = 0.0,
        accel_misalignment_mrad: float = 0.0,
        gyro_quantization_urad: float = 0.0,
        accel_quantization_mm_s: float = 0.0,
        gyro_range_deg_s: float = 0.0,
        accel_range_g: float = 0.0,
        gyro_g_sensitivity_deg_h_g: float = 0.0,
        name: str = "custom",
        source: str = "",
    ) -> ImuErrorModel:
        """Build a model from datasheet units (deg/h, mg, ug, deg/sqrt(h), m/s/sqrt(h), ppm,
        mrad, urad, mm/s, deg/s, g, deg/h/g)."""
        return cls(
            gyro_bias=gyro_bias_deg_h * DEG_PER_HOUR,
            accel_bias=accel_bias_mg * MG,
            gyro_bias_instability=gyro_bias_instability_deg_h * DEG_PER_HOUR,
            accel_bias_instability=accel_bias_instability_ug * UG,
            bias_correlation_time=bias_correlation_time_s,
            gyro_arw=gyro_arw_deg_sqrt_h * DEG_PER_SQRT_HOUR,
            accel_vrw=accel_vrw_m_s_sqrt_h * M_S_PER_SQRT_HOUR,
            gyro_rrw=gyro_rrw_deg_h_sqrt_h * DEG_PER_HOUR_PER_SQRT_HOUR,
            accel_rrw=accel_rrw_ug_sqrt_s * UG,
            gyro_scale=gyro_scale_ppm * PPM,
            accel_scale=accel_scale_ppm * PPM,
            gyro_misalignment=gyro_misalignment_mrad * 1e-3,
            accel_misalignment=accel_misalignment_mrad * 1e-3,
            gyro_quantization=gyro_quantization_urad * 1e-6,
            accel_quantization=accel_quantization_mm_s * 1e-3,
            gyro_range=gyro_range_deg_s * DEG,
            accel_range=accel_range_g * G0,
            gyro_g_sensitivity=gyro_g_sensitivity_deg_h_g * DEG_PER_HOUR / G0,
            name=name,
            source=source,
        )

    def to_dict(self) -> dict:
        return asdict(self)

    def scaled(self, **changes) -> ImuErrorModel:
        """A copy with some parameters replaced (SI units)."""
        return replace(self, **changes)


#: Grade presets. Values are typical of the class, not of one product (docs/filter.md, "IMU
#: grade presets", lists every number); sources: Groves (2013) table 4.1 and section 4.4;
#: Noureldin et al. (2013) table 4.2; datasheets of Honeywell HG9900 (navigation), HG1700 (RLG)
#: and KVH 1750 (FOG) (tactical), Honeywell HG4930, Analog Devices ADIS16495-1, Epson G370 and
#: Safran STIM300 (tactical MEMS), Bosch BMI088 / TDK ICM-20948 (consumer MEMS).
#:
#: The turn-on bias is the run-to-run (repeatability, over temperature) 1-sigma the filter must
#: start from; the bias instability the in-run floor of the Allan deviation. They differ most for
#: MEMS parts: a tactical MEMS gyro drifts by about 1 deg/h within a run but turns on tens to a
#: few hundred deg/h away from its last calibration (ADIS16495-1: 0.8 deg/h in-run, Epson G370:
#: 0.8 deg/h in-run and an initial bias of up to 0.1 deg/s = 360 deg/h), which rules out
#: gyrocompassing (the horizontal Earth rate is 15 cos(lat) deg/h).
GRADES: dict[str, ImuErrorModel] = {
    "navigation": ImuErrorModel.from_datasheet(
        gyro_bias_deg_h=0.003, accel_bias_mg=0.025,
        gyro_bias_instability_deg_h=0.003, accel_bias_instability_ug=10.0,
        bias_correlation_time_s=3600.0,
        gyro_arw_deg_sqrt_h=0.002, accel_vrw_m_s_sqrt_h=0.003,
        gyro_scale_ppm=5.0, accel_scale_ppm=100.0,
        gyro_misalignment_mrad=0.005, accel_misalignment_mrad=0.01,
        name="navigation", source="HG9900-class; Groves 2013 table 4.1",
    ),
    "tactical": ImuErrorModel.from_datasheet(
        gyro_bias_deg_h=1.0, accel_bias_mg=1.0,
        gyro_bias_instability_deg_h=0.5, accel_bias_instability_ug=50.0,
        bias_correlation_time_s=1800.0,
        gyro_arw_deg_sqrt_h=0.125, accel_vrw_m_s_sqrt_h=0.03,
        gyro_scale_ppm=150.0, accel_scale_ppm=300.0,
        gyro_misalignment_mrad=0.1, accel_misalignment_mrad=0.1,
        name="tactical", source="HG1700/KVH1750-class; Groves 2013 table 4.1",
    ),
    "tactical_mems": ImuErrorModel.from_datasheet(
        gyro_bias_deg_h=100.0, accel_bias_mg=2.0,
        gyro_bias_instability_deg_h=1.0, accel_bias_instability_ug=20.0,
        bias_correlation_time_s=600.0,
        gyro_arw_deg_sqrt_h=0.1, accel_vrw_m_s_sqrt_h=0.03,
        gyro_scale_ppm=500.0, accel_scale_ppm=300.0,
        gyro_misalignment_mrad=0.5, accel_misalignment_mrad=0.5,
        name="tactical_mems",
        source="HG4930/ADIS16495/G370/STIM300-class MEMS: deg/h in-run, ~100 deg/h turn-on",
    ),
    "consumer": ImuErrorModel.from_datasheet(
        gyro_bias_deg_h=360.0, accel_bias_mg=20.0,
        gyro_bias_instability_deg_h=10.0, accel_bias_instability_ug=100.0,
        bias_correlation_time_s=300.0,
        gyro_arw_deg_sqrt_h=0.3, accel_vrw_m_s_sqrt_h=0.1,
        gyro_scale_ppm=3000.0, accel_scale_ppm=3000.0,
        gyro_misalignment_mrad=1.0, accel_misalignment_mrad=1.0,
        name="consumer", source="BMI088/ICM-20948-class MEMS; Groves 2013 section 4.4",
    ),
}
GRADES["mems"] = GRADES["consumer"]


def grade(name: str) -> ImuErrorModel:
    """Look up a grade preset: ``"navigation"``, ``"tactical"``, ``"tactical_mems"`` or
    ``"consumer"`` (``"mems"``)."""
    try:
        return GRADES[name.lower()]
    except KeyError:
        raise ValueError(f"unknown IMU grade {name!r}; expected one of {sorted(GRADES)}") from None
