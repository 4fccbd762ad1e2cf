"""Build of insgnss: the package is described in pyproject.toml; this file adds the extension
module ``insgnss._aot``, the run's numba kernels compiled ahead of time (insgnss/aot.py).

The module is compiled when the package is built (``pip install .`` or ``pip install -e .``):
numba compiles each kernel of the compile-ahead manifest for the build machine's CPU, then a C
compiler links them with numba's runtime (one to two minutes). A build without a C compiler or
Python headers, or with ``INSGNSS_AOT=0``, installs the package without it: numba then compiles
the kernels on their first use, as before.
"""

import os
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = os.path.dirname(os.path.abspath(__file__))


class BuildExt(build_ext):
    """build_ext that compiles ``insgnss._aot`` with numba.pycc, and goes on without it when
    that fails."""

    def build_extension(self, ext):
        if ext.name != "insgnss._aot":
            return super().build_extension(ext)
        try:
            sys.path.insert(0, ROOT)
            from insgnss.aot import compiler

            cc_ext = compiler().distutils_extension()
            cc_ext._prepare_object_files(self)  # numba: the kernels' object file
            super().build_extension(cc_ext)
        except Exception as e:  # noqa: BLE001 - the package works without it (JIT)
            print(f"insgnss: the ahead-of-time kernels (insgnss._aot) were not built: {e}; "
                  "numba compiles the kernels on their first use", file=sys.stderr)


def extensions():
    if os.environ.get("INSGNSS_AOT", "1") == "0":
        return []
    return [Extension("insgnss._aot", sources=[], optional=True)]


setup(ext_modules=extensions(), cmdclass={"build_ext": BuildExt})
