"""MMSeg models: the spike data preprocessor, which owns and runs the
enhancer in every segmentor, the registered enhancers (:mod:`.enhancers`),
the legacy segmentor name (:mod:`.segmentors`) and image reconstruction
(:mod:`.reconstruction`)."""
from ..openmmlab_stack import check_mmseg_layer

check_mmseg_layer('wgse_mmseg.models')

from .data_preprocessor import (SpikeModelMismatchError,  # noqa: E402
                                SpikeSegDataPreProcessor)
from .enhancers import ENHANCERS  # noqa: E402
from .reconstruction import (ResidualBlock,  # noqa: E402
                             SpikeReconstructor, load_reconstructor)
from .segmentors import LEGACY_SEGMENTORS  # noqa: E402

__all__ = [
    'SpikeSegDataPreProcessor', 'SpikeModelMismatchError',
    'SpikeReconstructor', 'load_reconstructor'
]
