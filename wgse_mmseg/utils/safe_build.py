"""Building objects from configs read out of files: allow-listed classes only.

A checkpoint from anywhere carries its model config as data (an exported
file's ``meta['model']``; a Runner checkpoint's ``meta['cfg']`` text, read
by :func:`~wgse_mmseg.utils.config_data.read_config_data`). Handed to a
registry as it is, such a config chooses code: mmengine 0.10.7's
``Registry.get`` imports any dotted ``type`` (``'os.system'``) and a
``_scope_`` key imports a module, at any depth, because each built class
builds its own sub-configs.

:func:`check_file_config` walks such a config at every depth against an
:data:`_AllowList`: a tree naming the classes the config may build and, per
class, which of its arguments hold a config of their own and which classes
those may build. It refuses, with a :class:`ConfigDataError` naming the
file and the key path (``ckpt.pth: meta['model'].data_preprocessor.type:
...``):

* a ``type`` that is not the name of an allowed class at that place
  (dotted paths, unregistered names, anything but a string);
* a ``_scope_`` key anywhere;
* a key the class's ``__init__`` does not name (``**kwargs`` is not
  followed);
* a dict with ``type`` or ``_scope_`` in any argument the tree does not
  mark as a config (data that some code might build);
* any value that is not plain data (numbers, strings, booleans, ``None``,
  lists, tuples, dicts with string keys), and nesting deeper than
  :data:`MAX_DEPTH`.

:func:`build_from_file_config` then builds it with every ``type`` replaced
by the allowed class itself, so no registry looks up a name that came from
a file; a value a built class refuses (its declared arguments and stated
limits, :mod:`wgse_mmseg.argument_checks`: ``channels=0``) is reported
as a :class:`ConfigDataError` naming the file and the argument's key path
(``ckpt.pth: meta['model'].channels: SpikeReconstructor: channels must be
...``), before anything is allocated. Every build from file data in the package
goes through it (``tests/utils/test_safe_build.py`` audits the call sites).
"""
import inspect
from typing import Any, Dict, FrozenSet, Mapping, Optional

from ..argument_checks import ArgumentError
from .config_data import ConfigDataError

__all__ = []

#: class -> {argument holding a config of its own -> the _AllowList of that
#: config}; arguments not named take plain data only
_AllowList = Mapping[type, Mapping[str, '_AllowList']]

#: deepest nesting of lists and dicts accepted in a file's config
MAX_DEPTH = 32

_SCALARS = (str, int, float, bool, type(None))


def _arguments(cls: type) -> FrozenSet[str]:
    """The keyword arguments ``cls(...)`` names explicitly."""
    parameters = list(inspect.signature(cls.__init__).parameters.values())
    return frozenset(
        p.name for p in parameters[1:]
        if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY))


def _refuse(source: str, path: str, problem: str) -> ConfigDataError:
    return ConfigDataError(f'{source}: {path}: {problem}; a config read from '
                           f'a file builds only allow-listed classes')


def _check_depth(source: str, path: str, depth: int) -> None:
    if depth > MAX_DEPTH:
        raise _refuse(source, path, f'nested deeper than {MAX_DEPTH} levels')


def _keys(value: dict, source: str, path: str) -> None:
    for key in value:
        if not isinstance(key, str):
            raise _refuse(source, path, f'key {key!r} is not a string')


def _plain(value: Any, source: str, path: str, depth: int) -> Any:
    """A copy of plain data ``value``, holding no config anywhere."""
    _check_depth(source, path, depth)
    if isinstance(value, _SCALARS):
        return value
    if isinstance(value, (list, tuple)):
        items = [_plain(item, source, f'{path}[{index}]', depth + 1)
                 for index, item in enumerate(value)]
        return tuple(items) if isinstance(value, tuple) else items
    if isinstance(value, dict):
        _keys(value, source, path)
        for key in ('_scope_', 'type'):
            if key in value:
                raise _refuse(source, f'{path}.{key}',
                              f'{value[key]!r} would choose code here, where '
                              f'no config is allowed')
        return {key: _plain(item, source, f'{path}.{key}', depth + 1)
                for key, item in value.items()}
    raise _refuse(source, path, f'a {type(value).__name__} is not plain data '
                  f'(numbers, strings, booleans, None, lists, dicts)')


