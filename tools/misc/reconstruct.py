"""Reconstruct grey images from a spike stream and write them as PNGs, or
walk a recording into a video.

    python tools/misc/reconstruct.py SPIKE_FILE --out DIR
        [--method wgse|tfp|tfi] [--checkpoint CKPT] [--height H --width W]
        [--layout THW|HWT] [--frames 150,...] [--num-steps 41]
        [--exposure auto|none|GAIN] [--device cpu]
    python tools/misc/reconstruct.py SPIKE_FILE --out VIDEO.mp4|.gif
        --stride N [--batch-size 8] [--fps 10] [--save-frames] [...]

``SPIKE_FILE`` is any stream :func:`wgse_mmseg.fileio.load_spikes` reads
(``.dat``, ``.spk``, ``.npy``, ``.npz``; a ``.dat`` needs
``--height``/``--width`` or a ``<file>.json`` side file). For each requested
centre frame (default: the middle frame) the window of ``--num-steps`` frames
centred on it goes through the method, and ``DIR/<stem>_<frame>.png`` (8-bit
grey, upright) is written; each path is printed with the exposure gain applied,
the image's no-reference scores (NIQE and BRISQUE, lower is better; 2-D entropy
in bits; ``n/a`` where the image is too small or flat for one:
:mod:`wgse_mmseg.evaluation.quality`) and why that gain. ``--exposure auto``
(default) leaves an image of normal brightness as the method made it (a
calibrated stream is never made worse) and brightens only a clearly
under-exposed one, whose 99.5th percentile is below a quarter of white, so
that percentile becomes white: a dark recording gives a visible image
(:func:`wgse_mmseg.core.exposure.auto_exposure`); ``none`` keeps the
method's intensities; a number is a fixed gain.

An ``.npy``/``.npz`` that does not record its layout needs ``--layout THW``
(stored ``(T, H, W)``) or ``HWT`` (stored ``(H, W, T)``); it is never guessed
(:func:`wgse_mmseg.fileio.load_spikes`).

``--method wgse`` (default) runs the trained model of ``--checkpoint``: an
mmengine checkpoint of a ``configs/reconstruction`` config or a file of
``export_weights``; without one, the weights shipped in
``wgse_mmseg/weights``. The model's window length is its own ``num_steps``.
``tfp``/``tfi`` are the classical baselines on the REDS intensity scale.

``--stride N`` walks the recording (:mod:`wgse_mmseg.apis.recording_walk`):
the window centred on every ``N``-th readout (``0, N, 2N, ...``; those whose
window does not fit at the ends are skipped and said so) is reconstructed,
``--batch-size`` windows a model call, exposed as above (each window on its
own), and becomes a frame of the video ``--out`` (``.mp4`` or ``.gif``),
with ``<out stem>.csv`` (window, centre readout, start, end, batch,
time_ms) and, with ``--save-frames``, ``<out stem>_frames/*.png``. A
progress bar goes to stderr. An interrupted walk re-run with the same
arguments continues (its state is in ``<out>.partial/``; a damaged frame
there is made again); with other arguments it is refused, naming the
differences. A second walk into the same video while one runs stops at once
naming the first (process, host, command, start), or with ``--wait`` waits
for it.
"""
import argparse
import os.path as osp
import sys

from wgse_mmseg.command_line import (EXPOSURE, LAYOUT, LAYOUT_HELP, NUM_STEPS,
                                     Choice, Integer, Path, SequenceOf, Text,
                                     add_frame_size_options,
                                     check_frame_size)
from wgse_mmseg.core.constants import RECONSTRUCTION_METHODS as METHODS
from wgse_mmseg.core.exposure import apply_exposure
from wgse_mmseg.fileio.output_folder import check_tool_outputs
from wgse_mmseg.fileio.input_guard import keeps_inputs
from wgse_mmseg.fileio.locks import own_folder
from wgse_mmseg.apis.recording_walk import add_walk_options

# torch, OpenCV and the MMSeg layer are imported where they are used, after
# the arguments are read: --help and argument errors come at once.


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description='Reconstruct images from a spike stream')
    parser.add_argument('spikes', type=Path(),
                        help='spike file (.dat, .spk, .npy, .npz)')
    parser.add_argument('--out', type=Path(), required=True,
                        help='output directory (new, empty, or one it '
                        'made); with --stride the video, '
                        '.mp4 or .gif')
    parser.add_argument('--method', type=Choice(METHODS), default='wgse',
                        help=f'reconstruction method, of {list(METHODS)} '
                        '(default: wgse)')
    parser.add_argument(
        '--checkpoint', type=Path(),
        help='model checkpoint for --method wgse (default: shipped weights)')
    add_frame_size_options(parser)
    parser.add_argument(
        '--layout', type=LAYOUT,
        help=LAYOUT_HELP)
    parser.add_argument(
        '--frames', type=SequenceOf(Integer()),
        help='comma-separated centre frames (default: the middle frame)')
    parser.add_argument(
        '--num-steps', type=NUM_STEPS, default=41,
        help='window length for tfp/tfi (wgse uses its model\'s; default 41)')
    parser.add_argument(
        '--exposure', type=EXPOSURE, default='auto',
        help='auto (default: brightens only a clearly under-exposed image, '
        'its 99.5th percentile to white), none, or a gain')
    parser.add_argument('--device', type=Text(empty=False), default='cpu',
                        help='torch device')
    add_walk_options(parser)
    return parser


