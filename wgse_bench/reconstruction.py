"""Score reconstruction methods on a REDS-layout folder or a real recording.

    python -m wgse_bench.reconstruction DATA_ROOT
        [--methods wgse,tfp,tfi] [--checkpoint CKPT] [--models CKPT,...]
        [--num-steps 41] [--spike-suffix .dat] [--layout THW|HWT]
        [--repeat 3]
    python -m wgse_bench.reconstruction RECORDING
        [--frames 100,...] [--exposure auto|none|GAIN]
        [--height H --width W] [--layout THW|HWT] [--methods ...]
        [--checkpoint CKPT]

``DATA_ROOT`` holds ``spike/<name>.dat`` beside ``gt/<name>.png``
(:class:`~wgse_mmseg.datasets.reds.REDSSpikeDataset`; ``--spike-suffix``
for ``.spk``/``.npy``/``.npz`` streams, ``--layout`` for arrays that do not
record their layout). Every method sees the
same ``num_steps``-frame windows centred on the ground truth's frame and is
scored by :class:`ReconstructionMetric` (PSNR, SSIM, 2-D entropy); so is
each trained model of ``--models`` (named by its file's stem). Beside each
method's PSNR margin over TFP the table gives its cost on the first sample's
frame size: parameters, multiply-adds (torch's ``FlopCounterMode`` FLOPs / 2,
the convention of Spike-Zoo's GFLOPs; a model's enhancer counted on its
``reference`` backend, which computes what every backend computes) and the
median wall time of ``--repeat`` reconstructions of one frame on this
machine, which a line above the table names.

``RECORDING`` is a spike file without ground truth (``.dat``, ``.spk``,
``.npy``, ``.npz``, e.g. the UHSR recordings' ``.npz``): each method
reconstructs the window centred on each ``--frames`` frame (default: the
middle one) and the image, as ``tools/misc/reconstruct.py`` writes it (its
``--exposure``, by default ``auto``: a dark recording's image brightened so
that its 99.5th percentile is white, each method's own gain), is scored by
the no-reference measures (:mod:`wgse_mmseg.evaluation.quality`: NIQE and
BRISQUE, lower is better; 2-D entropy, higher means more detail); prints a
Markdown table of the means over the frames, naming the machine.
"""
import argparse
import os.path as osp
import sys
from typing import Dict, List, Optional, Sequence

import numpy as np
from torch.utils.flop_counter import FlopCounterMode
from tqdm import tqdm

from wgse_mmseg import register_all_modules

# a command line (``python -m``): its own explicit set-up of the MMSeg layer,
# as the tools make it, before the layer's packages are imported
register_all_modules()
from wgse_mmseg.argument_checks import (ArgumentError, check_integer,
                                        check_path, check_read_options,
                                        check_text, is_choice, is_integer)
from wgse_mmseg.command_line import (EXPOSURE, LAYOUT, LAYOUT_HELP, NUM_STEPS,
                                     Choice, Integer, Path, SequenceOf, Text,
                                     add_frame_size_options, check_frame_size)
from wgse_mmseg.core.exposure import apply_exposure
from wgse_mmseg.limits import MAX_NUM_STEPS
from wgse_mmseg.core.spike_formats import SpikeFileError, centered_window
from wgse_mmseg.fileio.spike_files import load_spikes, spike_shape
from wgse_mmseg.fileio.images import to_uint8
from wgse_mmseg.evaluation.quality import (NO_REFERENCE_METRICS,
                                           no_reference_scores)
from wgse_mmseg.datasets.reds import (LoadSpikeImagePair,
                                      PackReconstructionInputs,
                                      REDSSpikeDataset)
from wgse_mmseg.models.reconstruction import (METHODS, SpikeReconstructor,
                                              load_reconstructor,
                                              reconstruction_method)
from wgse_mmseg.evaluation.metrics import ReconstructionMetric

from .machine import machine_record
from .markdown import markdown_table
from .timing import summarize, time_calls

__all__ = ['benchmark', 'score_recording']


def _method(method: str, checkpoint: Optional[str], device: str):
    """``(function, model)`` of a method: the function maps ``(T, H, W)``
    spikes to an ``(H, W)`` image; the model (whose ``num_steps`` is the
    window length) is ``wgse``'s, ``None`` for a classical method (any
    length)."""
    if method == 'wgse':
        model = load_reconstructor(checkpoint, device)
        return model.reconstruct, model
    return reconstruction_method(method), None


#: the crops' sides on which :func:`multiply_adds` counts a frame's
#: products per pixel
COUNT_CROPS = (8, 16)


