# Worked example: WGSE in front of a third MMSeg model, by config alone.
#
# DeepLabV3+ with a ResNet-18 (V1c) backbone on Spike-Cityscapes, trained from
# scratch with the paper's recipe (T=129, crop 256x512, flips, batch 4, AdamW
# lr 1e-3 / wd 0.01, 10-epoch warm-up, OHEM cross-entropy).
#
# Any MMSeg segmentor takes spike streams once three things are in place:
#   1. custom_imports naming wgse_mmseg.mmseg_layer -- comes with the dataset
#      base config below; it sets up the MMSeg layer and registers the spike
#      loader/transforms, SpikeCityscapesDataset, SpikeSegDataPreProcessor
#      and WGSE.
#   2. model.data_preprocessor = SpikeSegDataPreProcessor (replacing the RGB
#      SegDataPreProcessor, hence `_delete_=True`): it batches the (T, H, W)
#      binary streams without mean/std, pads them, and runs the WGSE enhancer,
#      whose (B, T, H, W) output is what the backbone sees.
#   3. model.backbone.in_channels = num_steps: the backbone's stem takes T
#      channels instead of 3 (WGSE maps T frames back to exactly T channels).
# Everything else is the stock MMSeg model config.
#
#   python tools/train.py configs/examples/deeplabv3plus_r18_wgse.py \
#       --cfg-options num_steps=41 data_root=DIR crop_size=128,256
_base_ = [
    'mmseg::_base_/models/deeplabv3plus_r50-d8.py',
    # (1) custom_imports, num_steps, crop_size, data_root, pipelines:
    '../_base_/datasets/spike_cityscapes.py',
    '../_base_/models/wgse.py',
    '../_base_/default_runtime.py',
    '../_base_/schedules/adamw_warmup_100e.py',
]
# SyncBN on multi-GPU runs: sync_bn
norm_cfg = dict(type='BN', requires_grad=True)
ohem = dict(type='OHEMPixelSampler', thresh=0.7, min_kept=100000)
model = dict(
    pretrained=None,  # no RGB ImageNet weights: the stem takes T channels
    # (2) batch and enhance spike streams instead of normalising RGB images:
    data_preprocessor=dict(
        _delete_=True, **_base_.spike_data_preprocessor, enhancer=_base_.wgse),
    # (3) the backbone takes the T enhanced spike channels:
    backbone=dict(
        depth=18,
        in_channels={{_base_.num_steps}},
        norm_cfg=norm_cfg),
    # ResNet-18 stages give 64, 128, 256, 512 channels (BasicBlock, no x4
    # expansion as in ResNet-50's 256..2048), so the heads shrink with it.
    decode_head=dict(
        in_channels=512,
        channels=128,
        c1_in_channels=64,
        c1_channels=48,
        norm_cfg=norm_cfg,
        sampler=ohem),
    auxiliary_head=dict(in_channels=256, channels=64, norm_cfg=norm_cfg))
optim_wrapper = dict(optimizer=dict(lr=1e-3, weight_decay=0.01))
