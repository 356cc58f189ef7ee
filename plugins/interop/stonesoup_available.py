"""Whether Stone Soup is installed, and the named error where it is needed and is not: the one place the interop
plugin's modules (:mod:`.stonesoup_filters`, :mod:`.stonesoup_models`, :mod:`.stonesoup_export`) ask."""

from __future__ import annotations

from datetime import datetime

from workbench.types import InputError

__all__ = ["AVAILABLE", "REASON", "EPOCH", "StoneSoupMissing", "require_stonesoup"]


class StoneSoupMissing(InputError, ImportError):
    """Stone Soup is needed and not installed: the message says how to install it (``pip install
    "workbench[stonesoup]"``).  An :class:`~workbench.types.InputError` (the command line prints one line, exit
    2) and an ``ImportError``."""


try:  # Stone Soup is an optional extra: without it the plugin provides nothing
    import stonesoup  # noqa: F401
except ImportError as _exc:  # pragma: no cover - depends on the environment
    AVAILABLE = False
    REASON = (f"Stone Soup is not installed ({_exc}); install it with pip install \"workbench[stonesoup]\" to get "
              f"the ss-* filters")
else:
    AVAILABLE = True
    REASON = ""


def require_stonesoup(what: str) -> None:
    """Raise :class:`StoneSoupMissing` naming ``what`` when Stone Soup is not installed."""
    if not AVAILABLE:
        raise StoneSoupMissing(f"{what} needs Stone Soup: {REASON}")


#: The time of every prior handed to Stone Soup (its states need time stamps; only the differences matter).
EPOCH = datetime(2000, 1, 1)
