"""MMSeg models: the spike data preprocessor, the registered enhancers
(:mod:`.enhancers`) and image reconstruction (:mod:`.reconstruction`)."""
from .._openmmlab import require_openmmlab

require_openmmlab('wgse_mmseg.models')

from . import enhancers, reconstruction  # noqa: E402,F401  (registers)
from .data_preprocessor import SpikeSegDataPreProcessor  # noqa: E402

__all__ = ['SpikeSegDataPreProcessor']
