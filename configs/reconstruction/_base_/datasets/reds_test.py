# Evaluation on a REDS-layout folder (docs/reconstruction.md):
#   data_root/spike/<name>.dat (250x400 frames) beside data_root/gt/<name>.png
# Each sample is the num_steps-frame window centred on the ground truth's
# frame (the middle frame of the stream). Settings overridable with
# `--cfg-options num_steps=41 data_root=DIR crop_size=H,W` or in a child
# config (wgse_mmseg/utils/spike_settings.py lists the fields they reach);
# crop_size is the training crop of the configs that train.
# Sets up and registers the MMSeg layer of wgse_mmseg (its import is the
# explicit opt-in to the compatibility patches, wgse_mmseg/mmseg_layer.py).
custom_imports = dict(imports=['wgse_mmseg.mmseg_layer'],
                      allow_failed_imports=False)

num_steps = 41
data_root = 'data/reds'
crop_size = (128, 128)

test_pipeline = [
    dict(type='LoadSpikeImagePair', num_steps=num_steps),
    dict(type='PackReconstructionInputs'),
]
test_dataloader = dict(
    batch_size=1,
    num_workers=0,
    sampler=dict(type='DefaultSampler', shuffle=False),
    dataset=dict(type='REDSSpikeDataset', data_root=data_root,
                 data_prefix=dict(spike_path='spike', gt_path='gt'),
                 pipeline=test_pipeline))
test_evaluator = dict(type='ReconstructionMetric')
