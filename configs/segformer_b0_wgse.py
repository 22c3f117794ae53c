# SegFormer-B0 (MiT-B0) on Spike-Cityscapes with WGSE in front (the paper's
# setting: T=129, crop 256x512, flips, batch 4, AdamW lr 2e-4 / wd 0.002,
# 10-epoch warm-up, OHEM cross-entropy). No pretrained weights.
_base_ = [
    'mmseg::_base_/models/segformer_mit-b0.py',
    './_base_/datasets/spike_cityscapes.py',
    './_base_/models/wgse.py',
    './_base_/default_runtime.py',
    './_base_/schedules/adamw_warmup_100e.py',
]
# SyncBN on multi-GPU runs: sync_bn
norm_cfg = dict(type='BN', requires_grad=True)
model = dict(
    data_preprocessor=dict(
        _delete_=True, **_base_.spike_data_preprocessor, enhancer=_base_.wgse),
    backbone=dict(in_channels={{_base_.num_steps}}),
    decode_head=dict(
        norm_cfg=norm_cfg,
        sampler=dict(type='OHEMPixelSampler', thresh=0.7, min_kept=100000)))
optim_wrapper = dict(optimizer=dict(lr=2e-4, weight_decay=0.002))