def multiply_adds(model: SpikeReconstructor, spikes: np.ndarray) -> int:
    """Multiply-adds of ``model.reconstruct(spikes)`` for one ``(T, H, W)``
    window: torch's ``FlopCounterMode`` FLOPs / 2, with a WGSE enhancer on
    its ``reference`` backend (its band networks' own ``nn.Conv1d``, which
    the counter sees; the ``torch`` backend's fused kernels and the compiled
    and Triton ones compute the same products out of its sight).

    A fully convolutional model does the same products at every pixel, so
    the count is made on two top-left crops (:data:`COUNT_CROPS` on a side)
    and scaled to ``H * W`` when both give the same count per pixel; any
    other model (or a frame no larger than the crops) is counted whole."""
    height, width = spikes.shape[-2:]
    crops = [spikes[..., :min(side, height), :min(side, width)]
             for side in COUNT_CROPS]
    if crops[-1].shape == spikes.shape:  # no larger than the crops
        return _counted_multiply_adds(model, spikes)
    small, large = (_counted_multiply_adds(model, crop) for crop in crops)
    small_pixels, large_pixels = (crop.shape[-2] * crop.shape[-1]
                                  for crop in crops)
    if small * large_pixels != large * small_pixels:
        return _counted_multiply_adds(model, spikes)
    return small * height * width // small_pixels


def _counted_multiply_adds(model: SpikeReconstructor,
                           spikes: np.ndarray) -> int:
    """:func:`multiply_adds` counted on the whole of ``spikes``."""
    enhancer = model.enhancer
    backend = getattr(enhancer, 'backend', None)
    if backend is not None:
        enhancer.backend = 'reference'
    try:
        with FlopCounterMode(display=False) as counter:
            model.reconstruct(spikes)
    finally:
        if backend is not None:
            enhancer.backend = backend
    return counter.get_total_flops() // 2


def _cost(function, model: Optional[SpikeReconstructor],
          spikes: np.ndarray, device: str,
          repeat: int) -> Dict[str, Optional[float]]:
    """Parameters, multiply-adds and median milliseconds of one frame."""
    timings = time_calls(lambda: function(spikes), device, repeat, warmup=1)
    return dict(
        params=0 if model is None else sum(
            p.numel() for p in model.parameters()),
        multiply_adds=None if model is None else multiply_adds(model,
                                                               spikes),
        ms_per_frame=summarize(timings.wall)['median'] * 1000)


def benchmark(data_root: str, methods: Sequence[str] = METHODS,
              checkpoint: Optional[str] = None, num_steps: int = 41,
              spike_suffix: str = '.dat', device: str = 'cpu',
              progress: bool = True,
              layout: Optional[str] = None,
              models: Sequence[str] = (),
              repeat: int = 0) -> Dict[str, Dict[str, float]]:
    """``{method: {'PSNR', 'SSIM', 'Entropy2D'}}`` over the folder's samples
    (a progress bar on stderr unless ``progress`` is False).

    ``checkpoint`` is the ``wgse`` model (default: the shipped weights);
    ``models`` are more trained models, each scored under its file's stem;
    every model's ``num_steps`` must equal ``num_steps``. ``layout``: of
    ``.npy``/``.npz`` streams that do not record it
    (``LoadSpikeFromFile``'s). With ``repeat`` > 0 each entry also gets
    ``params``, ``multiply_adds`` (``None`` for the classical methods) and
    ``ms_per_frame`` on the first sample (median of ``repeat`` calls after
    one untimed).
    """
    functions, networks = {}, {}
    sources = dict(wgse=checkpoint or 'shipped weights')
    for method in methods:
        functions[method], networks[method] = _method(method, checkpoint,
                                                      device)
    for path in models:
        name = osp.splitext(osp.basename(path))[0]
        if name in functions:
            raise ValueError(f'{path}: a second entry named {name!r}')
        networks[name] = load_reconstructor(path, device)
        functions[name], sources[name] = networks[name].reconstruct, path
    for name, network in networks.items():
        if network is not None and network.num_steps != num_steps:
            raise ValueError(
                f'{sources[name]}: the model takes {network.num_steps}-frame '
                f'windows, not {num_steps}')
    dataset = REDSSpikeDataset(
        data_root=data_root, spike_suffix=spike_suffix,
        pipeline=[LoadSpikeImagePair(num_steps, layout=layout),
                  PackReconstructionInputs()])
    metrics = {method: ReconstructionMetric() for method in functions}
    for index in tqdm(range(len(dataset)), desc='reconstruction benchmark',
                      disable=not progress):
        data = dataset[index]
        spikes = data['inputs'].numpy()
        gt = data['data_samples'].gt_image
        for method, function in functions.items():
            pred = gt.clone()
            pred.data = pred.data.new_tensor(function(spikes))[None]
            metrics[method].process(None, [dict(pred_image=pred,
                                                gt_image=gt)])
    results = {method: metric.evaluate(len(dataset))
               for method, metric in metrics.items()}
    if repeat > 0:
        spikes = dataset[0]['inputs'].numpy()
        for method, function in functions.items():
            results[method].update(_cost(function, networks[method], spikes,
                                         device, repeat))
    return results