def parse_args(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    check_frame_size(parser, args)
    if args.checkpoint and args.method != 'wgse':
        parser.error('--checkpoint is for --method wgse')
    if args.stride is not None and args.frames:
        parser.error('--frames and --stride: name centre frames, or walk '
                     'every STRIDE-th one')
    if args.stride is None:  # a folder of PNGs the package owns
        check_tool_outputs(args, folders=['out'])
    else:  # a video, with its CSV and folders beside it
        check_tool_outputs(args, 'out')
    return args


def walk(args) -> None:
    """``--stride``: reconstruct a window every ``args.stride`` readouts into
    the video ``args.out``
    (:func:`~wgse_mmseg.apis.recording_walk.walk_recording`)."""
    import torch

    from wgse_mmseg.fileio.images import to_uint8
    from wgse_mmseg.apis.recording_walk import walk_recording
    from wgse_mmseg.apis.walk_plan import walk_outputs
    from wgse_mmseg.models.reconstruction import (load_reconstructor,
                                                  reconstruction_method)
    walk_outputs(args.out, args.save_frames, [args.spikes])  # before loading
    if args.method == 'wgse':
        model = load_reconstructor(args.checkpoint, args.device)
        reconstruct, length = model.reconstruct_windows, model.num_steps
    else:
        method = reconstruction_method(args.method)
        length = args.num_steps

        def reconstruct(spikes):
            return [method(window.numpy()) for window in spikes]

    def render(window, image):
        image = torch.as_tensor(image).cpu().numpy()
        return to_uint8(apply_exposure(image, args.exposure).image)

    settings = dict(method=args.method, checkpoint=args.checkpoint and
                    osp.abspath(args.checkpoint), exposure=args.exposure)
    report = walk_recording(
        args.spikes, args.out, reconstruct, render, length, args.stride,
        args.batch_size, args.fps, settings, args.save_frames, args.height,
        args.width, args.layout, wait=args.wait)
    print(report.summary('reconstructed', args.save_frames))


@keeps_inputs
def main(argv=None):
    args = parse_args(argv)
    import wgse_mmseg
    wgse_mmseg.register_all_modules()  # the MMSeg layer, before its import
    from wgse_mmseg.core.spike_formats import SpikeFileError, centered_window
    from wgse_mmseg.fileio.images import to_uint8, write_png
    from wgse_mmseg.fileio.spike_files import load_spikes, spike_shape
    from wgse_mmseg.evaluation.quality import no_reference_scores
    from wgse_mmseg.models.reconstruction import (load_reconstructor,
                                                  reconstruction_method)
    if args.stride is not None:
        try:
            return walk(args)
        except (ValueError, FileNotFoundError) as err:
            sys.exit(f'{osp.basename(__file__)}: error: {err}')
    try:
        total, _, _ = spike_shape(args.spikes, args.height, args.width,
                                  layout=args.layout)
        length = args.num_steps
        if args.method == 'wgse':
            model = load_reconstructor(args.checkpoint, args.device)
            method, length = model.reconstruct, model.num_steps
        else:
            method = reconstruction_method(args.method)
        frames = args.frames if args.frames else [total // 2]
        starts = [centered_window(args.spikes, total, f, length)
                  for f in frames]
    except (SpikeFileError, ValueError, FileNotFoundError) as err:
        sys.exit(f'{osp.basename(__file__)}: error: {err}')
    stem = osp.splitext(osp.basename(args.spikes))[0]
    with own_folder(args.out):
        for frame, start in zip(frames, starts):
            window = load_spikes(args.spikes, args.height, args.width, start,
                                 length, args.layout)
            exposed = apply_exposure(method(window), args.exposure)
            image = to_uint8(exposed.image)
            path = osp.join(args.out, f'{stem}_{frame}.png')
            try:
                write_png(path, image)
            except OSError as err:
                sys.exit(f'{osp.basename(__file__)}: error: --out {args.out}: '
                         f'cannot write {path}: {err}')
            scores = '\t'.join(
                f'{name.lower()}='
                + ('n/a' if value is None else f'{value:.3f}')
                for name, value in no_reference_scores(image).items())
            print(f'{path}\texposure_gain={exposed.gain:.3g}\t{scores}\t'
                  f'exposure: {exposed.reason}')


if __name__ == '__main__':
    main()
