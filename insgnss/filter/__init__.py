"""Error-state Kalman filter, measurement models and RTS smoother.

Public API::

    from insgnss.filter import FilterConfig, run_filter, GnssPosition, GnssVelocity
    result = run_filter(imu, initial, [GnssPosition(gnss), GnssVelocity(gnss)], FilterConfig())
    result.forward, result.smoothed, result.innovations, result.rejected

See docs/filter.md.
"""

from .engine import BIAS_COLS, STD_COLS, FilterConfig, FilterResult, run_filter
from .measurements import (
    BodyVelocity,
    Cupt,
    GnssPosition,
    GnssVelocity,
    Heading,
    Measurement,
    NominalState,
    Zaru,
    Zupt,
)
from .models import ExtraState, ProcessModel, StateLayout, error_dynamics, process_model
from .smoother import rts_error_state
from .wander_model import run_wander_filter

__all__ = [
    "BIAS_COLS", "STD_COLS", "FilterConfig", "FilterResult", "run_filter",
    "BodyVelocity", "Cupt", "GnssPosition", "GnssVelocity", "Heading", "Measurement",
    "NominalState", "Zaru", "Zupt", "ExtraState", "ProcessModel", "StateLayout",
    "error_dynamics", "process_model", "rts_error_state", "run_wander_filter",
]
