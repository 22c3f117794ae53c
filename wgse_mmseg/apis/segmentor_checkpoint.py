"""A trained spike segmentor from its config and a checkpoint, strictly.

``mmseg.apis.init_model`` loads a checkpoint non-strictly: one trained for
another ``num_steps`` would leave the backbone's stem at random weights with
only a logged warning. :func:`load_segmentor` refuses such a file instead,
and reads it weights-only (nothing in it is executed). ``tools/demo.py`` and
the ONNX export (:mod:`.onnx_export`) load their models through it.
"""
from ..openmmlab_stack import check_mmseg_layer

check_mmseg_layer('wgse_mmseg.apis.segmentor_checkpoint')  # before MMSeg
# is imported
from typing import Dict, Tuple  # noqa: E402

from mmengine.runner.checkpoint import load_state_dict  # noqa: E402
from torch import nn  # noqa: E402

from mmseg.registry import MODELS  # noqa: E402
from ..datasets import SpikeCityscapesDataset  # noqa: E402
from ..models.data_preprocessor import (SpikeModelMismatchError,  # noqa
                                        unfit_weights)
from ..utils.checkpoint import (CheckpointError, check_dataset_meta,  # noqa
                                checkpoint_state_dict, read_checkpoint)

__all__ = ['load_segmentor']


def _dataset_meta(path: str, state: dict) -> Dict[str, list]:
    """Classes and palette from a checkpoint's ``meta['dataset_meta']``
    (checked: :func:`~wgse_mmseg.utils.checkpoint.check_dataset_meta`),
    Spike-Cityscapes' for what it names none of."""
    meta = state.get('meta')
    if meta is not None and not isinstance(meta, dict):
        raise CheckpointError(f'{path}: meta must be a mapping, found '
                              f'{type(meta).__name__}')
    meta = (meta or {}).get('dataset_meta')
    meta = {} if meta is None else meta
    if not isinstance(meta, dict):
        raise CheckpointError(f'{path}: meta.dataset_meta must be a mapping '
                              f'with classes and palette, found '
                              f'{type(meta).__name__}')
    default = SpikeCityscapesDataset.METAINFO
    return check_dataset_meta(f'{path} (meta.dataset_meta)', dict(
        classes=meta.get('classes', list(default['classes'])),
        palette=meta.get('palette', [list(c) for c in default['palette']])))


def load_segmentor(cfg, checkpoint: str) -> Tuple[nn.Module, dict]:
    """The segmentor of ``cfg`` (a loaded config; its ``num_steps`` set)
    with the weights of ``checkpoint``, and its dataset meta (``classes``,
    ``palette``).

    The checkpoint is read weights-only, its state dict
    and dataset meta checked before the model is built, and must fit the
    model exactly: a ``ValueError`` names the file and the field otherwise
    (one trained with another ``T`` needs ``--cfg-options num_steps=T``).
    """
    state = read_checkpoint(checkpoint)
    weights = checkpoint_state_dict(checkpoint, state)
    dataset_meta = _dataset_meta(checkpoint, state)
    model = MODELS.build(cfg.model)
    try:
        load_state_dict(model, weights, strict=True)
    except SpikeModelMismatchError as err:
        raise SpikeModelMismatchError(f'{checkpoint}: {err}') from None
    except RuntimeError as err:
        raise unfit_weights(checkpoint, cfg.get('num_steps'), err) from err
    return model.eval(), dataset_meta
