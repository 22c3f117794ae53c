# Training on spikes simulated from still images (no REDS needed): each
# sample moves a view of an image along a random smooth trajectory over
# num_steps steps and simulates spikes on the REDS scale (white fires 0.6
# spikes per step); the ground truth is the centre frame. Images: matplotlib's
# sample images by default, or any folder with
#   --cfg-options train_dataloader.dataset.image_dir=DIR
# Validation: 16 held-out simulated samples (another seed).
_base_ = ['./reds_test.py']

train_pipeline = [
    dict(type='SpikeRandomFlip', prob=0.5,
         direction=('horizontal', 'vertical')),
    dict(type='PackReconstructionInputs'),
]
train_dataloader = dict(
    batch_size=8,
    num_workers=2,
    persistent_workers=True,
    sampler=dict(type='InfiniteSampler', shuffle=True),
    dataset=dict(type='SimulatedSpikeImageDataset', image_dir=None,
                 num_samples=1000000, crop_size={{_base_.crop_size}},
                 num_steps={{_base_.num_steps}}, seed=0,
                 pipeline=train_pipeline))
val_dataloader = dict(
    batch_size=1,
    num_workers=0,
    sampler=dict(type='DefaultSampler', shuffle=False),
    dataset=dict(type='SimulatedSpikeImageDataset', image_dir=None,
                 num_samples=16, crop_size=(96, 96),
                 num_steps={{_base_.num_steps}}, seed=1,
                 pipeline=[dict(type='PackReconstructionInputs')]))
val_evaluator = dict(type='ReconstructionMetric')
