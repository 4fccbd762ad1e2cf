"""insgnss: inertial navigation and INS/GNSS integration.

Frames, units and column names are described in ``docs/conventions.md``: navigation frame ENU,
body frame right-forward-up, SI units inside (rad, m, m/s, s), pandas DataFrames indexed by time.

The names below are imported on first use (:mod:`insgnss._lazy`), so that ``import insgnss``
and the command line start without numba, pandas or the filter.
"""

from ._lazy import lazy_exports
from ._version import __version__

_EXPORTS = {
    "InsgnssError": ".errors",
    "jacobian": ".linearization",
    "vanloan": ".linearization",
    "INSMechanization": ".mechanization.strapdown",
    "NavState": ".mechanization.strapdown",
    "mechanize": ".mechanization.strapdown",
    "integrate_position": ".mechanization.inverse",
    "inverse_mechanize": ".mechanization.inverse",
    "est_wind": ".trajectory_tools",
    "llh_to_vne": ".trajectory_tools",
    "vne_to_rpy": ".trajectory_tools",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

__all__ = ["INSMechanization", "InsgnssError", "NavState", "est_wind", "integrate_position",
           "inverse_mechanize", "jacobian", "llh_to_vne", "mechanize", "vanloan", "vne_to_rpy",
           "__version__"]
