"""Datasets and pipeline transforms, registered with MMSeg.

* :class:`SpikeCityscapesDataset` (:mod:`.spike_cityscapes`);
* reconstruction data (:mod:`.reds`);
* transforms (:mod:`.transforms`).

What makes the data (the Cityscapes converter, the synthetic street scenes,
REDS-style views) is :mod:`wgse_mmseg.data_generation`, which needs no
OpenMMLab.
"""
from ..openmmlab_stack import check_mmseg_layer

check_mmseg_layer('wgse_mmseg.datasets')

from .reds import (LoadSpikeImagePair,  # noqa: E402
                   PackReconstructionInputs, REDSSpikeDataset,
                   SimulatedSpikeImageDataset)
from .spike_cityscapes import SpikeCityscapesDataset  # noqa: E402
from .transforms import (LoadSpikeFromFile, SimulateSpikes,  # noqa: E402
                         SpikeRandomCrop, SpikeRandomFlip)

__all__ = [
    'SpikeCityscapesDataset', 'REDSSpikeDataset',
    'SimulatedSpikeImageDataset', 'LoadSpikeFromFile', 'SpikeRandomCrop',
    'SpikeRandomFlip', 'SimulateSpikes', 'LoadSpikeImagePair',
    'PackReconstructionInputs'
]
