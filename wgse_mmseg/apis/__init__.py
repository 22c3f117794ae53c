"""What the tools and users run: inference on spike files
(:mod:`.inferencer`), checkpoint loading, ONNX export and its runtime.
Import the module you need. The benchmarks and experiment grids are the
measurement wing, ``wgse_bench``, which this package never imports."""
from ..openmmlab_stack import require_openmmlab

require_openmmlab('wgse_mmseg.apis')  # each module checks MMSeg itself