def format_table(results: Dict[str, Dict[str, float]],
                 device: Optional[str] = None) -> str:
    """Markdown table of :func:`benchmark`'s results (margin over TFP; the
    cost columns where measured, under a line naming the machine of
    ``device``)."""
    costs = all('ms_per_frame' in scores for scores in results.values())
    headers = ['method', 'PSNR (dB)', 'SSIM', '2-D entropy (bits)',
               'PSNR - TFP']
    if costs:
        headers += ['parameters', 'GMACs / frame', 'ms / frame']
    reference = results.get('tfp', {}).get('PSNR')
    rows = []
    for method, scores in results.items():
        row = [method.upper(), f'{scores["PSNR"]:.2f}',
               f'{scores["SSIM"]:.4f}',
               f'{scores["Entropy2D"]:.3f}',
               '' if reference is None else
               f'{scores["PSNR"] - reference:+.2f}']
        if costs:
            macs = scores['multiply_adds']
            row += [f'{scores["params"]:,}',
                    '-' if macs is None else f'{macs / 1e9:.1f}',
                    f'{scores["ms_per_frame"]:.0f}']
        rows.append(row)
    table = '\n'.join('| ' + ' | '.join(cells) + ' |' for cells in
                      [headers, ['---'] * len(headers)] + rows)
    if not costs:
        return table
    machine = machine_record(device or 'cpu')
    where = machine.get('gpu') or machine['cpu']
    return (f'{where} ({machine["torch_threads"]} threads, load '
            f'{machine["load_average"]:.1f}), torch {machine["torch"]}, '
            f'wgse_mmseg {machine["wgse_mmseg"]}\n\n' + table)


