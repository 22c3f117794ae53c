"""Train a segmentor on spike streams (MMSeg's tools/train.py, for spikes).

    python tools/train.py configs/pspnet_wgse.py [--work-dir DIR] [--resume]
        [--cfg-options num_steps=41 data_root=DIR crop_size=128,256 ...]

``mim train wgse_mmseg configs/pspnet_wgse.py`` runs this script. A second
training into a work dir that a training is writing is refused, naming it
(``--wait`` waits for it instead).
"""
import argparse
import os.path as osp
import sys

from wgse_mmseg.command_line import Path
from wgse_mmseg.fileio.input_guard import OutputFolderError
from wgse_mmseg.fileio.locks import add_wait_option
from wgse_mmseg.utils.config import (add_runner_arguments, build_runner,
                                     config_from_args)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description='Train a segmentor')
    parser.add_argument('config', type=Path(), help='train config file path')
    parser.add_argument(
        '--resume', action='store_true', default=False,
        help='resume from the latest checkpoint in the work_dir')
    parser.add_argument('--amp', action='store_true', default=False,
                        help='enable automatic-mixed-precision training')
    add_runner_arguments(parser)
    add_wait_option(parser)
    return parser


def _amp_device_missing() -> bool:
    """Whether mmengine's ``AmpOptimWrapper`` (``--amp``) has no device here:
    it trains on CUDA, NPU, MLU or MUSA only."""
    from mmengine.device import (is_cuda_available, is_mlu_available,
                                 is_musa_available, is_npu_available)
    return not (is_cuda_available() or is_npu_available() or
                is_mlu_available() or is_musa_available())


def main():
    args = build_parser().parse_args()
    # torch and OpenMMLab once the arguments are read (--help answers at once)
    from wgse_mmseg.core.spike_formats import SpikeFileError
    from wgse_mmseg.utils.checkpoint import CheckpointError
    from wgse_mmseg.utils.cross_checks import ModelFitError
    if args.amp and _amp_device_missing():
        sys.exit(f'{osp.basename(__file__)}: error: --amp: mixed-precision '
                 f'training needs a GPU (CUDA; or an NPU, MLU or MUSA '
                 f'device), and torch sees none here; train without --amp')
    try:
        cfg = config_from_args(args)
        if args.amp:
            cfg.optim_wrapper.type = 'AmpOptimWrapper'
            cfg.optim_wrapper.loss_scale = 'dynamic'
        cfg.resume = args.resume
        if args.wait:  # for SpikeRunner.train
            cfg.wait_for_work_dir = True
        runner = build_runner(cfg)
    except (ValueError, OSError) as err:  # the config, the model, the files
        sys.exit(f'{osp.basename(__file__)}: error: {err}')
    try:
        runner.train()
    except (ModelFitError, OutputFolderError) as err:
        # a setting and what works; the work dir's other writer
        sys.exit(f'{osp.basename(__file__)}: error: {err}')
    except (FileNotFoundError, SpikeFileError, CheckpointError) as err:
        # data and checkpoint files: the message names the file
        sys.exit(f'{osp.basename(__file__)}: error: {type(err).__name__}: '
                 f'{err}')


if __name__ == '__main__':
    main()
