"""What the MMSeg layer needs before it imports MMSeg.

:mod:`wgse_mmseg.core` needs only torch and numpy; the MMSeg layer
(``wgse_mmseg.datasets``, ``.evaluation``, ``.models``, ``.apis``,
``.utils``) and the tools need mmengine, mmsegmentation and mmcv (or
mmcv-lite) as well, and the compatibility patches of
:mod:`wgse_mmseg.compat`. Each layer package calls
:func:`prepare_mmseg_layer` first.
"""
import importlib.util
from typing import List

__all__ = ['OPENMMLAB', 'missing_openmmlab', 'require_openmmlab',
           'prepare_mmseg_layer']

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


def prepare_mmseg_layer(what: str) -> None:
    """Before ``what`` (a layer package) imports MMSeg: a clear ImportError
    where the stack is missing, else the compatibility patches (once per
    process, unless turned off; :func:`wgse_mmseg.compat.apply_compat`)."""
    require_openmmlab(what)
    from .compat import OPT_OUT, apply_compat
    from .compat.mmcv_ops_fallback import has_compiled_ops
    if not apply_compat() and not has_compiled_ops():
        raise ImportError(
            f'{what} needs mmcv.ops, which mmcv-lite lacks: {OPT_OUT} is set, '
            f'so the stand-in of wgse_mmseg.compat is off. Unset it, or '
            f'install full mmcv; wgse_mmseg.core works either way.')
