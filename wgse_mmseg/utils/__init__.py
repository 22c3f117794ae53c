"""Helpers of the MMSeg layer: loading configs with the package's overrides
(:mod:`.config`), the spike settings and the fields that carry them
(:mod:`.spike_settings`) and reading the config stored in a checkpoint as
data (:mod:`.config_data`). They need mmengine, not MMSeg itself."""
from ..openmmlab_stack import require_openmmlab

require_openmmlab('wgse_mmseg.utils')
