from .._openmmlab import require_openmmlab

require_openmmlab('wgse_mmseg.datasets')

from . import reds, simulate_transform  # noqa: E402,F401  (registers)
from .spike_cityscapes import SpikeCityscapesDataset  # noqa: E402
from .transforms import LoadSpikeFromFile, SpikeRandomCrop, SpikeRandomFlip  # noqa: E402

__all__ = [
    'SpikeCityscapesDataset', 'LoadSpikeFromFile', 'SpikeRandomCrop',
    'SpikeRandomFlip'
]
