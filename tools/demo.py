"""Segment one spike stream and save a colour overlay (MMSeg's image demo),
or walk a recording into a video of overlays.

    python tools/demo.py SPIKE_FILE CONFIG CHECKPOINT [--out-file PATH]
        [--device cpu] [--opacity 0.5] [--height H --width W]
        [--layout THW|HWT] [--cfg-options num_steps=41 ...]
        [--backend pytorch|onnxruntime]
        [--stride N [--batch-size 8] [--fps 10] [--save-frames]]

``SPIKE_FILE`` is any stream :func:`wgse_mmseg.fileio.load_spikes` reads
(``.dat``: ``--height``/``--width`` or a side file). The config's test
pipeline takes the ``num_steps`` frames centred on the middle one, as in
testing (``--cfg-options num_steps=T`` sets the model's ``T``).

The prediction, in the dataset's palette, is blended (``--opacity``) over
the window's spike rate and written as a PNG to ``--out-file`` (default
``<stem>_seg.png`` here); the path is printed.

``--stride N`` walks the recording instead
(:mod:`wgse_mmseg.apis.recording_walk`): the window of ``num_steps``
readouts centred on every ``N``-th readout is segmented as the one-window
demo segments it, and its overlay becomes a frame of the video
``--out-file`` (``.mp4`` or ``.gif``; default ``<stem>_seg.mp4``), with
``<out stem>.csv`` beside it; an interrupted walk re-run with the same
arguments resumes (docs/user_guide.md, "Train and test", has the rest).

``--backend onnxruntime`` runs an exported model: CHECKPOINT is then the
``.onnx`` file (``OnnxSpikeSegmentor`` of ``wgse_mmseg.apis.onnx_segmentor``,
preprocessing and enhancer inside), the config still gives ``num_steps``,
and the palette is Spike-Cityscapes'.
"""
import argparse
import copy
import json
import os.path as osp
import sys

from wgse_mmseg.command_line import (EXPOSURE, LAYOUT, PROBABILITY, Choice,
                                     Path, Text, add_frame_size_options,
                                     check_frame_size)
from wgse_mmseg.fileio.output_folder import check_tool_outputs
from wgse_mmseg.fileio.input_guard import keeps_inputs
from wgse_mmseg.apis.recording_walk import add_walk_options
from wgse_mmseg.utils.config import add_config_options

# The model's modules (torch, OpenCV, OpenMMLab) are imported where they are
# used, after the arguments are read: --help and argument errors come at once.


#: what runs the model: the checkpoint in PyTorch, or an exported model
BACKENDS = ('pytorch', 'onnxruntime')


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description='Segment a spike stream and save a colour overlay')
    parser.add_argument('spikes', type=Path(),
                        help='spike file (.dat, .spk, .npy, .npz)')
    parser.add_argument('config', type=Path(), help='config file')
    parser.add_argument(
        'checkpoint', type=Path(),
        help='checkpoint file (the .onnx file with --backend onnxruntime)')
    parser.add_argument(
        '--out-file', type=Path(),
        help='output PNG (default: <stem>_seg.png); with --stride the '
        'video, .mp4 or .gif (default: <stem>_seg.mp4)')
    parser.add_argument(
        '--device', type=Text(empty=False),
        help='device used for inference (default: cuda:0 if available, '
        'else cpu)')
    parser.add_argument(
        '--opacity', type=PROBABILITY, default=0.5,
        help='opacity of the painted segmentation map, in [0, 1]')
    add_frame_size_options(parser)
    parser.add_argument(
        '--layout', type=LAYOUT,
        help='THW or HWT: how a .npy/.npz that does not record its '
        'layout stores its frames, (T, H, W) or (H, W, T) (default: the '
        'config\'s LoadSpikeFromFile layout, else what the file records; '
        'an error where it records none)')
    add_config_options(parser)
    parser.add_argument(
        '--exposure', type=EXPOSURE, default='auto',
        help='exposure of the grey clip under the overlay: auto (default: '
        'brightens only a clearly under-exposed clip, its 99.5th percentile '
        'to white), none, or a gain')
    parser.add_argument(
        '--backend', type=Choice(BACKENDS), default='pytorch',
        help='pytorch (default: CHECKPOINT is a checkpoint) or onnxruntime '
        '(CHECKPOINT is an exported .onnx model)')
    add_walk_options(parser)
    return parser


