"""wgse_mmseg: spike-camera data and WGSE for MMSegmentation.

Two layers:

* :mod:`wgse_mmseg.core` needs only torch and numpy: spike I/O, wavelets,
  representations, WGSE and its kernels, the simulator;
* the MMSeg layer (:mod:`.datasets`, :mod:`.models`, :mod:`.evaluation`)
  registers them, and the datasets, transforms, data preprocessor and
  metrics, with MMSeg's registries.

Importing the package imports core and, where mmengine, mmsegmentation and
mmcv are installed, the MMSeg layer, so that
``custom_imports=dict(imports=['wgse_mmseg'])`` in a config registers
everything; before that it applies the compatibility patches of
:mod:`wgse_mmseg.compat` (once per process; ``WGSE_MMSEG_NO_COMPAT=1``
turns them off). Without that stack the MMSeg layer's names raise an
ImportError that says what to install.
"""
import warnings

from . import core
from ._openmmlab import missing_openmmlab, require_openmmlab
from .version import __version__

_MMSEG_LAYER = ('datasets', 'evaluation', 'models')


def _import_mmseg_layer():
    """Apply the compatibility patches, then import (and so register) the
    MMSeg layer. Returns why it did not import, or ``None``."""
    from .compat import OPT_OUT, apply_compat
    applied = apply_compat()
    try:
        from . import datasets, evaluation, models  # noqa: F401 (registers)
    except ImportError as error:  # e.g. mmcv-lite with the patches off
        message = (f'the MMSeg layer of wgse_mmseg did not import: {error}' +
                   ('' if applied else f' ({OPT_OUT} is set: MMSeg then '
                                       f'needs full mmcv)'))
        warnings.warn(message + '; wgse_mmseg.core still works')
        return message
    return None


#: why the MMSeg layer did not import although the stack is installed
_LAYER_ERROR = None if missing_openmmlab() else _import_mmseg_layer()


def __getattr__(name):
    if name in _MMSEG_LAYER:  # only reached where the layer is missing
        if _LAYER_ERROR:
            raise ImportError(_LAYER_ERROR)
        require_openmmlab(f'wgse_mmseg.{name}')
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')


__all__ = ['__version__', 'core', 'datasets', 'evaluation', 'models']
