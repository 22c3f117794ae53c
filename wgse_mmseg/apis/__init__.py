"""What the tools and users run: inference on spike files
(:mod:`.inferencer`), model benchmarks (:mod:`.benchmarking`), the
experiment grid (:mod:`.experiments`) and the reconstruction and simulator
benchmarks. Import the module you need."""
from .._openmmlab import require_openmmlab

require_openmmlab('wgse_mmseg.apis')  # each module checks MMSeg itself
