"""What the MMSeg layer needs before it imports MMSeg.

:mod:`wgse_mmseg.core` needs torch, NumPy, PyWavelets, OpenCV and PyYAML
(Triton for the GPU kernels); the MMSeg layer (``wgse_mmseg.datasets``,
``.engine``, ``.evaluation``, ``.models``, ``.apis``, ``.utils``) and the
tools need mmengine, mmsegmentation and mmcv (or mmcv-lite) as well, and,
under mmcv-lite, the stand-in ``mmcv.ops`` of :mod:`wgse_mmseg.compat`,
since MMSeg imports ``mmcv.ops`` at module level.

The compatibility patches are applied by an explicit call,
:func:`prepare_mmseg_layer` (made by :func:`wgse_mmseg.register_all_modules`,
by importing :mod:`wgse_mmseg.mmseg_layer` from a config's
``custom_imports``, by the configs' runner and by the tools), never by
importing a layer package: each of those only checks, with
:func:`check_mmseg_layer`, that it can import MMSeg, and says which call is
missing where it cannot.
"""
import functools
import importlib.metadata as metadata
import importlib.util
import os
import sys
from typing import Dict, List

__all__ = []

#: the import names of the stack
OPENMMLAB = ('mmengine', 'mmcv', 'mmseg')
#: stack (``STACK=`` of tools/setup_env.sh) -> import name -> the
#: distributions that provide it (docs/install.md)
STACKS = {
    'openmmlab': {'mmengine': ('mmengine',), 'mmcv': ('mmcv-lite', 'mmcv'),
                  'mmseg': ('mmsegmentation',)},
    'onedl': {'mmengine': ('onedl-mmengine',), 'mmcv': ('onedl-mmcv',),
              'mmseg': ('onedl-mmsegmentation',)},
}
_SETUP_HINT = ('`bash tools/setup_env.sh` (OpenMMLab\'s releases) or `STACK='
               'onedl bash tools/setup_env.sh` (the maintained onedl-* fork)')


def missing_openmmlab() -> List[str]:
    """The import names of the stack that cannot be found."""
    missing = []
    for name in OPENMMLAB:
        try:
            found = importlib.util.find_spec(name) is not None
        except (ImportError, ValueError):  # a parent or sys.modules entry
            found = False
        if not found:
            missing.append(name)
    return missing


@functools.lru_cache(maxsize=None)
def installed_stacks() -> Dict[str, Dict[str, str]]:
    """stack -> ``{distribution: version}`` of its distributions that are
    installed, for the stacks with any installed."""
    found = {}
    for stack, packages in STACKS.items():
        for distributions in packages.values():
            for distribution in distributions:
                try:
                    version = metadata.version(distribution)
                except metadata.PackageNotFoundError:
                    continue
                found.setdefault(stack, {})[distribution] = version
    return found


def require_openmmlab(what: str) -> None:
    """Raise a clear ImportError for ``what`` where the stack is missing, or
    where distributions of both stacks are installed (each overwrites the
    other's files of the same import packages)."""
    missing = missing_openmmlab()
    if missing:
        raise ImportError(
            f'{what} needs mmengine, mmcv and mmseg (missing here: '
            f'{", ".join(missing)}) from one of the two stacks: '
            f'{_stack_list()}. wgse_mmseg.core (spike I/O, wavelets, '
            f'representations, WGSE, the simulator) works without them; for '
            f'the rest run {_SETUP_HINT} or, on a GPU machine without '
            f'network, `bash dev/gpu_bundle.sh install` (docs/wgse_speed.md).')
    stacks = installed_stacks()
    if len(stacks) > 1:
        found = '; '.join(
            f'{stack}: ' + ', '.join(f'{d} {v}'
                                     for d, v in sorted(dists.items()))
            for stack, dists in sorted(stacks.items()))
        raise ImportError(
            f'{what}: distributions of both OpenMMLab stacks are installed '
            f'({found}); they share the import packages mmseg, mmengine and '
            f'mmcv, so neither is whole. Use a fresh environment made by '
            f'{_SETUP_HINT}, or uninstall one stack\'s distributions '
            f'(installing wgse_mmseg never pulls a stack in: choose one with '
            f'the extras [openmmlab] or [onedl]).')


def _stack_list() -> str:
    return '; '.join(
        f'{stack}: ' + ', '.join(' or '.join(dists)
                                 for dists in packages.values())
        for stack, packages in STACKS.items())


def _mmseg_importable() -> bool:
    """Whether MMSeg imports now: mmcv's compiled ops, the stand-in
    ``mmcv.ops`` installed, or an MMSeg that needs no ``mmcv.ops``."""
    from .compat.mmcv_ops_fallback import has_compiled_ops, stand_in_names
    installed = sys.modules.get('mmcv.ops')
    return (has_compiled_ops()
            or getattr(installed, '__wgse_fallback__', False)
            or not stand_in_names())


def check_mmseg_layer(what: str) -> None:
    """Before ``what`` (a layer package) imports MMSeg: a clear ImportError
    where the stack is missing, or where MMSeg cannot be imported yet because
    the patches were not applied (:func:`prepare_mmseg_layer`). Changes
    nothing in the process."""
    require_openmmlab(what)
    if _mmseg_importable():
        return
    from .compat import OPT_OUT
    if os.environ.get(OPT_OUT, '') not in ('', '0'):
        raise ImportError(
            f'{what} needs mmcv.ops, which mmcv-lite lacks: {OPT_OUT} is set, '
            f'so the stand-in of wgse_mmseg.compat is off. Unset it, or '
            f'install full mmcv; wgse_mmseg.core works either way.')
    raise ImportError(
        f'{what} imports MMSeg, which needs mmcv.ops, and mmcv-lite has no '
        f'compiled ops: set the MMSeg layer up first, explicitly: '
        f'wgse_mmseg.register_all_modules() in Python, '
        f"custom_imports=dict(imports=['wgse_mmseg.mmseg_layer']) in a "
        f'config (the shipped ones have it); the tools do it themselves.')


def prepare_mmseg_layer(what: str = 'the MMSeg layer of wgse_mmseg') -> None:
    """The explicit set-up of the MMSeg layer, before anything imports MMSeg:
    a clear ImportError where the stack is missing, else the compatibility
    patches (once per process, unless turned off;
    :func:`wgse_mmseg.compat.apply_compat`; a layer package imported
    afterwards says so where they are off and MMSeg cannot be imported)."""
    require_openmmlab(what)
    from .compat import apply_compat
    apply_compat()
