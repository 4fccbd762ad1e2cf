"""The compile-ahead manifest (``insgnss/data/compile_ahead.json``): per process, the numba
kernels a run calls from Python, in the order of their first call, with their argument types
as numba's ``repr`` (recorded by ``python -m insgnss.compile_ahead record``). Read by the
compile-ahead helper (:mod:`insgnss.compile_ahead`) and by the ahead-of-time build
(:mod:`insgnss.aot`)."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from importlib import resources

#: the recorded kernels per process (``python -m insgnss.compile_ahead record``)
MANIFEST = "compile_ahead.json"


def load_manifest() -> dict:
    """The packaged manifest (``insgnss/data/compile_ahead.json``); ``{}`` when absent."""
    try:
        text = (resources.files("insgnss") / "data" / MANIFEST).read_text()
    except (FileNotFoundError, OSError):
        return {}
    return json.loads(text)


def entry_key(e: dict) -> tuple:
    """``(module, name, argument types)`` of a manifest entry: one kernel specialisation."""
    return e["module"], e["name"], tuple(e["args"])


def type_namespace() -> dict:
    """The names that the recorded ``repr`` strings of numba types use (:func:`argument_types`)."""
    from numba.core import types

    ns = {k: getattr(types, k) for k in dir(types) if not k.startswith("_")}
    # the reprs that are not constructor calls: bool, none, an omitted argument's default
    ns.update({"bool": types.boolean, "none": types.none,
               "omitted": lambda default: types.Omitted(default), "__builtins__": {}})
    return ns


def argument_types(args: list[str], ns: dict) -> tuple:
    """The numba types of recorded argument ``repr`` strings (:func:`type_namespace`)."""
    return tuple(eval(a, ns) for a in args)  # noqa: S307 (our own package data)


# --- the argument types an ahead-of-time export takes, without numba -------------------------------
#
# A run loads the exports of insgnss._aot and checks each call's arguments against the
# recorded types (insgnss.aot) without importing numba (insgnss.jit): the recorded ``repr``
# strings of the types an export can take are read here into the small descriptions below.
# numba's own reading (:func:`argument_types`) stays for compiling (the build, the compile-ahead
# helper), which converts these with :func:`numba_types`.

#: the dtypes an array (or a scalar of the same name) may have in an export's arguments
DTYPES = ("float64", "float32", "int64", "int32", "int16", "int8", "uint64", "uint32",
          "uint16", "uint8", "bool", "complex128", "complex64")


@dataclass(frozen=True)
class ArrayArg:
    """numba's ``Array(dtype, ndim, layout, readonly, aligned)``."""

    dtype: str
    ndim: int
    layout: str
    readonly: bool = False
    aligned: bool = True


@dataclass(frozen=True)
class ScalarArg:
    """A scalar of one of :data:`DTYPES`, or ``none``."""

    name: str


@dataclass(frozen=True)
class OmittedArg:
    """numba's ``omitted(default=...)``: an argument the call left out."""

    default: object


def _array(dtype: ScalarArg, ndim: int, layout: str, readonly: bool = False,
           aligned: bool = True) -> ArrayArg:
    if not isinstance(dtype, ScalarArg) or dtype.name not in DTYPES:
        raise TypeError(f"array of {dtype!r}")
    return ArrayArg(dtype.name, int(ndim), str(layout), bool(readonly), bool(aligned))


_ARG_NAMESPACE = {"__builtins__": {}, "Array": _array, "none": ScalarArg("none"),
                  "omitted": lambda default: OmittedArg(default),
                  **{d: ScalarArg(d) for d in DTYPES}}


def argument_kinds(args: list[str]) -> tuple:
    """The :class:`ArrayArg` / :class:`ScalarArg` / :class:`OmittedArg` of recorded argument
    ``repr`` strings; raises (NameError, TypeError, ...) for any other type."""
    return tuple(eval(a, dict(_ARG_NAMESPACE)) for a in args)  # noqa: S307 (our package data)


def read_only(sig: tuple) -> tuple:
    """``sig`` with every array read-only."""
    return tuple(replace(t, readonly=True) if isinstance(t, ArrayArg) else t for t in sig)


def numba_types(sig: tuple) -> tuple:
    """numba's types of :func:`argument_kinds` descriptions (imports numba)."""
    from numba.core import types

    def one(t):
        if isinstance(t, ArrayArg):
            return types.Array(one(ScalarArg(t.dtype)), t.ndim, t.layout, readonly=t.readonly,
                               aligned=t.aligned)
        if isinstance(t, OmittedArg):
            return types.Omitted(t.default)
        return {"bool": types.boolean, "none": types.none}.get(t.name) or getattr(types, t.name)

    return tuple(one(t) for t in sig)


__all__ = ["DTYPES", "MANIFEST", "ArrayArg", "OmittedArg", "ScalarArg", "argument_kinds",
           "argument_types", "entry_key", "load_manifest", "numba_types", "read_only",
           "type_namespace"]
