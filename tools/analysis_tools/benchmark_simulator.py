"""Throughput of the spike simulator, and load time of spike files.

Prints two tables:

1. Simulator throughput in pixel-steps per second (``H * W * T`` per
   second) for the base model and for each effect alone, each against a
   plain NumPy step-loop integrate-and-fire on the same input in the same
   run (``vs NumPy loop``: its time over the row's time). Inputs are a
   procedural street scene (:func:`wgse_mmseg.data_generation.synthetic.
   render_street_scene`): ``still`` is its middle frame, ``video`` its
   ``--frames`` frames spread over the stream. Where the compiled CPU
   kernel is built, the base model also runs on the torch path (as without
   it, and as on a GPU); both must give the same spikes.
2. Time to load one ``--load-shape`` sample (default 129x512x1024) from
   each format with :func:`wgse_mmseg.fileio.load_spikes` (files
   just written, so from the page cache: decoding, not the disk), against
   simulating it.

Each time is the median of ``--repeat`` runs after one warm-up run. The
default size runs in about a minute on two cores; the full-size run is::

    python tools/analysis_tools/benchmark_simulator.py --height 512 \\
        --width 1024 --repeat 5

``--threads`` sets torch's intra-op threads (default 1, the NumPy loop's
count, so the ratio compares algorithms, not core counts).
"""
import argparse

from wgse_mmseg.command_line import NUM_STEPS, SIDE, Integer, SequenceOf, Text
from wgse_mmseg.limits import MAX_NUM_STEPS, MAX_REPEAT, MAX_WORKERS


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--height', type=SIDE, default=256)
    parser.add_argument('--width', type=SIDE, default=512)
    parser.add_argument('--steps', type=NUM_STEPS, default=129)
    parser.add_argument('--frames', type=Integer(2, MAX_NUM_STEPS),
                        default=3, help='video frames over the stream')
    parser.add_argument('--repeat', type=Integer(1, MAX_REPEAT), default=5)
    parser.add_argument('--device', type=Text(empty=False), default='cpu')
    parser.add_argument('--threads', type=Integer(0, MAX_WORKERS), default=1,
                        help='torch intra-op threads (0: torch default)')
    parser.add_argument('--load-shape', default=(129, 512, 1024),
                        type=SequenceOf(SIDE, names=('T', 'H', 'W')),
                        help='T,H,W of the load-time sample')
    parser.add_argument('--skip-load', action='store_true')
    return parser


def main():
    args = build_parser().parse_args()
    # torch and the simulator once the arguments are read (--help at once)
    import numpy as np
    import torch

    from wgse_bench.simulator import header, load_rows, simulator_rows
    from wgse_mmseg.data_generation.synthetic import render_street_scene
    if args.threads:
        torch.set_num_threads(args.threads)
    frames, _ = render_street_scene(np.random.default_rng(0), args.height,
                                    args.width, args.frames)
    still = frames[args.frames // 2:args.frames // 2 + 1]
    lines = header(args) + [''] + simulator_rows(args, still, frames)
    if not args.skip_load:
        lines += [''] + load_rows(args, still)
    print('\n'.join(lines))


if __name__ == '__main__':
    main()
