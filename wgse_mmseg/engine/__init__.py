"""Training-loop pieces registered with MMSeg: the shipped configs' runner
(:mod:`.runner`), the visualisation hook that draws spike clips
(:mod:`.visualization_hook`) and the model wrapper for distributed runs on
CPUs (:mod:`.model_wrappers`)."""
from ..openmmlab_stack import check_mmseg_layer

check_mmseg_layer('wgse_mmseg.engine')

from .model_wrappers import CPUDistributedDataParallel  # noqa: E402
from .runner import SpikeRunner  # noqa: E402
from .visualization_hook import (SpikeVisualizationHook,  # noqa: E402
                                 spike_clip_image)

__all__ = [
    'CPUDistributedDataParallel', 'SpikeRunner', 'SpikeVisualizationHook'
]
