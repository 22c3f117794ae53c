"""Evaluate a checkpoint on spike streams (MMSeg's tools/test.py, for spikes).

    python tools/test.py CONFIG CHECKPOINT [--work-dir DIR] [--out DIR]
        [--cfg-options num_steps=41 data_root=DIR ...]

Prints mIoU, mAcc and aAcc (MMSeg's IoUMetric).
"""
import argparse
import os.path as osp
import sys

from wgse_mmseg.core.arguments import Path
from wgse_mmseg.core.output_folder import check_tool_outputs, keeps_inputs
from wgse_mmseg.utils.config import (add_runner_arguments, build_runner,
                                     config_from_args)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description='Test a segmentor')
    parser.add_argument('config', type=Path(), help='test config file path')
    parser.add_argument('checkpoint', type=Path(), help='checkpoint file')
    parser.add_argument('--out', type=Path(),
                        help='directory to save the predicted masks')
    add_runner_arguments(parser)
    return parser


@keeps_inputs
def main():
    args = build_parser().parse_args()
    check_tool_outputs(args, 'out')
    # torch and OpenMMLab once the arguments are read (--help answers at once)
    from wgse_mmseg.core.io import SpikeFileError
    from wgse_mmseg.utils.checkpoint import read_checkpoint
    try:
        cfg = config_from_args(args)
        if args.out is not None:
            cfg.test_evaluator['output_dir'] = args.out
            cfg.test_evaluator['keep_results'] = True
        runner = build_runner(cfg)
        # Strict: a checkpoint made for another T (or model) must not be
        # scored with some layers left at random initialisation.
        try:
            runner.load_checkpoint(args.checkpoint, strict=True)
        except Exception:
            # a file that is no checkpoint is named (weights-only read);
            # else the loader's own error stands
            read_checkpoint(args.checkpoint)
            raise
    except (ValueError, OSError, RuntimeError) as err:
        sys.exit(f'{osp.basename(__file__)}: error: {err}')
    try:
        runner.test()
    except (FileNotFoundError, SpikeFileError) as err:
        # data files: the message names the file
        sys.exit(f'{osp.basename(__file__)}: error: {type(err).__name__}: '
                 f'{err}')


if __name__ == '__main__':
    main()
