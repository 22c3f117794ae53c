"""Stated limits on the work a file can make the package do.

Whatever a file declares (a header's frame count, a zip member's inflated
size, a YAML document's nesting), the readers check it against the file and
against these limits before they allocate, and an error message quotes at
most :data:`EXCERPT_CHARS` characters of an offending value:

``READ_LIMIT_BYTES``
    the most one spike read may allocate: the requested window as read
    (``length * H * W * itemsize``), and an ``.npz`` member's declared
    inflated size (2 GiB; a 1024x2048 stream of 129 frames is 270 MB).
``TEXT_FILE_LIMIT_BYTES``
    the largest side file, marker or scene file (JSON/YAML) read (1 MiB;
    a converter's marker is a few kB).
"""
import json
from typing import Any

__all__ = ['READ_LIMIT_BYTES', 'TEXT_FILE_LIMIT_BYTES', 'EXCERPT_CHARS',
           'cut', 'excerpt', 'read_text_file', 'load_json_file']

READ_LIMIT_BYTES = 2**31
TEXT_FILE_LIMIT_BYTES = 2**20
EXCERPT_CHARS = 200


def cut(text: str, limit: int = EXCERPT_CHARS) -> str:
    """``text``, cut to ``limit`` characters with a note of its full
    length when longer."""
    if len(text) <= limit:
        return text
    return f'{text[:limit]}... ({len(text)} characters)'


def excerpt(value: Any, limit: int = EXCERPT_CHARS) -> str:
    """``repr(value)`` for an error message, :func:`cut` to ``limit``."""
    return cut(repr(value), limit)


def read_text_file(path: str, what: str,
                   limit: int = TEXT_FILE_LIMIT_BYTES) -> str:
    """The UTF-8 text of ``path``, refused when longer than ``limit``
    bytes (read at most ``limit + 1`` bytes, so a growing or special file
    cannot make it read more).

    Raises:
        ValueError: naming ``path`` and ``what`` it should be, for a file
            over the limit or not UTF-8. ``OSError`` passes through.
    """
    with open(path, 'rb') as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        raise ValueError(
            f'{path}: a {what} larger than {limit} bytes is refused '
            f'(wgse_mmseg.core.limits.TEXT_FILE_LIMIT_BYTES)')
    try:
        return data.decode('utf-8')
    except UnicodeDecodeError as err:
        raise ValueError(f'{path}: a {what} must be UTF-8 text ({err})') \
            from err


def load_json_file(path: str, what: str) -> Any:
    """The JSON value in ``path`` (:func:`read_text_file`'s limit).

    Raises:
        ValueError: naming ``path``, for a file over the limit, invalid
            JSON, or nesting deeper than Python's recursion limit.
            ``OSError`` passes through.
    """
    text = read_text_file(path, what)
    try:
        return json.loads(text)
    except RecursionError as err:
        raise ValueError(f'{path}: a {what} nested too deeply') from err
    except ValueError as err:
        raise ValueError(f'{path}: a {what} must be JSON ({err})') from err
