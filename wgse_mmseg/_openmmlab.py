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
import importlib.util
import os
import sys
from typing import List

__all__ = []

#: import name -> distribution to install
OPENMMLAB = {'mmengine': 'mmengine', 'mmcv': 'mmcv-lite',
             'mmseg': 'mmsegmentation'}


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


def require_openmmlab(what: str) -> None:
    """Raise a clear ImportError for ``what`` where the stack is missing."""
    missing = missing_openmmlab()
    if missing:
        raise ImportError(
            f'{what} needs {", ".join(OPENMMLAB[n] for n in missing)} '
            f'(import names: {", ".join(missing)}), which cannot be imported '
            f'here. wgse_mmseg.core (spike I/O, wavelets, representations, '
            f'WGSE, the simulator) works without them; for the rest run '
            f'`bash tools/setup_env.sh` or, on a GPU machine without network, '
            f'`bash tools/gpu_bundle.sh install` (docs/wgse_speed.md).')


def _mmcv_ops_importable() -> bool:
    """Whether ``import mmcv.ops`` works: full mmcv, or the stand-in is
    installed."""
    from .compat.mmcv_ops_fallback import has_compiled_ops
    installed = sys.modules.get('mmcv.ops')
    return has_compiled_ops() or getattr(installed, '__wgse_fallback__',
                                         False)


def check_mmseg_layer(what: str) -> None:
    """Before ``what`` (a layer package) imports MMSeg: a clear ImportError
    where the stack is missing, or where MMSeg cannot be imported yet because
    the patches were not applied (:func:`prepare_mmseg_layer`). Changes
    nothing in the process."""
    require_openmmlab(what)
    if _mmcv_ops_importable():
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
