"""MMSeg models: the spike data preprocessor, the registered enhancers
(:mod:`.enhancers`) and image reconstruction (:mod:`.reconstruction`)."""
from .._openmmlab import prepare_mmseg_layer

prepare_mmseg_layer('wgse_mmseg.models')

from .data_preprocessor import SpikeSegDataPreProcessor  # noqa: E402
from .enhancers import ENHANCERS  # noqa: E402
from .reconstruction import (ResidualBlock,  # noqa: E402
                             SpikeReconstructor, load_reconstructor)

__all__ = ['SpikeSegDataPreProcessor', 'ENHANCERS', 'SpikeReconstructor',
           'ResidualBlock', 'load_reconstructor']
