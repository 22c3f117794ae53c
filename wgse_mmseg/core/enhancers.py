"""The enhancers, listed once.

An enhancer is a module ``(B, T, H, W) -> (B, T, H, W)`` a model config puts
in front of its network (``data_preprocessor=dict(enhancer=dict(type=...))``
for segmentation, ``enhancer=`` of the reconstruction model). Every other
list derives from :data:`ENHANCERS`: the MMSeg registration
(:mod:`wgse_mmseg.models.enhancers`) and the classes a checkpoint's model
config may build
(:data:`wgse_mmseg.models.reconstruction.RECONSTRUCTION_BUILDS`).
"""
from .representations import (TFI, TFP, SpatialMeanFilter,
                              TemporalMeanFilter)
from .wgse import WGSE

__all__ = []

#: WGSE and the classical representations, each refusing NaN and Inf
#: (:func:`~wgse_mmseg.core.checks.check_finite`)
ENHANCERS = (WGSE, TFP, TFI, SpatialMeanFilter, TemporalMeanFilter)
