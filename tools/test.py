"""Evaluate a checkpoint on spike streams (MMSeg's tools/test.py, for spikes).

    python tools/test.py CONFIG CHECKPOINT [--work-dir DIR] [--out DIR]
        [--cfg-options num_steps=41 data_root=DIR ...]

Prints mIoU, mAcc and aAcc (MMSeg's IoUMetric).
"""
import argparse

from mmengine.registry import RUNNERS
from mmengine.runner import Runner

from wgse_mmseg.utils.config import add_runner_arguments, config_from_args


def parse_args():
    parser = argparse.ArgumentParser(description='Test a segmentor')
    parser.add_argument('config', help='test config file path')
    parser.add_argument('checkpoint', help='checkpoint file')
    parser.add_argument('--out', help='directory to save the predicted masks')
    add_runner_arguments(parser)
    return parser.parse_args()


def main():
    args = parse_args()
    cfg = config_from_args(args)
    if args.out is not None:
        cfg.test_evaluator['output_dir'] = args.out
        cfg.test_evaluator['keep_results'] = True
    # as MMSeg's tools: the config's runner_type (SpikeRunner) where it has one
    runner = RUNNERS.build(cfg) if 'runner_type' in cfg else \
        Runner.from_cfg(cfg)
    # Strict: a checkpoint made for another T (or model) must not be scored
    # with some layers left at random initialisation.
    runner.load_checkpoint(args.checkpoint, strict=True)
    runner.test()


if __name__ == '__main__':
    main()
