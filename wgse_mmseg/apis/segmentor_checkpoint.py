"""A trained spike segmentor from its config and a checkpoint, strictly.

``mmseg.apis.init_model`` loads a checkpoint non-strictly: one trained for
another ``num_steps`` would leave the backbone's stem at random weights with
only a logged warning. :func:`load_segmentor` refuses such a file instead,
and reads it weights-only (nothing in it is executed). ``tools/demo.py`` and
the ONNX export (:mod:`.onnx_export`) load their models through it.
"""
from .._openmmlab import check_mmseg_layer

check_mmseg_layer('wgse_mmseg.apis.segmentor_checkpoint')  # before MMSeg
# is imported
from typing import Dict, Tuple  # noqa: E402

from mmengine.runner.checkpoint import load_state_dict  # noqa: E402
from torch import nn  # noqa: E402

from mmseg.registry import MODELS  # noqa: E402
from ..datasets import SpikeCityscapesDataset  # noqa: E402
from ..utils.checkpoint import read_checkpoint  # noqa: E402

__all__ = ['load_segmentor']


def _dataset_meta(state: dict) -> Dict[str, list]:
    """Classes and palette from a checkpoint's ``meta['dataset_meta']``,
    Spike-Cityscapes' where it names none."""
    meta = state.get('meta')
    meta = meta.get('dataset_meta') if isinstance(meta, dict) else None
    meta = meta if isinstance(meta, dict) else {}
    default = SpikeCityscapesDataset.METAINFO
    return dict(classes=list(meta.get('classes', default['classes'])),
                palette=[list(c) for c in meta.get('palette',
                                                   default['palette'])])


def load_segmentor(cfg, checkpoint: str) -> Tuple[nn.Module, dict]:
    """The segmentor of ``cfg`` (a loaded config; its ``num_steps`` set)
    with the weights of ``checkpoint``, and its dataset meta (``classes``,
    ``palette``).

    The checkpoint is read weights-only
    (:func:`~wgse_mmseg.utils.checkpoint.read_checkpoint`) and must fit the
    model exactly: a ``ValueError`` names the file otherwise (one trained
    with another ``T`` needs ``--cfg-options num_steps=T``).
    """
    model = MODELS.build(cfg.model)
    state = read_checkpoint(checkpoint)
    try:
        load_state_dict(model, state.get('state_dict', state), strict=True)
    except RuntimeError as err:
        raise ValueError(
            f'{checkpoint}: does not fit the model built from the config '
            f'(num_steps={cfg.get("num_steps")}; a checkpoint trained with '
            f'another T needs --cfg-options num_steps=T): {err}') from err
    return model.eval(), _dataset_meta(state)
