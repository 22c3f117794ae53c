"""Any MMSeg config as a spike config: its model, the spike dataset.

mmengine refuses two bases that set the same key, so a full MMSeg config
(one with its own data loaders, SegNeXt's say, which has no
``_base_/models`` file) cannot inherit the spike dataset base beside it.
:func:`spike_config` combines the two instead: everything of the MMSeg
config but its data (model, schedule, runtime), the spike dataset base's
data (loaders, evaluators, pipelines, the spike settings), and the model
changed by the documented recipe: the spike data preprocessor (with an
enhancer or none) and the heads' class count; T then reaches the stem by
the spike settings (:mod:`wgse_mmseg.utils.spike_settings`). A sliding
test window given as one side (MMSeg's UNet bases) becomes ``(side,
side)``, as MMSeg's own UNet configs set it.
"""
import os.path as osp
from typing import Any, Dict, Optional, Union

from .cross_checks import OWN_TARGET_HEADS, ModelFitError
from .spike_settings import stem_fields

__all__ = []

#: the keys of the spike dataset base that replace an MMSeg config's data
DATA_KEYS = ('custom_imports', 'dataset_type', 'num_classes', 'data_root',
             'num_steps', 'crop_size', 'train_pipeline', 'test_pipeline',
             'train_dataloader', 'val_dataloader', 'test_dataloader',
             'val_evaluator', 'test_evaluator', 'spike_data_preprocessor',
             'tta_pipeline')
#: what MMSeg configs keep of an RGB data set that a spike set has not
RGB_KEYS = ('img_ratios', )
#: the package's dataset base, under its configs
DATASET_BASE = osp.join('_base_', 'datasets', 'spike_cityscapes.py')


def _heads(model: dict):
    """The head configs of ``model`` (decode and auxiliary, lists too)."""
    for key in ('decode_head', 'auxiliary_head'):
        heads = model.get(key)
        for head in heads if isinstance(heads, (list, tuple)) else [heads]:
            if isinstance(head, dict):
                yield head


def spike_config(config: Union[str, Any], enhancer: Optional[dict] = None,
                 cfg_options: Optional[Dict[str, Any]] = None):
    """The MMSeg config ``config`` (a path, ``mmseg::`` names included, or
    a loaded ``Config``) with the spike dataset's data and its model
    taking spikes: an mmengine ``Config`` to train or test like a shipped
    one (``Runner.from_cfg``, or ``cfg.dump(path)`` for the tools).

    Args:
        config: a full MMSeg config or a model base.
        enhancer: the enhancer's config (``dict(type='WGSE')``), or
            ``None`` for raw spikes.
        cfg_options: ``--cfg-options`` as a dict, applied last (``num_steps``,
            ``data_root``, ``crop_size`` to every field that carries them).
    """
    from mmengine.config import Config

    from ..openmmlab_stack import prepare_mmseg_layer
    from ..compat.config_scopes import package_configs
    from .config import load_config
    prepare_mmseg_layer('spike_config')
    if isinstance(config, Config):
        cfg = config
    elif '::' in config:  # a package's config: mmengine's hub finds it
        from mmengine.hub import get_config
        cfg = get_config(config)
    else:
        cfg = Config.fromfile(config)
    base = Config.fromfile(osp.join(package_configs(), DATASET_BASE))
    merged = {key: value for key, value in cfg.to_dict().items()
              if key not in DATA_KEYS + RGB_KEYS}
    merged.update({key: base[key] for key in DATA_KEYS})
    model = merged['model']
    if not isinstance(model.get('decode_head'), (dict, list, tuple)):
        raise ModelFitError(
            f'{getattr(cfg, "filename", config)}: its model '
            f'({model.get("type")}) has no decode_head: not a segmentor '
            f'that spike segmentation can train')
    model['data_preprocessor'] = dict(base['spike_data_preprocessor'],
                                      enhancer=enhancer)
    for head in _heads(model):
        if 'num_classes' in head and \
                head.get('type') not in OWN_TARGET_HEADS:
            head['num_classes'] = base['num_classes']
    test_cfg = model.get('test_cfg')
    if isinstance(test_cfg, dict) and isinstance(test_cfg.get('crop_size'),
                                                 int):  # UNet's bases
        side = test_cfg['crop_size']
        test_cfg['crop_size'] = (side, side)
        if isinstance(test_cfg.get('stride'), int):
            test_cfg['stride'] = (test_cfg['stride'], ) * 2
    merged.setdefault('default_scope', 'mmseg')
    spike = Config(merged, filename=getattr(cfg, 'filename', None))
    for _, backbone in stem_fields(spike):
        backbone.pop('in_channels', None)  # the settings give it T
    return load_config(spike, cfg_options)
