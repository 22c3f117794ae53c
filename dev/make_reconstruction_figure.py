"""A figure like the paper's Fig. 9: reconstructions of a stream over time.

    python dev/make_reconstruction_figure.py SPIKE_FILE --out FIG.png
        [--methods wgse] [--frames 60,100,... | --count 5]
        [--checkpoint CKPT] [--height H --width W] [--layout THW|HWT]
        [--scale 1.0]

One column per centre frame (``--frames``, or ``--count`` frames spread
evenly over the stream), one row per method (``wgse``, ``tfp``, ``tfi``; the
paper's figure is the ``wgse`` row), each tile labelled with its frame and
method. ``--scale`` resizes the tiles. Written as an 8-bit grey PNG. An
``.npy``/``.npz`` that does not record its layout needs ``--layout THW`` or
``HWT``.
"""
import argparse
import os.path as osp
import sys

import numpy as np

from wgse_mmseg.command_line import (LAYOUT, LAYOUT_HELP, Choice, Integer,
                                     Number, Path, SequenceOf, Text,
                                     add_frame_size_options,
                                     check_frame_size)
from wgse_mmseg.core.constants import RECONSTRUCTION_METHODS as METHODS
from wgse_mmseg.limits import MAX_FIGURE_TILES, MAX_TILE_SCALE
from wgse_mmseg.fileio.input_guard import keeps_inputs
from wgse_mmseg.fileio.output_folder import check_tool_outputs

# OpenCV, torch and the MMSeg layer are imported where they are used, after
# the arguments are read: --help and argument errors come at once.
_GAP = 4


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description='Reconstructions of a spike stream over time, as a grid')
    parser.add_argument('spikes', type=Path(),
                        help='spike file (.dat, .spk, .npy, .npz)')
    parser.add_argument('--out', type=Path(), required=True,
                        help='output PNG')
    parser.add_argument('--methods', default=('wgse',),
                        type=SequenceOf(Choice(METHODS),
                                        max_length=len(METHODS)),
                        help=f'comma-separated rows, of {list(METHODS)}')
    parser.add_argument('--frames',
                        type=SequenceOf(Integer(),
                                        max_length=MAX_FIGURE_TILES),
                        help='comma-separated centre frames')
    parser.add_argument('--count', type=Integer(1, MAX_FIGURE_TILES),
                        default=5,
                        help='columns spread over the stream (no --frames)')
    parser.add_argument('--checkpoint', type=Path(),
                        help='wgse model (default: shipped)')
    add_frame_size_options(parser)
    parser.add_argument(
        '--layout', type=LAYOUT,
        help=LAYOUT_HELP)
    parser.add_argument('--scale', default=1.0,
                        type=Number(0, MAX_TILE_SCALE, strict_minimum=True),
                        help='tile scale factor')
    parser.add_argument('--device', type=Text(empty=False), default='cpu')
    return parser


def parse_args(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    check_frame_size(parser, args)
    check_tool_outputs(args, 'out')
    return args


def labelled(tile: np.ndarray, text: str) -> np.ndarray:
    """``tile`` (8-bit grey) with ``text`` on a dark band above it."""
    import cv2
    band = np.zeros((22, tile.shape[1]), np.uint8)
    cv2.putText(band, text, (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, 255, 1,
                cv2.LINE_AA)
    return np.vstack([band, tile])


def grid(rows) -> np.ndarray:
    """Tiles ``rows[i][j]`` (equal sizes) joined with white gaps."""
    height, width = rows[0][0].shape
    out = np.full((len(rows) * (height + _GAP) - _GAP,
                   len(rows[0]) * (width + _GAP) - _GAP), 255, np.uint8)
    for i, row in enumerate(rows):
        for j, tile in enumerate(row):
            y, x = i * (height + _GAP), j * (width + _GAP)
            out[y:y + height, x:x + width] = tile
    return out


@keeps_inputs
def main(argv=None):
    args = parse_args(argv)
    import cv2

    import wgse_mmseg
    wgse_mmseg.register_all_modules()  # the MMSeg layer, before its import
    from wgse_mmseg.core.spike_formats import SpikeFileError, centered_window
    from wgse_mmseg.fileio.images import to_uint8, write_png
    from wgse_mmseg.fileio.spike_files import load_spikes, spike_shape
    from wgse_mmseg.models.reconstruction import (load_reconstructor,
                                                  reconstruction_method)
    try:
        total, height, width = spike_shape(args.spikes, args.height,
                                           args.width, layout=args.layout)
        if min(round(height * args.scale), round(width * args.scale)) < 1:
            raise ValueError(
                f'--scale {args.scale}: makes the {height}x{width} frames '
                f'of {args.spikes} tiles of 0 pixels; at least '
                f'{0.5 / min(height, width):.3g} keeps one')
        functions, length = {}, 41
        for method in args.methods:
            if method == 'wgse':
                model = load_reconstructor(args.checkpoint, args.device)
                functions[method], length = model.reconstruct, model.num_steps
            else:
                functions[method] = reconstruction_method(method)
        if args.frames:
            frames = list(args.frames)
        else:
            first, last = length // 2, total - length + length // 2
            frames = np.linspace(first, last, args.count).round().astype(
                int).tolist()
        starts = [centered_window(args.spikes, total, f, length)
                  for f in frames]
    except (SpikeFileError, ValueError, FileNotFoundError) as err:
        sys.exit(f'{osp.basename(__file__)}: error: {err}')
    columns = []
    for frame, start in zip(frames, starts):
        window = load_spikes(args.spikes, args.height, args.width, start,
                             length, args.layout)
        column = []
        for method, function in functions.items():
            tile = to_uint8(function(window))
            if args.scale != 1:
                tile = cv2.resize(tile, None, fx=args.scale, fy=args.scale,
                                  interpolation=cv2.INTER_AREA)
            column.append(labelled(tile, f'{method.upper()}  t={frame}'))
        columns.append(column)
    figure = grid([list(row) for row in zip(*columns)])
    write_png(args.out, figure)
    print(args.out)


if __name__ == '__main__':
    main()
