"""Every MMSeg model base with spike input: which train, which are refused
and why, and what a training step costs.

For each ``mmseg::_base_/models/*.py`` the documented recipe
(:func:`wgse_mmseg.utils.spike_model.spike_config`: the spike data
preprocessor, T to the stem, the heads' classes to the data's) is built
at ``num_steps`` T and checked as a training run checks it
(:func:`~wgse_mmseg.utils.cross_checks.check_training_fits`); a model that
passes trains two iterations on random spikes and labels and predicts one
window. A model is *refused* where the package refuses it before training
(a :class:`~wgse_mmseg.utils.cross_checks.ModelFitError` naming why), or
where it needs what this install lacks (a compiled mmcv op, MMDetection
or MMPretrain); every other error is a *failure*, which the suite's test
of this module does not allow. Weights a base would download (its
``pretrained`` or a ``Pretrained`` ``init_cfg``) are listed and left out,
since a spike stem cannot take RGB weights.

    python -m wgse_bench.model_bases --out docs/models.md
"""
import argparse
import glob
import os.path as osp
import re
import time
from typing import Any, Dict, List, Optional

__all__ = ['model_bases', 'try_model_base']

#: what an install without an optional package raises where a base needs it
_NEEDS = ((r'mmcv\._ext|MissingCompiledOp|compiled op|install onedl-mmcv',
           'compiled mmcv ops'),
          (r'mmdet|got an unexpected keyword argument', 'MMDetection'),
          (r'mmpretrain|mmpretrain\.', 'MMPretrain'),
          (r'text_encoder required', 'a vocabulary and CLIP weights '
           '(an open-vocabulary model)'))


def model_bases() -> List[str]:
    """The ``mmseg::`` names of MMSeg's model bases, sorted."""
    import mmseg
    folder = osp.join(osp.dirname(mmseg.__file__), '.mim', 'configs',
                      '_base_', 'models')
    return sorted(f'mmseg::_base_/models/{osp.basename(path)}'
                  for path in glob.glob(osp.join(folder, '*.py')))


def _downloads(model: Any, path: str = 'model') -> List[str]:
    """Fields of ``model`` that name weights to download, set to ``None``
    in place."""
    found: List[str] = []
    if isinstance(model, dict):
        for key, value in list(model.items()):
            weights = key in ('pretrained', 'checkpoint') and \
                isinstance(value, str)
            if weights or (isinstance(value, dict) and
                           value.get('type') == 'Pretrained'):
                found.append(f'{path}.{key}')
                model[key] = None
            else:
                found.extend(_downloads(value, f'{path}.{key}'))
    elif isinstance(model, (list, tuple)):
        for index, value in enumerate(model):
            found.extend(_downloads(value, f'{path}[{index}]'))
    return found


def _train_and_predict(model, num_steps: int, side: int,
                       iterations: int) -> float:
    """``iterations`` training iterations (SGD) on random spikes and
    labels, then one prediction; the seconds of the last iteration (the
    first also pays for allocations a later one reuses)."""
    import torch
    from mmengine.optim import OptimWrapper
    from mmengine.structures import PixelData

    from mmseg.structures import SegDataSample

    def batch(size):
        samples = []
        for _ in range(size):
            sample = SegDataSample(metainfo=dict(
                img_shape=(side, side), ori_shape=(side, side),
                pad_shape=(side, side)))
            sample.gt_sem_seg = PixelData(
                data=torch.randint(0, 19, (1, side, side)))
            samples.append(sample)
        inputs = [torch.randint(0, 2, (num_steps, side, side),
                                dtype=torch.uint8) for _ in range(size)]
        return dict(inputs=inputs, data_samples=samples)

    wrapper = OptimWrapper(torch.optim.SGD(model.parameters(), lr=1e-3))
    model.train()
    seconds = 0.0
    for _ in range(iterations):
        start = time.perf_counter()
        losses = model.train_step(batch(2), wrapper)
        seconds = time.perf_counter() - start
        if not all(torch.isfinite(v).all() for v in losses.values()):
            raise ValueError(f'a loss is not finite: {losses}')
    model.eval()
    predicted = model.val_step(batch(1))[0].pred_sem_seg.data
    if tuple(predicted.shape[-2:]) != (side, side):
        raise ValueError(f'predicted {tuple(predicted.shape)} for a '
                         f'{side}x{side} window')
    return seconds


