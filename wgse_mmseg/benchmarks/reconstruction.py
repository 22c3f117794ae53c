"""Score reconstruction methods on a REDS-layout folder.

    python -m wgse_mmseg.benchmarks.reconstruction DATA_ROOT
        [--methods wgse,tfp,tfi] [--checkpoint CKPT] [--num-steps 41]
        [--spike-suffix .dat] [--layout THW|HWT]

``DATA_ROOT`` holds ``spike/<name>.dat`` beside ``gt/<name>.png``
(:class:`~wgse_mmseg.datasets.reds.REDSSpikeDataset`; ``--spike-suffix``
for ``.spk``/``.npy``/``.npz`` streams, ``--layout`` for arrays that do not
record their layout). Every method sees the
same ``num_steps``-frame windows centred on the ground truth's frame and is
scored by :class:`ReconstructionMetric` (PSNR, SSIM, 2-D entropy); prints a
Markdown table with each method's PSNR margin over TFP.
"""
import argparse
from typing import Dict, Optional, Sequence

from tqdm import tqdm

from .. import register_all_modules

# a command line (``python -m``): its own explicit set-up of the MMSeg layer,
# as the tools make it, before the layer's packages are imported
register_all_modules()
from ..core import arguments
from ..core.arguments import LAYOUT, NUM_STEPS, Choice, Path, Text
from ..datasets.reds import (LoadSpikeImagePair, PackReconstructionInputs,
                             REDSSpikeDataset)
from ..models.reconstruction import (METHODS, load_reconstructor,
                                     reconstruction_method)
from ..evaluation.metrics import ReconstructionMetric

__all__ = ['benchmark', 'format_table']


def benchmark(data_root: str, methods: Sequence[str] = METHODS,
              checkpoint: Optional[str] = None, num_steps: int = 41,
              spike_suffix: str = '.dat', device: str = 'cpu',
              progress: bool = True,
              layout: Optional[str] = None) -> Dict[str, Dict[str, float]]:
    """``{method: {'PSNR', 'SSIM', 'Entropy2D'}}`` over the folder's samples
    (a progress bar on stderr unless ``progress`` is False).

    ``checkpoint`` is the ``wgse`` model (default: the shipped weights); its
    ``num_steps`` must equal ``num_steps``. ``layout``: of ``.npy``/``.npz``
    streams that do not record it (``LoadSpikeFromFile``'s).
    """
    functions = {}
    for method in methods:
        if method == 'wgse':
            model = load_reconstructor(checkpoint, device)
            if model.num_steps != num_steps:
                raise ValueError(
                    f'{checkpoint or "shipped weights"}: the model takes '
                    f'{model.num_steps}-frame windows, not {num_steps}')
            functions[method] = model.reconstruct
        else:
            functions[method] = reconstruction_method(method)
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
    return {method: metric.evaluate(len(dataset))
            for method, metric in metrics.items()}


def format_table(results: Dict[str, Dict[str, float]]) -> str:
    """Markdown table of :func:`benchmark`'s results (margin over TFP)."""
    lines = ['| method | PSNR (dB) | SSIM | 2-D entropy (bits) | PSNR - TFP |',
             '|---|---|---|---|---|']
    reference = results.get('tfp', {}).get('PSNR')
    for method, scores in results.items():
        margin = ('' if reference is None else
                  f'{scores["PSNR"] - reference:+.2f}')
        lines.append(f'| {method.upper()} | {scores["PSNR"]:.2f} | '
                     f'{scores["SSIM"]:.4f} | {scores["Entropy2D"]:.3f} | '
                     f'{margin} |')
    return '\n'.join(lines)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description='Score reconstruction methods on a REDS-layout folder')
    parser.add_argument('data_root', type=Path(),
                        help='folder with spike/ and gt/')
    parser.add_argument('--methods', default=METHODS,
                        type=arguments.Sequence(Choice(METHODS),
                                      max_length=len(METHODS)),
                        help=f'comma-separated, of {list(METHODS)}')
    parser.add_argument('--checkpoint', type=Path(),
                        help='wgse model (default: shipped weights)')
    parser.add_argument('--num-steps', type=NUM_STEPS, default=41)
    parser.add_argument('--spike-suffix', type=Text(empty=False),
                        default='.dat')
    parser.add_argument('--device', type=Text(empty=False), default='cpu')
    parser.add_argument(
        '--layout', type=LAYOUT,
        help='THW or HWT: how a .npy/.npz that does not record its '
        'layout stores its frames, (T, H, W) or (H, W, T) (default: what '
        'the file records; an error where it records none)')
    return parser


def main(argv=None):
    args = build_parser().parse_args(argv)
    methods = list(dict.fromkeys(args.methods))  # in order, once each
    results = benchmark(args.data_root, methods, args.checkpoint,
                        args.num_steps, args.spike_suffix, args.device,
                        layout=args.layout)
    print(format_table(results))


if __name__ == '__main__':
    main()
