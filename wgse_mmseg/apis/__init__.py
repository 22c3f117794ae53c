"""What the tools and users run: inference on spike files
(:mod:`.inferencer`) and the experiment grid (:mod:`.experiments`). Import
the module you need; the benchmarks are :mod:`wgse_mmseg.benchmarks`."""
from .._openmmlab import require_openmmlab

require_openmmlab('wgse_mmseg.apis')  # each module checks MMSeg itself
