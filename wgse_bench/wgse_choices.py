"""The choices of WGSE's benchmarks: the rows and batch shapes of
:mod:`.wgse`, the precisions of the band kernels that
:mod:`.gpu_report` and ``dev/sweep_band_kernels.py`` run, importable without
torch, so that their command lines answer ``--help`` and argument errors at
once. The kernels' own choices are :mod:`wgse_mmseg.core.kernel_choices`'."""
from wgse_mmseg.command_line import NUM_STEPS, SIDE, Integer, SequenceOf
from wgse_mmseg.core.kernel_choices import TOLERANCES
from wgse_mmseg.limits import MAX_BATCH_SIZE

__all__ = []

#: row -> what it runs
IMPLEMENTATIONS = {
    'reference': 'pytorch_wavelets + per-pixel nn.Conv1d',
    'torch': "WGSE, backend='torch'",
    'compiled': "WGSE, backend='compiled'",
    'triton': "WGSE, backend='triton'",
}
DEFAULT_SHAPES = ['4x41x128x128', '1x129x128x256']
#: a batch's shape, ``BxTxHxW`` on a command line
SHAPE = SequenceOf((Integer(1, MAX_BATCH_SIZE), NUM_STEPS, SIDE, SIDE),
                   names=('B', 'T', 'H', 'W'), separator='x')
#: the band kernels' precisions (TF32 off, TF32, bf16 autocast, fp16
#: autocast), each with its tolerance in the first-use check
PRECISIONS = tuple(TOLERANCES)
