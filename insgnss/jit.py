"""Compiled kernels that import numba only when something has to be compiled.

Every per-sample loop of the package is a numba kernel (``@njit(cache=True)``). Importing
numba and making its dispatchers (about 150, each checking its cache directory) costs about
0.2 s of every run, yet a run whose kernels all come from the ahead-of-time module
(:mod:`insgnss.aot`: the car drive, the walk, the simulated logs) never compiles anything.
:func:`njit` here takes numba's options and returns a :class:`Kernel`:

- **until it is needed** it holds the Python function and the options; calling it runs an
  ahead-of-time export when the arguments have the export's types (:func:`insgnss.aot.entry`
  attaches the exports);
- **on the first call that no export takes**, or the first use of a dispatcher attribute
  (``signatures``, ``compile``, ``py_func`` excepted), numba is imported and the dispatcher is
  made, ``numba.njit(**options)(py_func)``: the same compile and the same on-disk cache as a
  kernel decorated with numba's own ``njit``;
- **numba-compiled code** that calls a kernel sees the dispatcher itself (numba's ``typeof``
  of a :class:`Kernel`, registered when numba is loaded by a kernel, and through numba's
  ``numba_extensions`` entry point when numba is used first elsewhere): inlining and the JIT
  path are unchanged.

A :class:`Kernel` pickles by its module and name, like the function it wraps.
"""

from __future__ import annotations

import functools
import importlib
import sys
import threading

__all__ = ["Kernel", "njit"]

_LOCK = threading.RLock()
_REGISTERED = False


class Kernel:
    """A numba kernel whose dispatcher is made on first need (module docstring).

    Parameters
    ----------
    py_func : callable
        The Python function.
    options : dict
        numba's ``njit`` options (``cache``, ``inline``, ...).
    dispatcher : numba dispatcher, optional
        An existing dispatcher of ``py_func`` (a kernel decorated with numba's ``njit``).
    """

    def __init__(self, py_func, options: dict | None = None, dispatcher=None):
        self.py_func = py_func
        self._options = dict(options or {})
        self._disp = dispatcher
        #: ahead-of-time exports ``(n_args, check, export, defaults)`` (:func:`insgnss.aot.entry`)
        self.exports = ()
        functools.update_wrapper(self, py_func)

    @property
    def loaded(self):
        """The numba dispatcher when it has been made, else None (numba not needed yet)."""
        return self._disp

    @property
    def dispatcher(self):
        """The numba dispatcher (made, and numba imported, on first use)."""
        disp = self._disp
        if disp is None:
            with _LOCK:
                if self._disp is None:
                    register_numba()
                    import numba

                    self._disp = numba.njit(**self._options)(self.py_func)
                disp = self._disp
        return disp

    def __call__(self, *args, **kwargs):
        if not kwargs:
            n = len(args)
            for m, check, fn, pad in self.exports:
                if m == n and check(*args):
                    return fn(*args, *pad) if pad else fn(*args)
        disp = self._disp
        if disp is None:
            disp = self.dispatcher
        return disp(*args, **kwargs)

    def __getattr__(self, name: str):
        # only names the instance does not have: a dispatcher attribute (never a dunder, which
        # introspection asks for without needing numba)
        if name.startswith("__") or name in ("_disp", "_options", "py_func", "exports"):
            raise AttributeError(name)
        return getattr(self.dispatcher, name)

    def __reduce__(self):
        return _kernel, (self.__module__, self.__qualname__)

    def __repr__(self) -> str:
        state = "loaded" if self._disp is not None else "not loaded"
        return (f"<insgnss.jit.Kernel {self.__module__}.{self.__qualname__}: "
                f"{len(self.exports)} ahead-of-time exports, dispatcher {state}>")


def _kernel(module: str, qualname: str) -> Kernel:
    obj = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


def njit(*args, **options):
    """numba's ``njit`` (``@njit``, ``@njit(cache=True, ...)``) made lazy: a :class:`Kernel`."""
    if args and callable(args[0]) and len(args) == 1 and not options:
        return Kernel(args[0])
    if args:
        raise TypeError("insgnss.jit.njit takes the function or keyword options only")

    def decorate(f) -> Kernel:
        return Kernel(f, options)

    return decorate


def register_numba() -> None:
    """Teach numba that a :class:`Kernel` is its dispatcher (``typeof``); once per process.
    Imports numba."""
    global _REGISTERED
    if _REGISTERED:
        return
    from numba.core import types
    from numba.extending import typeof_impl

    @typeof_impl.register(Kernel)
    def _typeof_kernel(val, c):
        return types.Dispatcher(val.dispatcher)

    _REGISTERED = True


def numba_extension() -> None:
    """numba's ``numba_extensions`` entry point (pyproject.toml): numba calls it when it makes
    its first dispatcher in a process, so that numba code written elsewhere can call a kernel
    of this package before any of them was loaded."""
    register_numba()


if "numba.extending" in sys.modules:  # numba already in use: register now
    register_numba()
