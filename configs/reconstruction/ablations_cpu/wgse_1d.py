# Table 5 of the paper at an equal CPU budget: each model of this folder is
# trained from scratch with the same data (wgse_resnet_cpu_finetune.py's
# mixture of moving photographs, video frames and REDS training crops), the
# same 64-channel residual network and the same 300 iterations, batch 4, so
# they differ only in the enhancer. This one: WGSE-1d (db8, 5 levels).
#   python tools/train.py configs/reconstruction/ablations_cpu/wgse_1d.py \
#       --cfg-options \
#       train_dataloader.dataset.datasets.1.dataset.data_root=REDS_TRAIN
# docs/reconstruction.md ("Ablations") has the results and the commands.
_base_ = ['../wgse_resnet_cpu_finetune.py']
load_from = None
max_iters = 300
warmup_iters = 30
optim_wrapper = dict(optimizer=dict(lr=1e-3))
param_scheduler = [
    dict(type='LinearLR', start_factor=1e-2, by_epoch=False, begin=0,
         end=warmup_iters),
    dict(type='CosineAnnealingLR', by_epoch=False, begin=warmup_iters,
         end=max_iters, eta_min=1e-5),
]
train_cfg = dict(max_iters=max_iters, val_interval=max_iters)
default_hooks = dict(checkpoint=dict(interval=max_iters))
