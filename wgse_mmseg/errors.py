"""The package's one error base, and the bounded quotes its messages make.

Every error wgse_mmseg raises for what a user, a config or a file gave it
derives from :class:`WgseError` and from the built-in class it has always
had (``ValueError`` for a wrong value, ``OSError`` for a file system
failure, ...), so that both ``except WgseError`` and ``except ValueError``
catch it. A message quotes at most :data:`EXCERPT_CHARS` characters of an
offending value (:func:`excerpt`), so that a crafted value cannot flood a
log. Imports nothing outside the standard library.
"""
from typing import Any

__all__ = ['WgseError']

#: characters of a value quoted in an error message
EXCERPT_CHARS = 200


class WgseError(Exception):
    """Base of the package's errors. Each subclass also derives from its
    built-in class (``class SpikeFileError(WgseError, ValueError)``)."""


def cut(text: str, limit: int = EXCERPT_CHARS) -> str:
    """``text``, cut to ``limit`` characters with a note of its full
    length when longer."""
    if len(text) <= limit:
        return text
    return f'{text[:limit]}... ({len(text)} characters)'


def excerpt(value: Any, limit: int = EXCERPT_CHARS) -> str:
    """``repr(value)`` for an error message, :func:`cut` to ``limit``."""
    return cut(repr(value), limit)
