from . import reds, simulate_transform  # noqa: F401  (registers)
from .spike_cityscapes import SpikeCityscapesDataset
from .transforms import LoadSpikeFromFile, SpikeRandomCrop, SpikeRandomFlip

__all__ = [
    'SpikeCityscapesDataset', 'LoadSpikeFromFile', 'SpikeRandomCrop',
    'SpikeRandomFlip'
]
