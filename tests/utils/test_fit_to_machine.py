"""A config fits the machine it runs on: SyncBN at any depth becomes BN
where there is no CUDA, and ``num_workers=0`` works alone."""
import os.path as osp
import warnings

import pytest
import torch
from mmengine.config import Config
from mmengine.registry import RUNNERS

import wgse_mmseg
from wgse_mmseg.utils.distributed import fit_to_cpus, fit_workers

wgse_mmseg.register_all_modules()
ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))


@pytest.mark.skipif(torch.cuda.is_available(), reason='a machine with CUDA')
def test_every_syncbn_becomes_bn_on_cpus_with_one_warning():
    cfg = Config(dict(model=dict(
        backbone=dict(norm_cfg=dict(type='SyncBN', requires_grad=True),
                      backbone_cfg=dict(norm_cfg=dict(type='SyncBN'))),
        decode_head=[dict(norm_cfg=dict(type='SyncBN')),
                     dict(norm_cfg=dict(type='GN', num_groups=2))])))
    with pytest.warns(UserWarning, match=r'3 norm layers of type SyncBN '
                      r'are BN \(model\.backbone\.norm_cfg, model\.'
                      r'backbone\.backbone_cfg\.norm_cfg, model\.decode_'
                      r'head\[0\]\.norm_cfg\)'):
        fit_to_cpus(cfg)
    assert cfg.model.backbone.norm_cfg == dict(type='BN', requires_grad=True)
    assert cfg.model.backbone.backbone_cfg.norm_cfg.type == 'BN'
    assert [h.norm_cfg.type for h in cfg.model.decode_head] == ['BN', 'GN']
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        fit_to_cpus(cfg)  # nothing left: no second warning


def test_num_workers_zero_turns_persistent_workers_off(tmp_path):
    cfg = Config.fromfile(osp.join(ROOT, 'configs', 'pspnet_raw.py'))
    cfg.train_dataloader.num_workers = 0
    fit_workers(cfg)
    assert cfg.train_dataloader.persistent_workers is False
    assert cfg.val_dataloader.persistent_workers is True  # 2 workers
    # through the configs' runner, as tools/train.py and MMSeg's build it
    cfg = Config.fromfile(osp.join(ROOT, 'configs', 'pspnet_raw.py'))
    cfg.merge_from_dict({'train_dataloader.num_workers': 0,
                         'val_dataloader.num_workers': 0})
    cfg.work_dir = str(tmp_path)
    runner = RUNNERS.build(cfg)
    assert runner._train_dataloader['persistent_workers'] is False
    assert runner._val_dataloader['persistent_workers'] is False
