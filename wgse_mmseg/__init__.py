"""wgse_mmseg: spike-camera data and WGSE for MMSegmentation.

Importing the package registers everything with MMSeg's registries
(``custom_imports=dict(imports=['wgse_mmseg'])`` in a config does the same).
Where mmcv's compiled ops are missing (mmcv-lite), it first supplies the few
``mmcv.ops`` names MMSeg imports at module level, and says so once.
"""
from .compat import allow_mmengine_checkpoints, install_mmcv_ops_fallback
from .version import __version__

install_mmcv_ops_fallback()
allow_mmengine_checkpoints()

from . import datasets, evaluation, models  # noqa: E402  (registers the modules)

__all__ = ["__version__", "datasets", "evaluation", "models"]
