"""The WGSE benchmark's choices (:mod:`.wgse`): its rows and batch shapes,
importable without torch, so that its command line answers ``--help`` and
argument errors at once."""
from wgse_mmseg.core.arguments import NUM_STEPS, SIDE, Integer, SequenceOf
from wgse_mmseg.core.limits import MAX_BATCH_SIZE

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