def parse_args(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    check_frame_size(parser, args)
    if args.out_file is None:
        stem = osp.splitext(osp.basename(args.spikes))[0]
        args.out_file = f'{stem}_seg.' + (
            'png' if args.stride is None else 'mp4')
    check_tool_outputs(args, 'out_file')
    return args


def build_pipeline(cfg, height=None, width=None, layout=None):
    """The config's test pipeline without label loading.

    ``height``/``width`` (for ``.dat``) and ``layout`` (for ``.npy``/``.npz``
    files that do not record it), where given, are given to
    ``LoadSpikeFromFile``. Returns mmengine's ``Compose`` of it.
    """
    from mmengine.dataset import Compose
    pipeline = cfg.get('test_pipeline') or cfg.test_dataloader.dataset.pipeline
    transforms = []
    for transform in copy.deepcopy(pipeline):
        if transform['type'] == 'LoadAnnotations':
            continue
        if transform['type'] == 'LoadSpikeFromFile' and height is not None:
            transform.update(height=height, width=width)
        if transform['type'] == 'LoadSpikeFromFile' and layout is not None:
            transform.update(layout=layout)
        transforms.append(transform)
    if not any(t['type'] == 'LoadSpikeFromFile' for t in transforms):
        raise ValueError('the config\'s test pipeline has no '
                         'LoadSpikeFromFile; is it a spike config?')
    return Compose(transforms)


def load_model(cfg, checkpoint: str, device: str):
    """The segmentor of ``cfg`` with the weights of ``checkpoint``, strictly
    (:func:`~wgse_mmseg.apis.segmentor_checkpoint.load_segmentor`), its
    ``dataset_meta`` (classes, palette) set, in eval mode on ``device``."""
    from wgse_mmseg.apis.segmentor_checkpoint import load_segmentor
    model, model.dataset_meta = load_segmentor(cfg, checkpoint)
    model.cfg = cfg
    return model.to(device).eval()


def clip_image(spikes, exposure):
    """``(T, H, W)`` spikes (a tensor) -> the ``(H, W)`` uint8 TFP image
    (an array) of the whole clip (spike rate / 0.6) with ``exposure``
    applied, and what it did (``core.exposure.Exposed``)."""
    from wgse_mmseg.core.exposure import apply_exposure
    from wgse_mmseg.fileio.images import to_uint8
    from wgse_mmseg.core.reconstruction_baselines import tfp
    exposed = apply_exposure(tfp(spikes.cpu().numpy()), exposure)
    return to_uint8(exposed.image), exposed


def overlay(grey, labels, palette, opacity: float):
    """Blend the palette colours of ``labels`` over ``grey`` (NumPy arrays);
    RGB uint8."""
    import cv2
    import numpy as np
    palette = np.asarray(palette, dtype=np.uint8)
    if labels.max() >= len(palette):  # more classes than named colours
        extra = np.random.default_rng(42).integers(
            0, 256, (int(labels.max()) + 1 - len(palette), 3), np.uint8)
        palette = np.concatenate([palette, extra])
    if grey.shape != labels.shape:  # a test pipeline that resizes
        grey = cv2.resize(grey, labels.shape[::-1],
                          interpolation=cv2.INTER_LINEAR)
    colour = palette[labels].astype(np.float32)
    blended = (1 - opacity) * grey[..., None].astype(np.float32) + \
        opacity * colour
    return np.round(blended).astype(np.uint8)


def onnx_segmentor(path: str, device: str):
    """The exported model ``path`` in ONNX Runtime (imported only when
    asked): a function ``(B, T, H, W)`` float spikes -> ``(B, H, W)``
    labels, the palette the file records (Spike-Cityscapes' where it
    records none) and the ``(T, H, W)`` it was exported for."""
    from wgse_mmseg.apis.onnx_segmentor import OnnxSpikeSegmentor
    from wgse_mmseg.datasets import SpikeCityscapesDataset
    model = OnnxSpikeSegmentor(path, device=device)
    meta = getattr(model, 'dataset_meta', None) or {}
    palette = meta.get('palette', SpikeCityscapesDataset.METAINFO['palette'])

    def segment(spikes):
        logits = model(spikes)
        if logits.shape[1] > len(palette):
            raise ValueError(
                f'{path}: gives {logits.shape[1]} classes and records no '
                f'palette; the default (Spike-Cityscapes) has '
                f'{len(palette)} colours')
        return logits.argmax(1)
    return segment, palette, model.input_shape


def walk(args, cfg) -> None:
    """``--stride``: segment a window every ``args.stride`` readouts into
    the video ``args.out_file``
    (:func:`~wgse_mmseg.apis.recording_walk.walk_recording`)."""
    import torch

    from wgse_mmseg.apis.window_segmentor import (PipelineSegmentor,
                                                  pipeline_loader)
    from wgse_mmseg.fileio.spike_files import spike_shape
    from wgse_mmseg.apis.recording_walk import walk_recording
    from wgse_mmseg.apis.walk_plan import plan_recording_walk, walk_outputs
    walk_outputs(args.out_file, args.save_frames, [args.spikes])  # first
    pipeline = build_pipeline(cfg, args.height, args.width, args.layout)
    length = pipeline_loader(pipeline).num_steps
    if length is None:
        raise ValueError(f'{args.config}: a walk needs the window length: '
                         f'num_steps of LoadSpikeFromFile in the test '
                         f'pipeline (--cfg-options num_steps=T)')
    plan_recording_walk(args.spikes, length, args.stride, args.height,
                        args.width, pipeline_loader(pipeline).layout)
    if args.backend == 'pytorch':
        model = load_model(cfg, args.checkpoint, args.device)
        segment = PipelineSegmentor(model, pipeline, args.spikes)
        palette = model.dataset_meta['palette']
    else:
        segment, palette, (steps, height, width) = onnx_segmentor(
            args.checkpoint, args.device)
        frame = spike_shape(args.spikes, args.height, args.width,
                            pipeline_loader(pipeline).layout)[1:]
        if steps != length:
            raise ValueError(
                f'{args.checkpoint}: exported for windows of T={steps} but '
                f'the config\'s is num_steps={length}; add --cfg-options '
                f'num_steps={steps}')
        if (height, width) != tuple(frame):
            raise ValueError(
                f'{args.checkpoint}: exported for {height}x{width} frames '
                f'but {args.spikes} has {frame[0]}x{frame[1]}; export again '
                f'with --shape {steps} {frame[0]} {frame[1]}')

    def render(window, labels):
        grey, _ = clip_image(torch.from_numpy(window), args.exposure)
        return overlay(grey, labels.cpu().numpy(), palette, args.opacity)

    settings = dict(config=osp.abspath(args.config),
                    checkpoint=osp.abspath(args.checkpoint),
                    backend=args.backend, cfg_options=json.dumps(
                        args.cfg_options or {}, sort_keys=True, default=str),
                    opacity=args.opacity, exposure=args.exposure)
    report = walk_recording(
        args.spikes, args.out_file, segment, render, length, args.stride,
        args.batch_size, args.fps, settings, args.save_frames, args.height,
        args.width, pipeline_loader(pipeline).layout, wait=args.wait)
    print(report.summary('segmented', args.save_frames))


@keeps_inputs
def main(argv=None):
    args = parse_args(argv)
    import wgse_mmseg
    wgse_mmseg.register_all_modules()  # before mmseg is imported
    import torch
    from mmengine.registry import init_default_scope

    from wgse_mmseg.fileio.images import write_png
    from wgse_mmseg.utils.config import load_config
    from wgse_mmseg.utils.cross_checks import check_input_fits
    if args.device is None:
        args.device = 'cuda:0' if torch.cuda.is_available() else 'cpu'
    cfg = load_config(args.config, args.cfg_options)
    init_default_scope(cfg.get('default_scope', 'mmseg'))
    if args.stride is not None:
        try:
            return walk(args, cfg)
        except (ValueError, FileNotFoundError) as err:
            sys.exit(f'{osp.basename(__file__)}: error: {err}')
    try:
        # The stream is read first, so a file that does not fit fails fast.
        data = build_pipeline(cfg, args.height, args.width, args.layout)(
            dict(img_path=args.spikes))
        if args.backend == 'pytorch':
            model = load_model(cfg, args.checkpoint, args.device)
            check_input_fits(model, *data['inputs'].shape, args.spikes)
        else:
            segment, palette, _ = onnx_segmentor(args.checkpoint,
                                                 args.device)
    except (ValueError, FileNotFoundError) as err:
        sys.exit(f'{osp.basename(__file__)}: error: {err}')

    if args.backend == 'pytorch':
        batch = dict(inputs=[data['inputs']],
                     data_samples=[data['data_samples']])
        with torch.no_grad():
            result = model.test_step(batch)[0]
        labels = result.pred_sem_seg.data[0].cpu().numpy()
        palette = model.dataset_meta['palette']
    else:
        labels = segment(data['inputs'][None].float())[0].cpu().numpy()
    grey, exposed = clip_image(data['inputs'], args.exposure)
    image = overlay(grey, labels, palette, args.opacity)
    write_png(args.out_file, image[..., ::-1])  # RGB -> OpenCV's BGR
    print(f'{args.out_file}\texposure_gain={exposed.gain:.3g}\t'
          f'exposure: {exposed.reason}')


if __name__ == '__main__':
    main()
