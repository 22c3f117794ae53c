"""The compatibility patches the MMSeg layer needs, in one place.

Two changes to the process, both made by :func:`apply_compat`, which the
explicit set-up of the MMSeg layer calls before MMSeg is imported
(:func:`wgse_mmseg.register_all_modules`, also made by importing
:mod:`wgse_mmseg.mmseg_layer` from a config, by the tools and by the
configs' runner); importing a module of the package applies neither:

* :func:`install_mmcv_ops_fallback`: where mmcv's compiled ops are missing
  (mmcv-lite), a stand-in ``mmcv.ops`` with the few names MMSeg imports at
  module level (nothing is replaced under full mmcv);
* :func:`allow_mmengine_checkpoints`: torch's weights-only unpickler learns
  exactly the classes mmengine checkpoints hold, so resuming works under
  torch >= 2.6 with weights-only loading still on;

and it silences the deprecation warnings of :data:`QUIETED_DEPRECATIONS`,
which MMSeg raises about its own calls in every run.

``WGSE_MMSEG_NO_COMPAT=1`` in the environment turns both off (then MMSeg
needs full mmcv, and resuming a checkpoint needs
``torch.serialization.add_safe_globals`` done by the user).
"""
import os

import warnings

from .checkpoint_safety import allow_mmengine_checkpoints
from .mmcv_ops_fallback import install_mmcv_ops_fallback

__all__ = []

#: the environment variable that turns the patches off
OPT_OUT = 'WGSE_MMSEG_NO_COMPAT'
#: (message start, module) of the deprecation warnings MMSeg 1.2.2 gives
#: about its own internal calls whenever a model is built; nothing a user of
#: the configs can change
QUIETED_DEPRECATIONS = (
    ('``build_loss`` would be deprecated soon', 'mmseg.models.builder'),
    ('``build_pixel_sampler`` would be deprecated soon',
     'mmseg.structures.sampler.builder'),
)
_applied = False


def apply_compat() -> bool:
    """Apply both patches, once per process, unless :data:`OPT_OUT` is set
    to something other than ``''`` or ``'0'``. Returns whether they are
    applied."""
    global _applied
    if os.environ.get(OPT_OUT, '') not in ('', '0'):
        return False
    if not _applied:
        install_mmcv_ops_fallback()
        allow_mmengine_checkpoints()
        for message, module in QUIETED_DEPRECATIONS:
            warnings.filterwarnings('ignore', message=message, module=module)
        _applied = True
    return True
