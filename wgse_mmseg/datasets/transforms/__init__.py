"""Pipeline transforms for spike streams: loading (:mod:`.loading`),
augmentation (:mod:`.transforms`) and on-the-fly simulation from RGB frames
(:mod:`.simulate`)."""
from .loading import LoadSpikeFromFile
from .simulate import SimulateSpikes
from .transforms import SpikeRandomCrop, SpikeRandomFlip

__all__ = ['LoadSpikeFromFile', 'SpikeRandomCrop', 'SpikeRandomFlip',
           'SimulateSpikes']
