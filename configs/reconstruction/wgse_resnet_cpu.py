# CPU-sized WGSE reconstruction (the shipped weights,
# wgse_mmseg/weights/wgse_reconstruction_cpu.pth): the paper's model with the
# residual blocks narrowed from 256 to 64 channels (0.30 M parameters
# instead of 3.8 M), trained on small simulated crops with a short schedule.
_base_ = ['./wgse_resnet.py']
crop_size = (48, 48)
model = dict(channels=64)
train_dataloader = dict(batch_size=4, num_workers=1,
                        dataset=dict(crop_size=crop_size))
val_dataloader = dict(dataset=dict(num_samples=8, crop_size=(64, 64)))
max_iters = 500
warmup_iters = 50
val_interval = 100
optim_wrapper = dict(optimizer=dict(lr=1e-3))
param_scheduler = [
    dict(type='LinearLR', start_factor=1e-2, by_epoch=False, begin=0,
         end=warmup_iters),
    dict(type='CosineAnnealingLR', by_epoch=False, begin=warmup_iters,
         end=max_iters, eta_min=1e-5),
]
train_cfg = dict(max_iters=max_iters, val_interval=val_interval)
default_hooks = dict(logger=dict(interval=10),
                     checkpoint=dict(interval=val_interval))
