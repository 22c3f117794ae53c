"""Text and JSON files read within stated limits: a regular file (a FIFO
would block), at most :data:`~wgse_mmseg.limits.TEXT_FILE_LIMIT_BYTES`,
UTF-8, JSON nested at most :data:`~wgse_mmseg.limits.MAX_JSON_DEPTH` deep;
and paths OpenCV and ONNX Runtime can open.
"""
import json
import os
import re
import stat
from typing import Any

from ..errors import EXCERPT_CHARS, cut, excerpt  # noqa: F401
from ..limits import MAX_JSON_DEPTH, TEXT_FILE_LIMIT_BYTES

#: a JSON string literal (escapes included), whose brackets do not nest
_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"')


_JSON_BRACKET = re.compile(r'[\[\]{}]')


def check_utf8_path(path, library: str) -> None:
    """Refuse ``path`` where it holds bytes that are not UTF-8 (a name in
    another system's encoding, which Python carries as surrogates):
    ``library`` (OpenCV, ONNX Runtime) takes paths as UTF-8 and cannot
    open it (OpenCV's reader crashes the process on it).

    Raises:
        ValueError: naming the path (escaped) as not UTF-8.
    """
    try:
        os.fspath(path).encode('utf-8')
    except UnicodeEncodeError:
        raise ValueError(
            f'{ascii(os.fspath(path))}: the path holds bytes that are not '
            f'UTF-8, which {library} cannot open; rename the file or the '
            f'folder on its way') from None


def read_text_file(path: str, what: str,
                   limit: int = TEXT_FILE_LIMIT_BYTES) -> str:
    """The UTF-8 text of ``path``, refused when longer than ``limit``
    bytes (read at most ``limit + 1`` bytes, so a growing or special file
    cannot make it read more).

    Raises:
        ValueError: naming ``path`` and ``what`` it should be, for a file
            over the limit, not UTF-8, or no regular file (a FIFO would
            block the read). ``OSError`` passes through.
    """
    # O_NONBLOCK: opening a FIFO without a writer would wait for one
    fd = os.open(path, os.O_RDONLY | getattr(os, 'O_NONBLOCK', 0))
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise ValueError(f'{path}: a {what} is read from a regular file, '
                         f'not a FIFO, device or folder')
    with open(fd, 'rb') as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        raise ValueError(
            f'{path}: a {what} larger than {limit} bytes is refused '
            f'(wgse_mmseg.limits.TEXT_FILE_LIMIT_BYTES)')
    try:
        return data.decode('utf-8')
    except UnicodeDecodeError as err:
        raise ValueError(f'{path}: a {what} must be UTF-8 text ({err})') \
            from err


def json_depth(text: str) -> int:
    """The deepest nesting of arrays and objects in JSON ``text``, counted
    without parsing it (brackets inside strings do not count)."""
    depth = deepest = 0
    for bracket in _JSON_BRACKET.findall(_JSON_STRING.sub('""', text)):
        depth += 1 if bracket in '[{' else -1
        deepest = max(deepest, depth)
    return deepest


def parse_json(text: str, source: str, what: str,
               limit: int = TEXT_FILE_LIMIT_BYTES) -> Any:
    """The JSON value of ``text`` read from ``source`` (a file, or a model's
    metadata entry), the one bounded JSON parser of the package: at most
    ``limit`` characters and :data:`MAX_JSON_DEPTH` levels of nesting.

    Raises:
        ValueError: naming ``source`` and ``what`` it should be, for text
            over a limit or invalid JSON.
    """
    if len(text) > limit:
        raise ValueError(
            f'{source}: a {what} longer than {limit} characters is refused')
    depth = json_depth(text)
    if depth > MAX_JSON_DEPTH:
        raise ValueError(
            f'{source}: a {what} nested too deeply ({depth} levels; at most '
            f'{MAX_JSON_DEPTH} are read, wgse_mmseg.limits.'
            f'MAX_JSON_DEPTH)')
    try:
        return json.loads(text)
    except ValueError as err:
        raise ValueError(f'{source}: a {what} must be JSON ({err})') from err


def load_json_file(path: str, what: str,
                   limit: int = TEXT_FILE_LIMIT_BYTES) -> Any:
    """The JSON value in ``path``: :func:`read_text_file` then
    :func:`parse_json`, both with ``limit`` bytes.

    Raises:
        ValueError: naming ``path``, for a file over the limits, not UTF-8,
            or invalid JSON. ``OSError`` passes through.
    """
    return parse_json(read_text_file(path, what, limit), path, what, limit)
