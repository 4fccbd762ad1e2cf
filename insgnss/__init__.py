"""insgnss: inertial navigation and INS/GNSS integration.

Frames, units and column names are described in ``docs/conventions.md``: navigation frame ENU,
body frame right-forward-up, SI units inside (rad, m, m/s, s), pandas DataFrames indexed by time.
"""

from .errors import InsgnssError
from .mechanization.inverse import integrate_position, inverse_mechanize
from .mechanization.strapdown import NavState, mechanize

__version__ = "0.1.0"

__all__ = ["InsgnssError", "NavState", "integrate_position", "inverse_mechanize", "mechanize",
           "__version__"]
