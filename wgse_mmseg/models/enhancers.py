"""The enhancers registered with MMSeg, by class name.

``data_preprocessor=dict(enhancer=dict(type='WGSE', ...))`` builds
:class:`~wgse_mmseg.core.wgse.WGSE`; every class of
:data:`wgse_mmseg.core.enhancers.ENHANCERS` (the one list) is registered
the same way. The classes live in :mod:`wgse_mmseg.core` (torch only); this
module only registers them.
"""
from mmseg.registry import MODELS

from ..core.enhancers import ENHANCERS

for _enhancer in ENHANCERS:
    MODELS.register_module(module=_enhancer)

__all__ = []
