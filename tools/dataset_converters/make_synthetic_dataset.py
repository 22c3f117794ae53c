"""Make the embedded Spike-Cityscapes-format dataset (procedural street scenes).

    python tools/dataset_converters/make_synthetic_dataset.py data/synthetic_spike_cityscapes

Resumable: a sample whose marker matches the settings and its files is kept;
any other is made again. See wgse_mmseg/datasets/synthetic.py.
"""
import argparse
import os.path as osp
import sys

import wgse_mmseg
wgse_mmseg.register_all_modules()  # the MMSeg layer's set-up, before its import
from wgse_mmseg.datasets.synthetic import make_synthetic_dataset  # noqa: E402


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('out_dir', help='dataset root to write')
    parser.add_argument('--num-train', type=int, default=48)
    parser.add_argument('--num-val', type=int, default=12)
    parser.add_argument('--height', type=int, default=128)
    parser.add_argument('--width', type=int, default=256)
    parser.add_argument('--num-steps', type=int, default=41,
                        help='T, spike frames per sample')
    parser.add_argument('--threshold', type=float, default=1 / 0.6)
    parser.add_argument('--seed', type=int, default=0)
    return parser.parse_args()


def main():
    args = parse_args()
    try:
        written = make_synthetic_dataset(
            args.out_dir, args.num_train, args.num_val, args.height,
            args.width, args.num_steps, threshold=args.threshold,
            seed=args.seed)
    except (ValueError, OSError) as err:
        sys.exit(f'{osp.basename(__file__)}: error: {err}')
    print(f'{written} samples written to {args.out_dir} '
          f'({args.num_train} train, {args.num_val} val in all)')


if __name__ == '__main__':
    main()
