"""What the tools run: model benchmarks (:mod:`.benchmarking`) and the
reconstruction benchmark (:mod:`.reconstruction_benchmark`). Import the
module you need; importing this package registers nothing."""
from .._openmmlab import require_openmmlab

require_openmmlab('wgse_mmseg.apis')
