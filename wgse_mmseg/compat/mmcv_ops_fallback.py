"""Supply ``mmcv.ops`` to MMSegmentation when mmcv's compiled ops are missing
and the installed MMSeg cannot import without them.

``mmcv-lite`` (and onedl-mmcv built without its ops) ships ``mmcv/ops/*.py``
but not the ``mmcv._ext`` extension, so ``import mmcv.ops`` fails. Whether
MMSeg then still imports is read off MMSeg's own source
(:func:`mmseg_mmcv_ops_imports`): MMSegmentation 1.2.2 imports
``point_sample`` and ``sigmoid_focal_loss`` unguarded, so it needs a
stand-in; onedl-mmsegmentation 1.4.2 guards every such import with
``except ModuleNotFoundError`` (what ``import mmcv.ops`` raises without the
extension) and needs none. Where one is needed (:func:`stand_in_names`),
this module installs a stand-in ``mmcv.ops`` package holding exactly the
names MMSeg imports without an ``ImportError`` handler (a name missing from
an importable ``mmcv.ops`` raises ``ImportError``, which a
``ModuleNotFoundError`` handler does not catch):

* the ops that mmcv itself writes in pure Python (:data:`PURE_PYTHON_OPS`),
  loaded straight from mmcv's own source files;
* for every other needed name, a placeholder that raises
  :class:`MissingCompiledOpError` when it is used (not when it is imported),
  naming the op and how to get it.

Every other name is absent, as under mmcv-lite: ``from mmcv.ops import
nms`` raises ``ImportError``, ``hasattr(mmcv.ops, 'nms')`` is False and
``import mmcv.ops.nms`` fails, so other libraries' ``try: from mmcv.ops
import X`` probes see what they would see without the stand-in.

With compiled ops (``mmcv._ext`` importable) nothing is replaced. Without
them, one line on stderr says so, once per run: not in torchrun's other
ranks, nor in processes started from this one (the environment variable
:data:`NOTICE_SHOWN` carries that).
"""
import ast
import functools
import importlib.util
import os
import os.path as osp
import sys
import types
from typing import Dict, Set

from ..errors import WgseError

__all__ = []

#: op name -> the mmcv.ops module that defines it without the compiled
#: extension
PURE_PYTHON_OPS = {'point_sample': 'point_sample'}
#: set in the environment once the one-line notice has been shown
NOTICE_SHOWN = 'WGSE_MMSEG_MMCV_NOTICE_SHOWN'

_INSTALL_HINT = ('install mmcv with its ops: `MMCV=full bash '
                 'tools/setup_env.sh` (a source build, about 30 minutes on 2 '
                 'cores) or, on a GPU, the fork\'s prebuilt wheels (`STACK='
                 'onedl MMCV=full MMCV_WHEELS=...`), see docs/install.md')


class MissingCompiledOpError(WgseError, RuntimeError):
    """An mmcv op that needs the compiled extension was used without it."""


def _missing_op(name: str):
    """A stand-in for a compiled op: importable, raises on use."""

    def fail(*args, **kwargs):
        raise MissingCompiledOpError(
            f'mmcv.ops.{name} needs mmcv\'s compiled extension, which is not '
            f'installed; {_INSTALL_HINT}')

    return type(name, (), {'__init__': fail, '__call__': fail,
                           '__doc__': f'Unavailable: {name}.'})


def has_compiled_ops() -> bool:
    """Whether mmcv's compiled extension (``mmcv._ext``) can be imported."""
    try:
        return importlib.util.find_spec('mmcv._ext') is not None
    except (ImportError, ValueError):
        return False


#: how an ``from mmcv.ops import`` is guarded, weakest first: no handler
#: that catches its failure; a handler for ``ModuleNotFoundError`` only (what
#: ``import mmcv.ops`` raises without ``mmcv._ext``, but not a name missing
#: from an ``mmcv.ops`` that imports); a handler for any ``ImportError``
GUARDS = ('unguarded', 'ModuleNotFoundError', 'ImportError')


def _guard_of(handlers) -> int:
    """The index in :data:`GUARDS` of what ``except`` clauses catch."""
    caught = 0
    for handler in handlers:
        if handler.type is None:
            return 2
        kinds = (handler.type.elts if isinstance(handler.type, ast.Tuple)
                 else [handler.type])
        for kind in kinds:
            name = kind.id if isinstance(kind, ast.Name) else None
            if name in ('ImportError', 'Exception', 'BaseException'):
                return 2
            if name == 'ModuleNotFoundError':
                caught = 1
    return caught