def try_model_base(base: str, num_steps: int = 8, side: int = 64,
                   iterations: int = 2) -> Dict[str, Any]:
    """One model base with spike input (module docstring), trained
    ``iterations`` iterations (the page's step time is the second's; one
    says whether the base trains).

    Returns:
        ``base``, ``status`` (``'trains'``, ``'refused'`` or
        ``'failed'``), ``reason`` (why, for the latter two), ``downloads``
        (fields left out), ``parameters`` (millions) and ``step_s`` (one
        training iteration of batch 2 at ``side`` x ``side``, the last).
    """
    from wgse_mmseg.argument_checks import check_integer

    # before the stack's imports and the sweep's try: a wrong count is the
    # caller's, no row's
    check_integer('try_model_base', 'iterations', iterations, 1)
    import torch
    from mmengine.registry import init_default_scope

    from mmseg.registry import MODELS
    from wgse_mmseg.utils.cross_checks import ModelFitError, \
        check_training_fits
    from wgse_mmseg.utils.spike_model import spike_config
    row: Dict[str, Any] = dict(base=base, status='failed', reason='',
                               downloads=[], parameters=None, step_s=None)
    try:
        cfg = spike_config(base, cfg_options=dict(
            num_steps=num_steps, crop_size=(side, side),
            **{'train_dataloader.batch_size': 2}))
        row['downloads'] = _downloads(cfg.model)
        init_default_scope('mmseg')
        torch.manual_seed(0)
        model = MODELS.build(cfg.model)
        row['parameters'] = sum(p.numel() for p in model.parameters()) / 1e6
        check_training_fits(cfg, model)
        row['step_s'] = _train_and_predict(model, num_steps, side,
                                           iterations)
        row['status'] = 'trains'
    except ModelFitError as err:
        row.update(status='refused', reason=str(err).split(': ', 1)[-1])
    except Exception as err:  # classified below; the test allows none
        text = f'{type(err).__name__}: {err}'
        needs = next((what for pattern, what in _NEEDS
                      if re.search(pattern, text)), None)
        row.update(status='refused' if needs else 'failed',
                   reason=(f'needs {needs}: ' if needs else '') + ' '.join(
                       text.split())[:300])
    return row


def format_rows(rows: List[Dict[str, Any]], machine: Dict[str, Any],
                num_steps: int, side: int) -> str:
    """The Markdown page of :func:`try_model_base`'s rows."""
    from .markdown import markdown_table
    table = markdown_table(
        ['model base', 'with spikes', 'params (M)',
         f'train step (s, 2x{num_steps}x{side}x{side})',
         'weights left out', 'why not'],
        [[osp.basename(r['base']), r['status'],
          '-' if r['parameters'] is None else f'{r["parameters"]:.2f}',
          '-' if r['step_s'] is None else f'{r["step_s"]:.2f}',
          ', '.join(r['downloads']) or '-', r['reason'] or '-']
         for r in rows])
    trains = sum(r['status'] == 'trains' for r in rows)
    return (f'# Models\n\nMMSeg\'s model bases (`mmseg::_base_/models/`) '
            f'with spike input by the recipe of the user guide ("WGSE in '
            f'front of any MMSeg model"; `wgse_mmseg.spike_config`): each '
            f'is built for T={num_steps}, checked as training starts, '
            f'trained two iterations of batch 2 on random '
            f'{side}x{side} spikes and labels and asked for one '
            f'prediction, or refused with the reason the package gives. '
            f'*Weights left out* are the RGB weights a base would '
            f'download, which a spike stem cannot take: set them to `None` '
            f'to train from scratch, as the shipped configs do. The step '
            f'time is one training iteration on the CPU, without an '
            f'enhancer. Made by `python -m wgse_bench.model_bases --out '
            f'docs/models.md`.\n\n'
            f'{trains} of {len(rows)} model bases train with spikes '
            f'here; machine: {machine["cpu"]}, {machine["cpu_count"]} '
            f'CPUs, torch {machine["torch"]}, mmseg '
            f'{machine["mmsegmentation"]}, mmcv {machine["mmcv"]}; 1-minute '
            f'load average {machine["load_average"]} when the sweep ended '
            f'(the step times are slower under load).\n\n{table}\n')


def build_parser() -> argparse.ArgumentParser:
    from wgse_mmseg.command_line import Integer, Path, Text
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--num-steps', type=Integer(1, 1024), default=8,
                        help='T of the spike input')
    parser.add_argument('--side', type=Integer(16, 1024), default=64,
                        help='side of the square training windows')
    parser.add_argument('--only', nargs='+', type=Text(empty=False),
                        help='base file names (pspnet_r50-d8.py ...)')
    parser.add_argument('--out', type=Path(),
                        help='write the page here as well')
    return parser


def main(argv: Optional[List[str]] = None) -> None:
    args = build_parser().parse_args(argv)
    import wgse_mmseg
    wgse_mmseg.register_all_modules()
    from .machine import machine_record
    bases = [b for b in model_bases() if not args.only or
             osp.basename(b) in args.only]
    rows = []
    for index, base in enumerate(bases):
        rows.append(try_model_base(base, args.num_steps, args.side))
        print(f'[{index + 1}/{len(bases)}] {osp.basename(base)}: '
              f'{rows[-1]["status"]} {rows[-1]["reason"][:120]}', flush=True)
    text = format_rows(rows, machine_record(), args.num_steps, args.side)
    print(text)
    if args.out:
        from wgse_mmseg.fileio.atomic import atomic_output
        with atomic_output(args.out) as out:
            out.write(text.encode())


if __name__ == '__main__':
    main()
