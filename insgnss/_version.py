"""The insgnss version: the single source (``pyproject.toml`` reads it, the package exports it).

A module of its own, holding only this string, so that ``insgnss.cli`` and the writers of
``summary.json`` get the version without importing the package ``__init__``: when a folder named
``insgnss`` in the current directory (a second checkout) shadows the package as a namespace
package, ``from insgnss import __version__`` fails while ``insgnss._version`` is still found
(tests/test_startup.py).
"""

__version__ = "0.1.0"
