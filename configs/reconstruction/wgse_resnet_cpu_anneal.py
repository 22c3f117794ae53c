# Second phase of the CPU-sized run that made the shipped weights: from the
# first phase's weights at iteration 200 (wgse_resnet_cpu.py, stopped there
# for the wall-clock budget, learning rate still 7.6e-4), 150 iterations of
# cosine decay from 4e-4 to 1e-5. See docs/reconstruction.md, "Results".
_base_ = ['./wgse_resnet_cpu.py']
load_from = 'work_dirs/reconstruction_wgse_resnet_cpu/iter_200.pth'
max_iters = 150
val_interval = 50
optim_wrapper = dict(optimizer=dict(lr=4e-4))
param_scheduler = [
    dict(type='CosineAnnealingLR', by_epoch=False, begin=0, end=max_iters,
         eta_min=1e-5),
]
train_cfg = dict(max_iters=max_iters, val_interval=val_interval)
default_hooks = dict(checkpoint=dict(interval=val_interval))
