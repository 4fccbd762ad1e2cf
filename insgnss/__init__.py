"""insgnss: inertial navigation and INS/GNSS integration.

Frames, units and column names are described in ``docs/conventions.md``: navigation frame ENU,
body frame right-forward-up, SI units inside (rad, m, m/s, s), pandas DataFrames indexed by time.
"""

from .errors import InsgnssError
from .linearization import jacobian, vanloan
from .mechanization.inverse import integrate_position, inverse_mechanize
from .mechanization.strapdown import INSMechanization, NavState, mechanize
from .trajectory_tools import est_wind, llh_to_vne, vne_to_rpy

__version__ = "0.1.0"

__all__ = ["INSMechanization", "InsgnssError", "NavState", "est_wind", "integrate_position",
           "inverse_mechanize", "jacobian", "llh_to_vne", "mechanize", "vanloan", "vne_to_rpy",
           "__version__"]