def score_recording(path: str, methods: Sequence[str] = METHODS,
                    checkpoint: Optional[str] = None, num_steps: int = 41,
                    frames: Optional[Sequence[int]] = None,
                    exposure='auto', height: Optional[int] = None,
                    width: Optional[int] = None, device: str = 'cpu',
                    layout: Optional[str] = None
                    ) -> Dict[str, Dict[str, Optional[float]]]:
    """No-reference scores of each method on a recording without ground
    truth: ``{method: {'NIQE', 'BRISQUE', 'Entropy2D', 'gain'}}``, means
    over the centre ``frames`` (default: the middle frame; ``None`` for a
    measure undefined on any of them, as the package's no-reference
    measures define them).

    Each image is scored as ``tools/misc/reconstruct.py`` writes it: the
    method's output at ``exposure`` (``'auto'``, ``'none'`` or a gain;
    ``gain`` is the mean gain applied), in 8 bits. ``tfp``/``tfi`` use
    ``num_steps``-frame windows, ``wgse`` its model's. ``layout``: as
    :func:`~wgse_mmseg.fileio.load_spikes` takes it.
    """
    entry = 'score_recording'
    check_path(entry, 'path', path)
    if not (isinstance(methods, (list, tuple)) and
            1 <= len(methods) <= len(METHODS) and
            all(is_choice(method, METHODS) for method in methods)):
        raise ArgumentError(entry, 'methods', f'a sequence of 1 to '
                            f'{len(METHODS)} of {list(METHODS)}', methods)
    check_path(entry, 'checkpoint', checkpoint, optional=True)
    check_integer(entry, 'num_steps', num_steps, 1, MAX_NUM_STEPS)
    if frames is not None and not (
            isinstance(frames, (list, tuple)) and frames and
            all(is_integer(frame) for frame in frames)):
        raise ArgumentError(entry, 'frames', 'a non-empty sequence of '
                            'integers (frame indices), or None', frames)
    EXPOSURE.check(exposure, entry, 'exposure')
    check_read_options(entry, height, width, layout)
    check_text(entry, 'device', device, empty=False)
    total, _, _ = spike_shape(path, height, width, layout)
    frames = list(frames) if frames else [total // 2]
    results = {}
    for method in methods:
        function, model = _method(method, checkpoint, device)
        length = num_steps if model is None else model.num_steps
        starts = [centered_window(path, total, f, length) for f in frames]
        scores: Dict[str, List[Optional[float]]] = {
            name: [] for name in list(NO_REFERENCE_METRICS) + ['gain']}
        for start in starts:
            window = load_spikes(path, height, width, start, length, layout)
            exposed = apply_exposure(function(window), exposure)
            scores['gain'].append(exposed.gain)
            for name, value in no_reference_scores(
                    to_uint8(exposed.image)).items():
                scores[name].append(value)
        results[method] = {
            name: None if None in values else float(sum(values) / len(values))
            for name, values in scores.items()}
    return results


def _format_recording_table(results: Dict[str, Dict[str, Optional[float]]],
                            recording: str, frames: Sequence[int],
                            exposure, device: str = 'cpu') -> str:
    """Markdown table of :func:`score_recording`'s results, under a line
    naming the recording, frames, exposure and machine."""
    def cell(value, digits):
        return '-' if value is None else f'{value:.{digits}f}'

    rows = [[method.upper(), cell(s['NIQE'], 3), cell(s['BRISQUE'], 2),
             cell(s['Entropy2D'], 3), cell(s['gain'], 2)]
            for method, s in results.items()]
    machine = machine_record(device)
    where = machine.get('gpu') or machine['cpu']
    return (f'{osp.basename(recording)}, centre frames '
            f'{",".join(map(str, frames))}, exposure {exposure}; {where}, '
            f'torch {machine["torch"]}, wgse_mmseg {machine["wgse_mmseg"]}'
            '\n\n' + markdown_table(
                ['method', 'NIQE (lower better)', 'BRISQUE (lower better)',
                 '2-D entropy (bits)', 'exposure gain'], rows))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description='Score reconstruction methods on a REDS-layout folder '
        '(PSNR, SSIM) or a recording without ground truth (NIQE, BRISQUE, '
        '2-D entropy)')
    parser.add_argument('data_root', type=Path(),
                        help='folder with spike/ and gt/, or a spike file '
                        '(.dat, .spk, .npy, .npz) without ground truth')
    parser.add_argument('--methods', default=METHODS,
                        type=SequenceOf(Choice(METHODS),
                                        max_length=len(METHODS)),
                        help=f'comma-separated, of {list(METHODS)}')
    parser.add_argument('--checkpoint', type=Path(),
                        help='wgse model (default: shipped weights)')
    parser.add_argument(
        '--models', type=SequenceOf(Path(), max_length=64),
        default=(), help='comma-separated checkpoints of more trained '
        'models, each scored under its file name (a folder of REDS streams)')
    parser.add_argument(
        '--repeat', type=Integer(0, 1000), default=3,
        help='timed reconstructions of one frame per method for the cost '
        'columns (default 3; 0 leaves them out)')
    parser.add_argument('--num-steps', type=NUM_STEPS, default=41)
    parser.add_argument('--spike-suffix', type=Text(empty=False),
                        default='.dat')
    parser.add_argument('--device', type=Text(empty=False), default='cpu')
    parser.add_argument(
        '--layout', type=LAYOUT,
        help=LAYOUT_HELP)
    parser.add_argument(
        '--frames', type=SequenceOf(Integer()),
        help='a recording\'s comma-separated centre frames (default: the '
        'middle frame)')
    parser.add_argument(
        '--exposure', type=EXPOSURE, default='auto',
        help='a recording\'s images are scored at this exposure: auto '
        '(default: a dark one brightened, its 99.5th percentile to white), '
        'none, or a gain')
    add_frame_size_options(parser)
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    methods = list(dict.fromkeys(args.methods))  # in order, once each
    if osp.isfile(args.data_root):
        check_frame_size(parser, args)
        try:
            total, _, _ = spike_shape(args.data_root, args.height,
                                      args.width, args.layout)
            frames = args.frames or [total // 2]
            results = score_recording(
                args.data_root, methods, args.checkpoint, args.num_steps,
                frames, args.exposure, args.height, args.width, args.device,
                args.layout)
        except (SpikeFileError, ValueError) as err:
            sys.exit(f'{parser.prog}: error: {err}')
        print(_format_recording_table(results, args.data_root, frames,
                                      args.exposure, args.device))
        return
    results = benchmark(args.data_root, methods, args.checkpoint,
                        args.num_steps, args.spike_suffix, args.device,
                        layout=args.layout, models=args.models,
                        repeat=args.repeat)
    print(format_table(results, args.device))


if __name__ == '__main__':
    main()
