"""Evaluate a checkpoint on spike streams (MMSeg's tools/test.py, for spikes).

    python tools/test.py CONFIG CHECKPOINT [--work-dir DIR] [--out DIR]
        [--show-dir DIR] [--show] [--wait-time S] [--tta]
        [--cfg-options num_steps=41 data_root=DIR ...]

Prints mIoU, mAcc and aAcc (MMSeg's IoUMetric). As MMSeg's: ``--show-dir``
saves every window's clip (a TFP image) under its prediction, ``--show``
shows them, ``--tta`` tests with the config's test-time augmentation
(``tta_model``, ``tta_pipeline``: the dataset base's flips).
"""
import argparse
import os.path as osp
import sys

from wgse_mmseg.command_line import Number, Path
from wgse_mmseg.fileio.output_folder import check_tool_outputs
from wgse_mmseg.fileio.input_guard import keeps_inputs
from wgse_mmseg.utils.config import (add_runner_arguments, build_runner,
                                     config_from_args)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description='Test a segmentor')
    parser.add_argument('config', type=Path(), help='test config file path')
    parser.add_argument('checkpoint', type=Path(), help='checkpoint file')
    parser.add_argument('--out', type=Path(),
                        help='directory to save the predicted masks')
    parser.add_argument('--show-dir', type=Path(),
                        help='directory to save the drawn results in')
    parser.add_argument('--show', action='store_true',
                        help='show the drawn results in a window')
    parser.add_argument('--wait-time', type=Number(0, 3600), default=2,
                        help='seconds each shown result stays')
    parser.add_argument('--tta', action='store_true',
                        help='test-time augmentation (the config\'s '
                        'tta_model and tta_pipeline)')
    add_runner_arguments(parser)
    return parser


def apply_test_options(cfg, args) -> None:
    """``--show``, ``--show-dir`` and ``--tta`` as MMSeg's tools/test.py
    applies them: the visualisation hook draws every test sample, to the
    visualiser's ``save_dir`` and on screen; the test loader runs
    ``tta_pipeline`` into ``tta_model`` around the model."""
    if args.show or args.show_dir:
        hook = cfg.default_hooks.get('visualization')
        if hook is None:
            raise ValueError('--show/--show-dir need a visualization hook '
                             'in default_hooks (the shipped configs\' '
                             'SpikeVisualizationHook)')
        hook['draw'] = True
        hook['show'] = args.show
        hook['wait_time'] = args.wait_time
        if args.show_dir:
            cfg.visualizer['save_dir'] = args.show_dir
    if args.tta:
        if 'tta_model' not in cfg or 'tta_pipeline' not in cfg:
            raise ValueError(f'--tta: {args.config} has no tta_model and '
                             f'tta_pipeline (the spike dataset base has '
                             f'both)')
        cfg.test_dataloader.dataset.pipeline = cfg.tta_pipeline
        cfg.tta_model.module = cfg.model
        # mmengine's TTA wrapper gives its own data preprocessor (else the
        # runner's default: MMSeg's RGB one) to the model it builds
        cfg.tta_model.data_preprocessor = cfg.model.data_preprocessor
        cfg.model = cfg.tta_model


@keeps_inputs
def main():
    args = build_parser().parse_args()
    check_tool_outputs(args, 'out', 'show_dir')
    # torch and OpenMMLab once the arguments are read (--help answers at once)
    from wgse_mmseg.core.spike_formats import SpikeFileError
    from wgse_mmseg.utils.checkpoint import read_checkpoint
    try:
        cfg = config_from_args(args)
        if args.out is not None:
            cfg.test_evaluator['output_dir'] = args.out
            cfg.test_evaluator['keep_results'] = True
        apply_test_options(cfg, args)
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
