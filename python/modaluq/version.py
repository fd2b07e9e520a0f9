"""The package's version: the installed distribution's, else the C++ core's (a source tree)."""

from ._core import __version__ as core_version

try:
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as _dist_version

    __version__ = _dist_version("modaluq")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = core_version

__all__ = ["__version__", "core_version"]
