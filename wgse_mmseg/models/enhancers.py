"""The enhancers a config puts in front of a model, registered with MMSeg.

``data_preprocessor=dict(enhancer=dict(type='WGSE', ...))`` builds
:class:`~wgse_mmseg.core.wgse.WGSE`; ``'TFP'``, ``'TFI'``,
``'SpatialMeanFilter'`` and ``'TemporalMeanFilter'`` build the classical
representations of :mod:`wgse_mmseg.core.representations`. The classes live
in :mod:`wgse_mmseg.core` (torch only); this module only registers them.
"""
from mmseg.registry import MODELS

from ..core.representations import (TFI, TFP, SpatialMeanFilter,
                                    TemporalMeanFilter)
from ..core.wgse import WGSE

ENHANCERS = (WGSE, TFP, TFI, SpatialMeanFilter, TemporalMeanFilter)
for _enhancer in ENHANCERS:
    MODELS.register_module(module=_enhancer)

__all__ = ['ENHANCERS']
