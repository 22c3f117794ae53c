# Spike-Cityscapes: Cityscapes scenes as spike streams (docs/user_guide.md,
# "Spike-Cityscapes layout").
#
# The spike settings are set here, once:
#   num_steps  T, spike frames per sample (the paper: 129)
#   data_root  the dataset root
#   crop_size  training crop (H, W) (the paper: 256 x 512)
# Override them with
# `--cfg-options num_steps=41 data_root=DIR crop_size=128,256`
# (any tool: the configs' runner, SpikeRunner) or by setting them alone in a
# child config: they reach every field that carries them (the list:
# wgse_mmseg/utils/spike_settings.py), so the loader, the preprocessor and the
# backbone's in_channels always agree.
# Sets up and registers the MMSeg layer of wgse_mmseg (its import is the
# explicit opt-in to the compatibility patches, wgse_mmseg/mmseg_layer.py).
custom_imports = dict(imports=['wgse_mmseg.mmseg_layer'],
                      allow_failed_imports=False)

dataset_type = 'SpikeCityscapesDataset'
num_classes = 19  # Cityscapes train ids 0-18; 255 is ignored
data_root = 'data/spike_cityscapes'
num_steps = 129
crop_size = (256, 512)

train_pipeline = [
    dict(type='LoadSpikeFromFile', num_steps=num_steps),
    dict(type='LoadAnnotations'),
    dict(type='SpikeRandomCrop', crop_size=crop_size, cat_max_ratio=0.75),
    dict(type='SpikeRandomFlip', prob=0.5,
         direction=('horizontal', 'vertical')),
    dict(type='PackSegInputs'),
]
test_pipeline = [
    dict(type='LoadSpikeFromFile', num_steps=num_steps),
    dict(type='LoadAnnotations'),
    dict(type='PackSegInputs'),
]
# Test-time augmentation (tools/test.py --tta): the stream as it is and
# flipped left-right, the two predictions' class probabilities averaged
# (tta_model: MMSeg's SegTTAModel, in MMSeg's default runtime; the flipped
# prediction is flipped back first).
tta_pipeline = [
    dict(type='LoadSpikeFromFile', num_steps=num_steps),
    dict(type='TestTimeAug', transforms=[
        [dict(type='SpikeRandomFlip', prob=0.0),
         dict(type='SpikeRandomFlip', prob=(1.0, 0.0))],
        [dict(type='LoadAnnotations')],
        [dict(type='PackSegInputs')]]),
]
train_dataloader = dict(
    batch_size=4,
    num_workers=2,
    persistent_workers=True,
    sampler=dict(type='DefaultSampler', shuffle=True),
    dataset=dict(
        type=dataset_type,
        data_root=data_root,
        data_prefix=dict(img_path='spike/train', seg_map_path='gtFine/train'),
        pipeline=train_pipeline))
val_dataloader = dict(
    batch_size=1,
    num_workers=2,
    persistent_workers=True,
    sampler=dict(type='DefaultSampler', shuffle=False),
    dataset=dict(
        type=dataset_type,
        data_root=data_root,
        data_prefix=dict(img_path='spike/val', seg_map_path='gtFine/val'),
        pipeline=test_pipeline))
test_dataloader = val_dataloader
val_evaluator = dict(type='IoUMetric', iou_metrics=['mIoU'])
test_evaluator = val_evaluator

# What replaces MMSeg's RGB SegDataPreProcessor in a model on this data:
#   model = dict(data_preprocessor=dict(
#       _delete_=True, **_base_.spike_data_preprocessor, enhancer=...))
# It batches the (T, H, W) streams without mean/std, pads crops (labels with
# 255) and checks T and the label range at the first batch.
spike_data_preprocessor = dict(
    type='SpikeSegDataPreProcessor',
    num_steps=num_steps,
    num_classes=num_classes,
    size=crop_size,
    pad_val=0,
    seg_pad_val=255)
