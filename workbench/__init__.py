"""workbench: simulate, compare and accelerate target-tracking algorithms in clutter and at low SNR."""

from importlib.metadata import PackageNotFoundError, version

from .hookspecs import hookimpl

try:
    __version__ = version("workbench")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0+unknown"

__all__ = ["hookimpl", "__version__"]
