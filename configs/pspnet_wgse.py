# PSPNet-R50-D8 on Spike-Cityscapes with WGSE in front (the paper's setting:
# T=129, crop 256x512, flips, batch 4, AdamW lr 1e-3 / wd 0.01, 10-epoch
# warm-up, OHEM cross-entropy). No pretrained weights.
# WGSE starts at the low-pass approximation of the stream (init='lowpass'),
# not at random: in front of PSPNet that is the recipe that put WGSE at or
# above TFP where the losses had flattened (docs/wgse_vs_tfp.md); the
# paper's random start trailed TFP by 8 mIoU there.
_base_ = [
    'mmseg::_base_/models/pspnet_r50-d8.py',
    './_base_/datasets/spike_cityscapes.py',
    './_base_/models/wgse.py',
    './_base_/default_runtime.py',
    './_base_/schedules/adamw_warmup_100e.py',
]
# SyncBN on multi-GPU runs: sync_bn
norm_cfg = dict(type='BN', requires_grad=True)
ohem = dict(type='OHEMPixelSampler', thresh=0.7, min_kept=100000)
model = dict(
    pretrained=None,
    data_preprocessor=dict(
        _delete_=True, **_base_.spike_data_preprocessor,
        enhancer=dict(**_base_.wgse, init='lowpass')),
    backbone=dict(in_channels={{_base_.num_steps}}, norm_cfg=norm_cfg),
    decode_head=dict(norm_cfg=norm_cfg, sampler=ohem),
    auxiliary_head=dict(norm_cfg=norm_cfg, sampler=ohem))
optim_wrapper = dict(optimizer=dict(lr=1e-3, weight_decay=0.01))
