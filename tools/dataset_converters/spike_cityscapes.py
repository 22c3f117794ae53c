"""Convert a Cityscapes root into Spike-Cityscapes (spike streams + train ids).

    python tools/dataset_converters/spike_cityscapes.py data/cityscapes \\
        data/spike_cityscapes --nproc 2

Resumable: rerun the same command after an interruption. Shardable: N
processes (machines sharing OUT_DIR, a Slurm array: tools/slurm_convert.sh),
the K-th given --shard K/N and otherwise the same arguments, together write
what one run writes. See docs/spike_cityscapes.md and
wgse_mmseg/data_generation/cityscapes_conversion.py.
"""
import argparse
import time

from wgse_mmseg.command_line import (NUM_STEPS, SEED, SIDE, Choice, Integer,
                                     Number, Path, Text)
from wgse_mmseg.data_generation.cityscapes_conversion import (
    ConversionSettings, convert_cityscapes, load_scene)
from wgse_mmseg.data_generation.cityscapes_layout import (ANNOTATED_INDEX,
                                                          CITYSCAPES_SPLITS,
                                                          SNIPPET_LENGTH)
from wgse_mmseg.data_generation.shards import SHARD, WHOLE
from wgse_mmseg.fileio.input_guard import keeps_inputs
from wgse_mmseg.fileio.locks import add_wait_option
from wgse_mmseg.fileio.output_folder import check_tool_outputs
from wgse_mmseg.limits import MAX_SAMPLES, MAX_WORKERS


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('cityscapes_root', type=Path(),
                        help='holds leftImg8bit/, gtFine/ and optionally '
                        'leftImg8bit_sequence/')
    parser.add_argument('out_dir', type=Path(),
                        help='Spike-Cityscapes root to write')
    parser.add_argument('--splits', nargs='+', default=['train', 'val'],
                        type=Choice(CITYSCAPES_SPLITS))
    parser.add_argument('--height', type=SIDE, default=512)
    parser.add_argument('--width', type=SIDE, default=1024)
    parser.add_argument('--num-steps', type=NUM_STEPS,
                        default=129,
                        help='T, spike readout steps per sample')
    parser.add_argument('--threshold', type=Number(0, strict_minimum=True),
                        default=1 / 0.6,
                        help='firing threshold (default: REDS convention '
                        '1/0.6, white fires 0.6 spikes per step)')
    parser.add_argument('--frames-around',
                        type=Integer(0, SNIPPET_LENGTH - 1 - ANNOTATED_INDEX),
                        default=1,
                        help='K: the sequence frames frame-K..frame+K span '
                        'the stream (2K/17 s of scene time); 0 always uses '
                        'the static model')
    parser.add_argument('--scene', type=Text(empty=False), default=None,
                        help='extra simulator effects: a JSON/YAML file or '
                        'inline JSON, e.g. \'{"shot_noise": {}}\'')
    parser.add_argument('--seed', type=SEED, default=0,
                        help='base seed; each sample also hashes its name')
    parser.add_argument('--nproc', type=Integer(1, MAX_WORKERS), default=1,
                        help='worker processes')
    parser.add_argument('--limit', type=Integer(1, MAX_SAMPLES), default=None,
                        help='at most N samples per split (for trials)')
    parser.add_argument('--shard', type=SHARD, default=WHOLE, metavar='K/N',
                        help='convert only the K-th of N disjoint parts '
                        '(every N-th sample, sorted by name); the N parts '
                        'of one job, same other arguments, make the whole')
    add_wait_option(parser)
    return parser


@keeps_inputs
def main():
    args = build_parser().parse_args()
    check_tool_outputs(args, folders=['out_dir'])
    start = time.perf_counter()
    try:
        settings = ConversionSettings(
            height=args.height, width=args.width, num_steps=args.num_steps,
            threshold=args.threshold, frames_around=args.frames_around,
            scene=load_scene(args.scene), seed=args.seed)
        counts = convert_cityscapes(args.cityscapes_root, args.out_dir,
                                    settings, args.splits, args.nproc,
                                    args.limit, shard=args.shard,
                                    wait=args.wait)
    except (OSError, ValueError) as err:  # each names the file or option
        raise SystemExit(f'error: {err}') from err
    part = '' if args.shard == WHOLE else f' (shard {args.shard})'
    print(f'{args.out_dir}{part}: {counts["sequence"]} samples from '
          f'sequences, {counts["static"]} from the static model, '
          f'{counts["skipped"]} already done, in '
          f'{time.perf_counter() - start:.1f} s')


if __name__ == '__main__':
    main()
