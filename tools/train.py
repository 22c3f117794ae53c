"""Train a segmentor on spike streams (MMSeg's tools/train.py, for spikes).

    python tools/train.py configs/pspnet_wgse.py [--work-dir DIR] [--resume]
        [--cfg-options num_steps=41 data_root=DIR crop_size=128,256 ...]

``mim train wgse_mmseg configs/pspnet_wgse.py`` runs this script.
"""
import argparse

from mmengine.registry import RUNNERS
from mmengine.runner import Runner

from wgse_mmseg.utils.config import add_runner_arguments, config_from_args


def parse_args():
    parser = argparse.ArgumentParser(description='Train a segmentor')
    parser.add_argument('config', help='train config file path')
    parser.add_argument(
        '--resume', action='store_true', default=False,
        help='resume from the latest checkpoint in the work_dir')
    parser.add_argument('--amp', action='store_true', default=False,
                        help='enable automatic-mixed-precision training')
    add_runner_arguments(parser)
    return parser.parse_args()


def main():
    args = parse_args()
    cfg = config_from_args(args)
    if args.amp:
        cfg.optim_wrapper.type = 'AmpOptimWrapper'
        cfg.optim_wrapper.loss_scale = 'dynamic'
    cfg.resume = args.resume
    # as MMSeg's tools: the config's runner_type (SpikeRunner) where it has one
    runner = RUNNERS.build(cfg) if 'runner_type' in cfg else \
        Runner.from_cfg(cfg)
    runner.train()


if __name__ == '__main__':
    main()
