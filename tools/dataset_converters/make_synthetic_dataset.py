"""Make the embedded Spike-Cityscapes-format dataset (procedural street
scenes).

    python tools/dataset_converters/make_synthetic_dataset.py \\
        data/synthetic_spike_cityscapes

Resumable: a sample whose marker matches the settings and its files is kept;
any other is made again. See wgse_mmseg/data_generation/synthetic.py.
"""
import argparse
import os.path as osp
import sys

from wgse_mmseg.command_line import (NUM_STEPS, SEED, SIDE, Integer, Number,
                                     Path)
from wgse_mmseg.limits import MAX_SAMPLES
from wgse_mmseg.fileio.locks import add_wait_option
from wgse_mmseg.fileio.output_folder import check_tool_outputs
from wgse_mmseg.fileio.input_guard import keeps_inputs
from wgse_mmseg.data_generation.synthetic import make_synthetic_dataset


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('out_dir', type=Path(), help='dataset root to write')
    count = Integer(0, MAX_SAMPLES)
    parser.add_argument('--num-train', type=count, default=48)
    parser.add_argument('--num-val', type=count, default=12)
    parser.add_argument('--height', type=SIDE, default=128)
    parser.add_argument('--width', type=SIDE, default=256)
    parser.add_argument('--num-steps', type=NUM_STEPS, default=41,
                        help='T, spike frames per sample')
    parser.add_argument('--threshold', type=Number(0, strict_minimum=True),
                        default=1 / 0.6)
    parser.add_argument('--seed', type=SEED, default=0)
    add_wait_option(parser)
    return parser


@keeps_inputs
def main():
    args = build_parser().parse_args()
    check_tool_outputs(args, folders=['out_dir'])
    try:
        written = make_synthetic_dataset(
            args.out_dir, args.num_train, args.num_val, args.height,
            args.width, args.num_steps, threshold=args.threshold,
            seed=args.seed, wait=args.wait)
    except (ValueError, OSError) as err:
        sys.exit(f'{osp.basename(__file__)}: error: {err}')
    print(f'{written} samples written to {args.out_dir} '
          f'({args.num_train} train, {args.num_val} val in all)')


if __name__ == '__main__':
    main()
