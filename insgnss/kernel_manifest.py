"""The compile-ahead manifest (``insgnss/data/compile_ahead.json``): per process, the numba
kernels a run calls from Python, in the order of their first call, with their argument types
as numba's ``repr`` (recorded by ``python -m insgnss.compile_ahead record``). Read by the
compile-ahead helper (:mod:`insgnss.compile_ahead`) and by the ahead-of-time build
(:mod:`insgnss.aot`)."""

from __future__ import annotations

import json
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


__all__ = ["MANIFEST", "argument_types", "entry_key", "load_manifest", "type_namespace"]
