"""wgse_mmseg: spike-camera data and WGSE for MMSegmentation.

Two layers:

* :mod:`wgse_mmseg.core` needs only torch and numpy: spike I/O, wavelets,
  representations, WGSE and its kernels, the simulator;
* the MMSeg layer (:mod:`.datasets`, :mod:`.engine`, :mod:`.evaluation`,
  :mod:`.models`; :mod:`.apis` and :mod:`.utils` for the tools) registers them, and the
  datasets, transforms, data preprocessor and metrics, with MMSeg's
  registries.

``import wgse_mmseg`` imports core only and changes nothing in the process,
as ``import mmseg`` registers nothing. The MMSeg layer registers when it is
imported: a config names it in ``custom_imports`` (the shipped ``_base_``
configs do), Python code calls :func:`register_all_modules`, and
``wgse_mmseg.models`` (any layer name) imports it on first use. A layer
package applies the compatibility patches of :mod:`wgse_mmseg.compat` before
it imports MMSeg (once per process; ``WGSE_MMSEG_NO_COMPAT=1`` turns them
off); without the OpenMMLab stack it raises an ImportError that says what to
install.
"""
import importlib

from . import core
from .version import __version__

#: the packages that register with MMSeg, as a config's ``custom_imports``
MMSEG_LAYER = ('wgse_mmseg.datasets', 'wgse_mmseg.engine',
               'wgse_mmseg.evaluation', 'wgse_mmseg.models')
_LAZY = ('apis', 'benchmarks', 'compat', 'datasets', 'engine', 'evaluation',
         'models', 'utils')


def register_all_modules() -> None:
    """Register every module of the package with MMSeg's registries (import
    :data:`MMSEG_LAYER`); for Python code that builds from configs that do
    not list ``custom_imports``."""
    for name in MMSEG_LAYER:
        importlib.import_module(name)


def __getattr__(name):
    if name in _LAZY:
        return importlib.import_module(f'{__name__}.{name}')
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')


__all__ = ['__version__', 'core', 'register_all_modules', 'MMSEG_LAYER']
