"""Convert a Cityscapes root into Spike-Cityscapes (spike streams + train ids).

    python tools/dataset_converters/spike_cityscapes.py data/cityscapes \\
        data/spike_cityscapes --nproc 2

Resumable: rerun the same command after an interruption. See
docs/spike_cityscapes.md and wgse_mmseg/datasets/cityscapes_conversion.py.
"""
import argparse
import time

import wgse_mmseg
wgse_mmseg.register_all_modules()  # the MMSeg layer's set-up, before its import
from wgse_mmseg.core.arguments import Integer  # noqa: E402
from wgse_mmseg.core.limits import MAX_SAMPLES, MAX_WORKERS  # noqa: E402
from wgse_mmseg.datasets.cityscapes_conversion import (ConversionSettings,
                                                       convert_cityscapes,
                                                       load_scene)


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('cityscapes_root',
                        help='holds leftImg8bit/, gtFine/ and optionally '
                        'leftImg8bit_sequence/')
    parser.add_argument('out_dir', help='Spike-Cityscapes root to write')
    parser.add_argument('--splits', nargs='+', default=['train', 'val'])
    parser.add_argument('--height', type=int, default=512)
    parser.add_argument('--width', type=int, default=1024)
    parser.add_argument('--num-steps', type=int, default=129,
                        help='T, spike readout steps per sample')
    parser.add_argument('--threshold', type=float, default=1 / 0.6,
                        help='firing threshold (default: REDS convention '
                        '1/0.6, white fires 0.6 spikes per step)')
    parser.add_argument('--frames-around', type=int, default=1,
                        help='K: the sequence frames frame-K..frame+K span '
                        'the stream (2K/17 s of scene time); 0 always uses '
                        'the static model')
    parser.add_argument('--scene', default=None,
                        help='extra simulator effects: a JSON/YAML file or '
                        'inline JSON, e.g. \'{"shot_noise": {}}\'')
    parser.add_argument('--seed', type=int, default=0,
                        help='base seed; each sample also hashes its name')
    parser.add_argument('--nproc', type=Integer(1, MAX_WORKERS), default=1,
                        help='worker processes')
    parser.add_argument('--limit', type=Integer(1, MAX_SAMPLES), default=None,
                        help='at most N samples per split (for trials)')
    return parser.parse_args()


def main():
    args = parse_args()
    start = time.perf_counter()
    try:
        settings = ConversionSettings(
            height=args.height, width=args.width, num_steps=args.num_steps,
            threshold=args.threshold, frames_around=args.frames_around,
            scene=load_scene(args.scene), seed=args.seed)
        counts = convert_cityscapes(args.cityscapes_root, args.out_dir,
                                    settings, args.splits, args.nproc,
                                    args.limit)
    except (OSError, ValueError) as err:  # each names the file or option
        raise SystemExit(f'error: {err}') from err
    print(f'{args.out_dir}: {counts["sequence"]} samples from sequences, '
          f'{counts["static"]} from the static model, {counts["skipped"]} '
          f'already done, in {time.perf_counter() - start:.1f} s')


if __name__ == '__main__':
    main()
