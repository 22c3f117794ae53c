"""What the tools run: model benchmarks (:mod:`.benchmarking`) and the
reconstruction benchmark (:mod:`.reconstruction_benchmark`). Import the
module you need; importing this package registers nothing."""
from .._openmmlab import prepare_mmseg_layer

prepare_mmseg_layer('wgse_mmseg.apis')
