"""Reading the fields of the text files the workbench accepts (recorded data, track files): one finite number
per field and one way to read a file, each failure one line naming the file, line and column."""

from __future__ import annotations

import math
from pathlib import Path

from .types import InputError

__all__ = ["finite_number", "read_text", "ImplausibleValueWarning"]


class ImplausibleValueWarning(UserWarning):
    """A recorded value that is well formed but physically unlikely (a unit slip?), with the numbers; the value
    is used as given."""


def finite_number(text: str, where: str) -> float:
    """Parse one CSV field as a finite float; ``where`` (file, line, column) goes into the error."""
    text = text.strip()
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{where}: expected a finite number, got {text!r}") from None
    if not math.isfinite(value):
        raise InputError(f"{where}: expected a finite number, got {text!r}")
    return value


def read_text(path: Path, what: str) -> str:
    """The text of ``path`` as UTF-8 (a byte-order mark is dropped); ``what`` names the kind of file in errors."""
    if not path.is_file():
        raise InputError(f"{path}: cannot read the {what}: no such file")
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start}); save it as UTF-8") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
