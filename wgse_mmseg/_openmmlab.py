"""Whether the OpenMMLab stack that the MMSeg layer needs is installed.

:mod:`wgse_mmseg.core` needs only torch and numpy; ``wgse_mmseg.datasets``,
``.models``, ``.evaluation`` and the tools need mmengine, mmsegmentation
and mmcv (or mmcv-lite) as well.
"""
import importlib.util
from typing import List

__all__ = ['OPENMMLAB', 'missing_openmmlab', 'require_openmmlab']

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
