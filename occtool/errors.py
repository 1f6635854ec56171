"""The library's exceptions.

Everything occtool raises on purpose derives from :class:`OcctoolError`; the command
line turns these into a one-line message and a non-zero exit status, never a
traceback.
"""

from __future__ import annotations


class OcctoolError(Exception):
    """Base class of all errors occtool raises deliberately."""


class InputError(OcctoolError, ValueError):
    """Input data (a log, a row, a parameter) that cannot be used as given."""


class ModelFormatError(OcctoolError, ValueError):
    """A model or report file that is malformed, or written by a newer format."""


class NotFittedError(OcctoolError, AttributeError):
    """A method that needs a fitted estimator was called before ``fit``."""


class MissingDependencyError(OcctoolError, ImportError):
    """An optional dependency (an extra) is needed but not installed."""

    def __init__(self, package: str, extra: str, purpose: str) -> None:
        self.package = package
        self.extra = extra
        super().__init__(
            f"{purpose} needs the optional package '{package}': "
            f"install it with `pip install 'occtool[{extra}]'`"
        )
