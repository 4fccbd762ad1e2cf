"""Process models: LLF strapdown (forward and inverse) and RISS."""

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {
    "INSMechanization": ".strapdown", "NavState": ".strapdown", "mechanize": ".strapdown",
    "integrate_position": ".inverse", "inverse_mechanize": ".inverse"}, globals())
__all__ = ["INSMechanization", "NavState", "integrate_position", "inverse_mechanize", "mechanize"]