def _ops_imports(tree: ast.Module) -> Dict[str, str]:
    """``{name: guard}`` of ``from mmcv.ops import ...`` run at a module's
    import (its top level, ``if`` and ``try`` bodies, handlers), each with
    its weakest guard (:data:`GUARDS`); imports in functions and classes run
    later, and are left out."""
    found = {}

    def visit(statements, guard):
        for node in statements:
            if isinstance(node, ast.ImportFrom) and node.module == 'mmcv.ops':
                for alias in node.names:
                    found[alias.name] = min(found.get(alias.name, 2), guard)
            elif isinstance(node, ast.If):
                visit(node.body, guard)
                visit(node.orelse, guard)
            elif isinstance(node, ast.Try):
                visit(node.body, max(guard, _guard_of(node.handlers)))
                for handler in node.handlers:
                    visit(handler.body, guard)
                visit(node.orelse, guard)
                visit(node.finalbody, guard)

    visit(tree.body, 0)
    return {name: GUARDS[guard] for name, guard in found.items()}


@functools.lru_cache(maxsize=None)
def mmseg_mmcv_ops_imports() -> Dict[str, str]:
    """``{name: guard}`` of what the installed MMSeg imports from
    ``mmcv.ops`` when its modules are imported (:data:`GUARDS`). Read from
    MMSeg's source files (parsed, never run) once per process; only files
    that mention ``mmcv.ops`` are parsed."""
    spec = importlib.util.find_spec('mmseg')
    if spec is None or not spec.submodule_search_locations:
        return {}
    found = {}
    for root in spec.submodule_search_locations:
        for folder, dirs, files in os.walk(root):
            dirs[:] = [d for d in dirs if not d.startswith('.')]
            for file_name in files:
                if not file_name.endswith('.py'):
                    continue
                with open(osp.join(folder, file_name), 'rb') as f:
                    source = f.read()
                if b'mmcv.ops' not in source:
                    continue
                for name, guard in _ops_imports(ast.parse(source)).items():
                    if name not in found or \
                            GUARDS.index(guard) < GUARDS.index(found[name]):
                        found[name] = guard
    return found


def stand_in_names() -> Set[str]:
    """The names a stand-in ``mmcv.ops`` must hold for the installed MMSeg,
    or the empty set where MMSeg imports without ``mmcv.ops`` (every import
    guarded): with a stand-in, a name it lacks raises an ImportError that a
    ``ModuleNotFoundError`` handler does not catch, so those are held too."""
    imports = mmseg_mmcv_ops_imports()
    if 'unguarded' not in imports.values():
        return set()
    return {name for name, guard in imports.items() if guard != 'ImportError'}


def install_mmcv_ops_fallback() -> bool:
    """Install the stand-in ``mmcv.ops`` if MMSeg needs one; True if it did.

    Idempotent, and a no-op where ``mmcv._ext`` exists, ``mmcv.ops`` is
    already imported, or the installed MMSeg imports without ``mmcv.ops``.
    """
    current = sys.modules.get('mmcv.ops')
    if current is not None:
        return getattr(current, '__wgse_fallback__', False)
    import mmcv
    if has_compiled_ops():
        return False
    needed = stand_in_names()
    if not needed:
        _notice_once('wgse_mmseg: mmcv without compiled ops: what needs them '
                     'fails when used (docs/install.md, "mmcv ops")')
        return False
    ops_dir = osp.join(osp.dirname(mmcv.__file__), 'ops')
    package = types.ModuleType('mmcv.ops')
    package.__path__ = []  # a package: `mmcv.ops.x` resolves only if loaded
    package.__wgse_fallback__ = True
    loaded = []
    for name in sorted(needed):
        module_name = PURE_PYTHON_OPS.get(name)
        path = module_name and osp.join(ops_dir, f'{module_name}.py')
        if path and osp.exists(path):
            module = sys.modules.get(f'mmcv.ops.{module_name}')
            if module is None:
                spec = importlib.util.spec_from_file_location(
                    f'mmcv.ops.{module_name}', path)
                module = importlib.util.module_from_spec(spec)
                sys.modules[spec.name] = module
                spec.loader.exec_module(module)
            setattr(package, name, getattr(module, name))
            loaded.append(name)
        else:
            setattr(package, name, _missing_op(name))
    sys.modules['mmcv.ops'] = package
    mmcv.ops = package
    placeholders = sorted(needed - set(loaded))
    _notice_once(
        f'wgse_mmseg: mmcv without compiled ops: '
        f'{", ".join(placeholders) or "none"} fail when used '
        f'(docs/install.md, "mmcv ops")')
    return True


def _notice_once(message: str) -> None:
    """``message`` on stderr, in the first process of a run only."""
    if os.environ.get(NOTICE_SHOWN) or os.environ.get('RANK', '0') != '0':
        return
    os.environ[NOTICE_SHOWN] = '1'
    print(message, file=sys.stderr)
