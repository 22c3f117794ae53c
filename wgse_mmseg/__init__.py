"""wgse_mmseg: spike-camera data and WGSE for MMSegmentation.

Without OpenMMLab:

* :mod:`wgse_mmseg.core`, the spike maths (torch, NumPy, PyWavelets;
  Triton for the GPU kernels): wavelets, representations, WGSE and its
  kernels, the simulator, the spike formats;
* :mod:`wgse_mmseg.fileio`, the file plumbing (torch-free): spike and image
  files, atomic writes, output folders, the input guard;
* :mod:`wgse_mmseg.data_generation` (converters, synthetic scenes) on top
  of both;

and with it:

* the MMSeg layer (:mod:`.datasets`, :mod:`.engine`, :mod:`.evaluation`,
  :mod:`.models`; :mod:`.apis` and :mod:`.utils` for the tools) registers them,
  and the datasets, transforms, data preprocessor and metrics, with MMSeg's
  registries.

Importing a module changes nothing in the process (``import wgse_mmseg``
imports none of its subpackages, nor torch, OpenMMLab, Triton, ONNX or
OpenCV; import a subpackage by name, ``import wgse_mmseg.core``; as
``import mmseg`` registers nothing). The MMSeg layer
needs compatibility patches (:mod:`wgse_mmseg.compat`: under mmcv-lite a
stand-in ``mmcv.ops`` that MMSeg imports at module level; torch's
weights-only allowlist for mmengine checkpoints; MMSeg's own deprecation
warnings quieted) before MMSeg is imported, applied by one explicit call,
:func:`register_all_modules`, which also registers the layer: Python code
calls it, a config names :mod:`wgse_mmseg.mmseg_layer` in ``custom_imports``
(whose import makes the call; the shipped configs do), and the tools and the
configs' runner make it themselves. ``WGSE_MMSEG_NO_COMPAT=1`` turns the
patches off. A layer package imported before the call, where MMSeg cannot
be imported without it, raises an ImportError that names the call; without
the OpenMMLab stack it says what to install.
"""
import importlib

from .errors import WgseError
from .version import __version__

#: the packages that register with MMSeg
_MMSEG_LAYER = ('wgse_mmseg.datasets', 'wgse_mmseg.engine',
                'wgse_mmseg.evaluation', 'wgse_mmseg.models')


def register_all_modules() -> None:
    """Set up the MMSeg layer: apply the compatibility patches (once per
    process), then register every module of the package with MMSeg's
    registries (its datasets, transforms, models, metrics, runner and hooks).
    Call it before importing MMSeg or a layer package; a config does the
    same by naming ``wgse_mmseg.mmseg_layer`` in ``custom_imports``."""
    from .openmmlab_stack import prepare_mmseg_layer
    prepare_mmseg_layer()
    for name in _MMSEG_LAYER:
        importlib.import_module(name)


def load_config(path: str, cfg_options: dict = None):
    """The config at ``path`` as the tools read it: ``cfg_options`` (a dict
    of dotted keys, ``--cfg-options``' values: ``{'num_steps': 41,
    'data_root': DIR}``) applied, the spike settings given to every field
    that carries them (the loaders, the data preprocessor, the backbone's
    stem, whatever the backbone), the MMSeg layer set up. Pass the result
    to ``mmseg.apis.init_model`` for the model ``tools/test.py`` builds."""
    from .utils.config import load_config as load
    return load(path, cfg_options)


def spike_config(config, enhancer: dict = None, cfg_options: dict = None):
    """Any MMSeg config (a path, ``mmseg::`` names included, or a loaded
    ``Config``: a model base or a full config, such as SegNeXt's, that
    mmengine would refuse to combine with the spike dataset base) with the
    spike dataset's data, its model taking spikes (the spike data
    preprocessor with ``enhancer``, T to the stem, the heads' classes to
    the data's) and ``cfg_options`` applied. The result trains and tests
    as a shipped config does; ``cfg.dump(path)`` writes it for the tools."""
    from .utils.spike_model import spike_config as combine
    return combine(config, enhancer, cfg_options)


__all__ = ['__version__', 'WgseError', 'load_config', 'register_all_modules',
           'spike_config']
