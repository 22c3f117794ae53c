"""Supply ``mmcv.ops`` to MMSegmentation when mmcv's compiled ops are missing.

``mmcv-lite`` ships ``mmcv/ops/*.py`` but not the ``mmcv._ext`` extension, so
``import mmcv.ops`` fails, and MMSegmentation 1.2.2 imports ``mmcv.ops`` at
module level (``point_sample``, ``sigmoid_focal_loss``). This module installs a
stand-in ``mmcv.ops`` package that

* loads the ops that mmcv itself writes in pure Python straight from mmcv's
  own source files (``point_sample.py``), and
* answers every other name with a placeholder that raises a clear error when
  it is used (not when it is imported), naming the op and how to get it, also
  as the submodules other packages import by path
  (``mmcv.ops.multi_scale_deform_attn``, which mmcv's own transformer bricks
  try at import and warn about when it is missing).

With full mmcv installed (``mmcv._ext`` importable) nothing is replaced. Where
it installs the stand-in, it says so in one line on stderr, once per run: not
in torchrun's other ranks, nor in processes started from this one (the
environment variable :data:`NOTICE_SHOWN` carries that).
"""
import importlib.util
import os
import os.path as osp
import sys
import types

__all__ = []

#: mmcv.ops modules that need no compiled extension, and the names they give.
PURE_PYTHON_OPS = {'point_sample': ('point_sample', 'bilinear_grid_sample')}
#: mmcv.ops modules imported by path elsewhere, and their compiled-only names.
PLACEHOLDER_MODULES = {
    'multi_scale_deform_attn': ('MultiScaleDeformableAttention',)}
#: set in the environment once the one-line notice has been shown
NOTICE_SHOWN = 'WGSE_MMSEG_MMCV_NOTICE_SHOWN'

_INSTALL_HINT = ('install full mmcv: '
                 '`MMCV=full bash tools/setup_env.sh` (about 30 minutes on '
                 '2 cores), see README "Install"')


class MissingCompiledOpError(RuntimeError):
    """An mmcv op that needs the compiled extension was used without it."""


def _missing_op(name: str):
    """A stand-in for a compiled op: importable, raises on use."""

    def fail(*args, **kwargs):
        raise MissingCompiledOpError(
            f'mmcv.ops.{name} needs mmcv\'s compiled extension, which is not '
            f'installed (mmcv-lite); {_INSTALL_HINT}')

    placeholder = type(name, (), {'__init__': fail, '__call__': fail,
                                  '__doc__': f'Unavailable: {name}.'})
    return placeholder


def has_compiled_ops() -> bool:
    """Whether mmcv's compiled extension (``mmcv._ext``) can be imported."""
    try:
        return importlib.util.find_spec('mmcv._ext') is not None
    except (ImportError, ValueError):
        return False


def install_mmcv_ops_fallback() -> bool:
    """Install the stand-in ``mmcv.ops`` if needed; True if it did.

    Idempotent, and a no-op where ``mmcv._ext`` exists or ``mmcv.ops`` is
    already importable.
    """
    current = sys.modules.get('mmcv.ops')
    if current is not None:
        return getattr(current, '__wgse_fallback__', False)
    import mmcv
    if has_compiled_ops():
        return False
    ops_dir = osp.join(osp.dirname(mmcv.__file__), 'ops')
    package = types.ModuleType('mmcv.ops')
    package.__path__ = []  # a package, so that `mmcv.ops.x` imports resolve
    package.__wgse_fallback__ = True
    loaded = []
    for module_name, names in PURE_PYTHON_OPS.items():
        path = osp.join(ops_dir, f'{module_name}.py')
        if not osp.exists(path):
            continue
        spec = importlib.util.spec_from_file_location(
            f'mmcv.ops.{module_name}', path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module
        spec.loader.exec_module(module)
        setattr(package, module_name, module)
        for name in names:
            setattr(package, name, getattr(module, name))
            loaded.append(name)

    for module_name, names in PLACEHOLDER_MODULES.items():
        module = types.ModuleType(f'mmcv.ops.{module_name}')
        for name in names:
            setattr(module, name, _missing_op(name))
        sys.modules[module.__name__] = module
        setattr(package, module_name, module)

    def __getattr__(name):
        if name.startswith('__'):
            raise AttributeError(name)
        return _missing_op(name)

    package.__getattr__ = __getattr__
    sys.modules['mmcv.ops'] = package
    mmcv.ops = package
    _notice_once(
        f'wgse_mmseg: mmcv-lite has no compiled ops; mmcv.ops supplies '
        f'{", ".join(loaded) or "nothing"} from mmcv\'s pure-Python code and '
        f'raises MissingCompiledOpError for other ops. For them, '
        f'{_INSTALL_HINT}.')
    return True


def _notice_once(message: str) -> None:
    """``message`` on stderr, in the first process of a run only."""
    if os.environ.get(NOTICE_SHOWN) or os.environ.get('RANK', '0') != '0':
        return
    os.environ[NOTICE_SHOWN] = '1'
    print(message, file=sys.stderr)
