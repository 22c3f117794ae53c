"""Config text from files that are data, read without executing anything.

An mmengine checkpoint stores its run's config as Python text
(``meta['cfg']``, ``Config.pretty_text``): assignments of plain values such
as ``model = dict(type='SpikeReconstructor', channels=64)``. Loading it with
``Config.fromstring`` would execute it, so a checkpoint from anywhere could
run any code. :func:`read_config_data` parses the text with :mod:`ast` and
accepts only top-level assignments of plain values (numbers, strings,
``True``/``False``/``None``, lists, tuples, dict displays and ``dict(...)``
calls with keyword arguments); anything else is refused with the source and
line, and nothing of the text is ever run.

A config file the user passes on the command line is different: it is
Python by design in MMSeg (``Config.fromfile``), and is executed.
"""
import ast
from typing import Any, Dict

from ..limits import MAX_JSON_DEPTH, TEXT_FILE_LIMIT_BYTES
from ..errors import WgseError

__all__ = []


class ConfigDataError(WgseError, ValueError):
    """Config text that is not plain data (or not parseable)."""


def _key(node: ast.AST, source: str, depth: int) -> Any:
    """A dict display's key: a plain value that can be a key (a list or
    dict cannot)."""
    key = _value(node, source, depth)
    try:
        hash(key)
    except TypeError:
        raise ConfigDataError(
            f'{source}: line {getattr(node, "lineno", "?")}: a dict key '
            f'{ast.unparse(node)[:80]!r} is a {type(key).__name__}, which '
            f'cannot be a key') from None
    return key


def _value(node: ast.AST, source: str, depth: int = 0) -> Any:
    """The plain value ``node`` spells, or :class:`ConfigDataError`."""
    if depth > MAX_JSON_DEPTH:
        raise ConfigDataError(
            f'{source}: line {getattr(node, "lineno", "?")}: values nested '
            f'deeper than {MAX_JSON_DEPTH} levels are not read '
            f'(wgse_mmseg.limits.MAX_JSON_DEPTH)')
    depth += 1
    if isinstance(node, ast.Constant):
        return node.value
    if isinstance(node, (ast.List, ast.Tuple)):
        items = [_value(item, source, depth) for item in node.elts]
        return items if isinstance(node, ast.List) else tuple(items)
    if isinstance(node, ast.Dict) and None not in node.keys:
        return {_key(key, source, depth): _value(value, source, depth)
                for key, value in zip(node.keys, node.values)}
    if isinstance(node, ast.UnaryOp) and isinstance(
            node.op, (ast.USub, ast.UAdd)) and isinstance(
                node.operand, ast.Constant) and isinstance(
                    node.operand.value, (int, float)):
        value = node.operand.value
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and \
            node.func.id == 'dict' and not node.args and \
            all(keyword.arg is not None for keyword in node.keywords):
        return {keyword.arg: _value(keyword.value, source, depth)
                for keyword in node.keywords}
    raise ConfigDataError(
        f'{source}: line {getattr(node, "lineno", "?")}: '
        f'{ast.unparse(node)[:80]!r} is not a plain value (only numbers, '
        f'strings, booleans, None, lists, tuples and dicts are read; '
        f'nothing is executed)')


def read_config_data(text: str, source: str) -> Dict[str, Any]:
    """``{name: value}`` of the top-level assignments in config ``text``.

    Args:
        text: Python-syntax config text (an mmengine ``pretty_text``).
        source: what to name in errors (a file, and where in it).

    Raises:
        ConfigDataError: the text does not parse, or holds anything but
            assignments of plain values to names.
    """
    if not isinstance(text, str):
        raise ConfigDataError(f'{source}: the config is a '
                              f'{type(text).__name__}, not text')
    if len(text) > TEXT_FILE_LIMIT_BYTES:
        raise ConfigDataError(
            f'{source}: config text of {len(text)} characters; at most '
            f'{TEXT_FILE_LIMIT_BYTES} are read')
    try:
        tree = ast.parse(text)
    except SyntaxError as error:
        raise ConfigDataError(f'{source}: the config text does not parse: '
                              f'{error.msg} (line {error.lineno})') from None
    except (RecursionError, MemoryError):  # the parser's own nesting limit
        raise ConfigDataError(f'{source}: the config text is nested too '
                              f'deeply to parse') from None
    values = {}
    for statement in tree.body:
        if not (isinstance(statement, ast.Assign) and
                len(statement.targets) == 1 and
                isinstance(statement.targets[0], ast.Name)):
            raise ConfigDataError(
                f'{source}: line {statement.lineno}: '
                f'{ast.unparse(statement)[:80]!r} is not an assignment of a '
                f'plain value; config text in a data file is read, never '
                f'executed')
        values[statement.targets[0].id] = _value(statement.value, source)
    return values
