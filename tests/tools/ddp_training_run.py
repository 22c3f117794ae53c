"""A short, deterministic training run that saves the WGSE enhancer's
parameters of every process (driver of ``test_distributed_training.py``;
not a test itself).

    python ddp_training_run.py CONFIG OUT [--launcher pytorch]
        [--cfg-options ...]

The run goes through :func:`wgse_mmseg.utils.config.config_from_args`, as
``tools/train.py`` does, with what makes one process with batch ``2B``
compute what ``N`` processes with batch ``B`` compute: no shuffling, no
flips, no dropout, GroupNorm in the head (BN statistics depend on the
split), plain cross-entropy (no OHEM) and SGD. Each process writes
``OUT/rank<r>.pt``: the enhancer's parameters before and after training.
"""
import argparse
import os.path as osp

import torch
import torch.distributed as dist
from mmengine.runner import Runner

from wgse_mmseg.utils.config import add_runner_arguments, config_from_args


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('config')
    parser.add_argument('out')
    add_runner_arguments(parser)
    args = parser.parse_args()
    cfg = config_from_args(args)
    cfg.randomness = dict(seed=0)
    cfg.train_dataloader.sampler.shuffle = False
    for step in cfg.train_dataloader.dataset.pipeline:
        if step.type == 'SpikeRandomFlip':
            step.prob = 0.0
    cfg.model.backbone.drop_path_rate = 0.0
    cfg.model.decode_head.update(dropout_ratio=0.0, sampler=None,
                                 norm_cfg=dict(type='GN', num_groups=8))
    cfg.optim_wrapper = dict(type='OptimWrapper',
                             optimizer=dict(type='SGD', lr=0.05))
    cfg.param_scheduler = []
    runner = Runner.from_cfg(cfg)
    model = getattr(runner.model, 'module', runner.model)
    enhancer = model.data_preprocessor.enhancer
    before = {k: v.detach().clone() for k, v in enhancer.state_dict().items()}
    runner.train()
    after = enhancer.state_dict()
    rank = dist.get_rank() if dist.is_initialized() else 0
    torch.save(dict(before=before, after=after,
                    wrapper=type(runner.model).__name__,
                    world_size=dist.get_world_size()
                    if dist.is_initialized() else 1),
               osp.join(args.out, f'rank{rank}.pt'))


if __name__ == '__main__':
    main()
