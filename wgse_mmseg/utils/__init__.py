"""Helpers of the MMSeg layer: loading configs with the package's overrides
(:mod:`.config`) and reading the config stored in a checkpoint as data
(:mod:`.config_data`)."""
from .._openmmlab import prepare_mmseg_layer

prepare_mmseg_layer('wgse_mmseg.utils')