def _config(cfg: Any, allowed: _AllowList, source: str, path: str,
            depth: int, resolve: bool) -> Dict[str, Any]:
    """A checked copy of ``cfg``; ``type`` the class itself if ``resolve``."""
    _check_depth(source, path, depth)
    names = {cls.__name__: cls for cls in allowed}
    if not isinstance(cfg, dict):
        raise _refuse(source, path, f'expected a config dict(type=...) of '
                      f'{sorted(names)}, found a {type(cfg).__name__}')
    _keys(cfg, source, path)
    if '_scope_' in cfg:
        raise _refuse(source, f'{path}._scope_', f'{cfg["_scope_"]!r}: a '
                      f'scope imports a module and is never read from a '
                      f'file')
    kind = cfg.get('type')
    if not isinstance(kind, str) or kind not in names:
        why = ' (a dotted path imports code)' if isinstance(kind, str) and \
            '.' in kind else ''
        raise _refuse(source, f'{path}.type', f'{kind!r}{why} is not one of '
                      f'the classes allowed here: {sorted(names)}')
    cls = names[kind]
    arguments = _arguments(cls)
    unknown = sorted(set(cfg) - arguments - {'type'})
    if unknown:
        raise _refuse(source, f'{path}.{unknown[0]}', f'{kind} takes no '
                      f'argument {unknown[0]!r} (it takes '
                      f'{sorted(arguments)})')
    checked = dict(type=cls if resolve else kind)
    for key, value in cfg.items():
        if key == 'type':
            continue
        sub = allowed[cls].get(key)
        checked[key] = _config(
            value, sub, source, f'{path}.{key}', depth + 1, resolve) \
            if sub is not None and value is not None else \
            _plain(value, source, f'{path}.{key}', depth + 1)
    return checked


def check_file_config(cfg: Any, allowed: _AllowList, source: str,
                      key: str) -> Dict[str, Any]:
    """A plain-data copy of ``cfg`` (``type`` names kept as strings), checked
    against ``allowed`` at every depth (see the module docstring).

    Args:
        cfg: the config as read from the file.
        allowed: the classes it may build, as a tree.
        source: the file, named in errors.
        key: where in the file ``cfg`` lies (``"meta['model']"``), the start
            of the key path in errors.

    Raises:
        ConfigDataError: naming ``source`` and the key path of the first
            thing refused.
    """
    return _config(cfg, allowed, source, key, 0, resolve=False)


def _declared_at(cfg: Any, path: str, err: ArgumentError) -> Optional[str]:
    """The key path in resolved ``cfg`` (at ``path``) of the config of class
    ``err.entry``, and of its argument ``err.argument`` where it is given
    there; ``None`` if no such config."""
    if isinstance(cfg, dict):
        kind = cfg.get('type')
        if isinstance(kind, type) and kind.__name__ == err.entry:
            return (f'{path}.{err.argument}' if err.argument in cfg else
                    path)
        items = ((f'{path}.{k}', v) for k, v in cfg.items())
    elif isinstance(cfg, (list, tuple)):
        items = ((f'{path}[{i}]', v) for i, v in enumerate(cfg))
    else:
        return None
    for where, value in items:
        found = _declared_at(value, where, err)
        if found is not None:
            return found
    return None


def build_from_file_config(registry, cfg: Any, allowed: _AllowList,
                           source: str, key: str):
    """``registry.build`` of ``cfg`` once :func:`check_file_config` accepts
    it, with each ``type`` given as the allowed class, so no name from the
    file is looked up in any registry.

    Raises:
        ConfigDataError: as :func:`check_file_config`, and for an argument
            a built class refuses (:class:`~wgse_mmseg.argument_checks.
            ArgumentError`), naming ``source`` and the argument's key path.
    """
    resolved = _config(cfg, allowed, source, key, 0, resolve=True)
    try:
        return registry.build(resolved)
    except ArgumentError as err:
        where = _declared_at(resolved, key, err) or key
        raise ConfigDataError(f'{source}: {where}: {err}') from err
