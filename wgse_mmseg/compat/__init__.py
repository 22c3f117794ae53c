"""The compatibility patches the MMSeg layer needs, in one place.

The package runs on two stacks with the same import packages (``mmseg``,
``mmengine``, ``mmcv``, ``mim``): OpenMMLab's final releases and the
maintained onedl-* fork (docs/install.md). :func:`apply_compat` makes each
change below only where a check of the installed stack finds it missing,
never by version lists; what the checks find on the two pinned stacks:

.. list-table::
   :header-rows: 1

   * - patch (what decides it)
     - OpenMMLab: mmseg 1.2.2, mmengine 0.10.7, mmcv(-lite) 2.1.0
     - onedl: mmseg 1.4.2, mmengine 0.10.12, onedl-mmcv 2.3.6
   * - stand-in ``mmcv.ops`` with the names MMSeg imports
       (:func:`install_mmcv_ops_fallback`: ``mmcv._ext`` present, and how
       MMSeg's source guards its ``mmcv.ops`` imports)
     - installed under mmcv-lite (``point_sample`` and
       ``sigmoid_focal_loss`` are imported unguarded); nothing under full
       mmcv
     - not installed: every ``mmcv.ops`` import is guarded
   * - torch's allowlist gets mmengine's checkpoint classes
       (:func:`allow_mmengine_checkpoints`: ``add_safe_globals`` exists)
     - added
     - added
   * - mmengine's checkpoint loader without full unpickling
       (:func:`guard_mmengine_checkpoint_loader`: a probe checkpoint)
     - left alone: it loads weights-only (torch's default)
     - replaced: its ``_safe_torch_load`` retries with
       ``weights_only=False``
   * - ``mmseg::`` scope to the installed distribution
       (:func:`map_scopes_to_installed_distributions`: the named
       distribution is missing)
     - left alone: ``mmsegmentation`` is installed
     - ``mmseg`` to ``onedl-mmsegmentation``
   * - ``wgse_mmseg::`` bases read from the package's configs
       (:func:`resolve_package_scope`: always, see its module)
     - added
     - added
   * - warnings quieted (:data:`QUIETED_WARNINGS`, where raised)
     - MMSeg's ``build_loss``/``build_pixel_sampler`` deprecations; mmcv's
       missing ``MultiScaleDeformableAttention`` under mmcv-lite
     - mmcv's missing ``MultiScaleDeformableAttention`` (no ops)

:func:`apply_compat` is the explicit set-up of the MMSeg layer, called
before MMSeg is imported (:func:`wgse_mmseg.register_all_modules`, also made
by importing :mod:`wgse_mmseg.mmseg_layer` from a config, by the tools, by
:func:`wgse_mmseg.utils.config.load_config` and by the configs' runner);
importing a module of the package applies nothing.

``WGSE_MMSEG_NO_COMPAT=1`` in the environment turns every patch off (then
MMSeg 1.2.2 needs full mmcv, resuming a checkpoint needs
``torch.serialization.add_safe_globals`` done by the user, the fork's
mmengine may unpickle a checkpoint in full, ``mmseg::`` bases do not
resolve on the fork, and ``wgse_mmseg::`` bases on neither stack).
"""
import os

import warnings

from .checkpoint_safety import (allow_mmengine_checkpoints,
                                guard_mmengine_checkpoint_loader)
from .config_scopes import (map_scopes_to_installed_distributions,
                            resolve_package_scope)
from .mmcv_ops_fallback import install_mmcv_ops_fallback

__all__ = []

#: the environment variable that turns the patches off
OPT_OUT = 'WGSE_MMSEG_NO_COMPAT'
#: (message start, module) of warnings OpenMMLab's code gives in every run
#: about itself: MMSeg 1.2.2's deprecations of its own internal calls, and
#: mmcv's import of an op it cannot have without compiled ops (the one-line
#: notice of :mod:`.mmcv_ops_fallback` says that once); nothing a user of the
#: configs can change
QUIETED_WARNINGS = (
    ('``build_loss`` would be deprecated soon', 'mmseg.models.builder'),
    ('``build_pixel_sampler`` would be deprecated soon',
     'mmseg.structures.sampler.builder'),
    ('Fail to import ``MultiScaleDeformableAttention``',
     'mmcv.cnn.bricks.transformer'),
)
_applied = False


def apply_compat() -> bool:
    """Apply the patches the installed stack needs, once per process, unless
    :data:`OPT_OUT` is set to something other than ``''`` or ``'0'``.
    Returns whether they are applied."""
    global _applied
    if os.environ.get(OPT_OUT, '') not in ('', '0'):
        return False
    if not _applied:
        for message, module in QUIETED_WARNINGS:
            warnings.filterwarnings('ignore', message=message, module=module)
        install_mmcv_ops_fallback()
        allow_mmengine_checkpoints()
        guard_mmengine_checkpoint_loader()
        map_scopes_to_installed_distributions()
        resolve_package_scope()
        _applied = True
    return True
