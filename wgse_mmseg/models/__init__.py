"""MMSeg models: the spike data preprocessor, the registered enhancers
(:mod:`.enhancers`), the segmentor that runs them in its forward
(:mod:`.segmentors`) and image reconstruction (:mod:`.reconstruction`)."""
from .._openmmlab import prepare_mmseg_layer

prepare_mmseg_layer('wgse_mmseg.models')

from .data_preprocessor import SpikeSegDataPreProcessor  # noqa: E402
from .enhancers import ENHANCERS  # noqa: E402
from .reconstruction import (ResidualBlock,  # noqa: E402
                             SpikeReconstructor, load_reconstructor)
from .segmentors import SpikeEncoderDecoder  # noqa: E402

__all__ = ['SpikeSegDataPreProcessor', 'ENHANCERS', 'SpikeReconstructor',
           'ResidualBlock', 'load_reconstructor', 'SpikeEncoderDecoder']
