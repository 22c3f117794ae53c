"""``SpikeEncoderDecoder``: the segmentor name earlier configs gave, kept
so that they (and the configs stored in their checkpoints) still build.

The spike data preprocessor owns and runs the enhancer in every segmentor
(:class:`~wgse_mmseg.models.SpikeSegDataPreProcessor`), so a spike model
needs no segmentor of its own: the name builds MMSeg's ``EncoderDecoder``
itself, and the shipped configs use MMSeg's segmentor types directly.
"""
from mmseg.models.segmentors import EncoderDecoder
from mmseg.registry import MODELS

__all__ = []

#: earlier registered name -> the MMSeg segmentor it builds now
LEGACY_SEGMENTORS = {'SpikeEncoderDecoder': EncoderDecoder}
for _name, _segmentor in LEGACY_SEGMENTORS.items():
    MODELS.register_module(name=_name, module=_segmentor)
