"""Lazy package exports (PEP 562 module ``__getattr__``).

The package ``__init__`` modules list their public names and the submodule each comes from;
the submodule is imported when a name is first used. So ``import insgnss.cli`` (``insgnss
--help``, light commands) does not import numba, pandas, the filter or matplotlib, while
``from insgnss import mechanize`` works as before.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping


def lazy_exports(package: str, exports: Mapping[str, str], namespace: dict
                 ) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package`` whose names load on first use.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    exports : mapping
        Public name -> module it is defined in, relative to ``package`` (``".strapdown"``).
    namespace : dict
        The package's ``globals()``; a loaded name is stored there, so each is imported once.
    """

    def __getattr__(name: str):
        try:
            module = exports[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        value = getattr(importlib.import_module(module, package), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(exports))

    return __getattr__, __dir__
