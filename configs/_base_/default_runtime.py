# MMSeg's runtime, logging by epoch to match the epoch-based schedule.
_base_ = ['mmseg::_base_/default_runtime.py']
log_processor = dict(by_epoch=True)
# Multi-GPU runs (tools/dist_train.sh) turn every BN into SyncBN, as MMSeg's
# SyncBN configs do; single-process runs keep BN (mmengine converts only when
# distributed), and so do CPU runs with gloo. sync_bn=None keeps per-GPU BN.
sync_bn = 'torch'
# mmengine's Runner that first gives num_steps, data_root and crop_size to the
# fields that carry them, so a config that inherits this one can set
# `num_steps = 41` alone (and MMSeg's tools take `--cfg-options num_steps=41`).
runner_type = 'SpikeRunner'
