"""What a spike segmentor costs: parameters, FLOPs, time and memory.

The measurements behind ``tools/analysis_tools/benchmark.py`` and the
experiment runner, following MMSeg's ``tools/analysis_tools/benchmark.py`` and
``get_flops.py`` but for ``T``-channel spike input. Inputs are random binary
streams ``(T, H, W)`` (spike probability 0.3) packed as the data loader packs
them, so every timing includes the data preprocessor (batching, padding, the
enhancer) as a real run does; reading files from disk is excluded.

What is measured, and how:

* **Parameters** (:func:`inference_parameters`): those used at inference,
  enhancer included, auxiliary head excluded (MMSeg's convention).
* **FLOPs** (:func:`count_flops`): mmengine's ``FlopAnalyzer`` (fvcore's
  counter, as in MMSeg's ``get_flops.py``) on one ``(1, T, H, W)`` stream
  through the enhancer and the segmentor's ``mode='tensor'`` forward
  (backbone and decode head, no final resize), each traced with
  ``torch.jit``; an enhancer that cannot be traced (a custom autograd
  function) has unknown FLOPs, reported as such. One multiply-add counts as
  one FLOP. Counted: convolutions, matrix products, linear layers, batch/
  group/layer norms, bilinear/nearest upsampling, adaptive average pooling.
  Not counted: element-wise operations (activations, additions), softmax,
  max/average pooling, cumulative sums; their names and call counts are
  returned as ``uncounted_ops``. The fixed representations (TFP, TFI, mean
  filters) therefore count as 0 FLOPs: their cost shows in the timings.
* **Latency** (:func:`measure_latency`): ``model.test_step`` on one stream
  (batch 1) under ``torch.no_grad``: preprocessing, enhancer, segmentor,
  resize and argmax. **Throughput**: images per second of the same at the
  training batch size.
* **Training step** (:func:`measure_train_step`): ``model.train_step`` with
  the config's optimiser on a labelled batch: forward, loss (OHEM
  included), backward and update. **Enhancer share**: the median time of
  the enhancer's forward (and backward, if it has parameters) on the same
  batch alone, divided by the median step time. The two are timed
  separately, so where the enhancer is nearly the whole step (tiny crops,
  few repeats) the share can read slightly above 100%.
* **Peak memory** during the timed training steps. CUDA:
  ``torch.cuda.max_memory_allocated`` (tensors only, reset before the
  steps). CPU: the process's peak resident set size (Linux ``VmHWM``, reset
  through ``/proc/self/clear_refs`` before the steps): everything the
  process holds, framework and allocator caches included, so it is an upper
  bound of what the step needs; where the reset is impossible, the peak
  over the process's life (``ru_maxrss``). ``memory['kind']`` says which.

Every timing runs ``warmup`` untimed calls, then ``repeat`` timed ones
(CUDA synchronised around each); the summary is the median and the median
absolute deviation (MAD) of the repeats, and the raw samples are kept.
"""
from wgse_mmseg.openmmlab_stack import check_mmseg_layer

check_mmseg_layer('wgse_bench.segmentation')  # before MMSeg is imported

import os
import platform
import resource
from collections import Counter
from typing import Any, Dict, List, Optional, Sequence, Tuple

import torch
import torch.nn as nn
from mmengine.analysis import FlopAnalyzer
from mmengine.optim import build_optim_wrapper
from mmengine.registry import init_default_scope
from mmengine.runner import load_checkpoint
from mmengine.structures import PixelData

from mmseg.registry import DATASETS, MODELS
from mmseg.structures import SegDataSample
from wgse_mmseg.utils.config import load_config

from .machine import machine_record
from .markdown import markdown_table
from .timing import summarize, time_calls

__all__ = [
    'count_flops', 'measure_latency', 'measure_throughput',
    'measure_train_step', 'measure_enhancer_step', 'benchmark_config'
]

SPIKE_PROBABILITY = 0.3
NUM_CLASSES = 19


def make_spike_batch(num_steps: int, height: int, width: int,
                     batch_size: int, labels: bool = False,
                     seed: int = 0) -> dict:
    """A batch as ``PackSegInputs`` makes it: ``inputs``, a list of binary
    ``uint8`` ``(T, H, W)`` streams, and ``data_samples`` with image metadata
    (and random train-id labels ``(1, H, W)`` if ``labels``)."""
    generator = torch.Generator().manual_seed(seed)
    inputs, samples = [], []
    for _ in range(batch_size):
        inputs.append((torch.rand(num_steps, height, width,
                                  generator=generator) <
                       SPIKE_PROBABILITY).to(torch.uint8))
        sample = SegDataSample()
        sample.set_metainfo(dict(img_shape=(height, width),
                                 ori_shape=(height, width),
                                 pad_shape=(height, width)))
        if labels:
            sample.gt_sem_seg = PixelData(data=torch.randint(
                0, NUM_CLASSES, (1, height, width), generator=generator))
        samples.append(sample)
    return dict(inputs=inputs, data_samples=samples)


def build_model(config: str, cfg_options: Optional[dict] = None,
                checkpoint: Optional[str] = None,
                device: str = 'cpu') -> Tuple[Any, nn.Module]:
    """``(cfg, model)`` for ``config`` with ``cfg_options`` (``num_steps``,
    ``crop_size``, ... as in :func:`wgse_mmseg.utils.config.load_config`),
    weights from ``checkpoint`` if given, on ``device``."""
    cfg = load_config(config, cfg_options)
    model = MODELS.build(cfg.model)
    if checkpoint is not None:
        load_checkpoint(model, checkpoint, map_location='cpu', strict=True,
                        logger='silent')
    return cfg, model.to(device)


def _enhancer(model: nn.Module) -> Optional[nn.Module]:
    return getattr(model.data_preprocessor, 'enhancer', None)


def _count(module: Optional[nn.Module]) -> int:
    return 0 if module is None else sum(p.numel()
                                        for p in module.parameters())


def inference_parameters(model: nn.Module) -> Dict[str, int]:
    """``{'total', 'enhancer'}``: parameters used at inference (the
    auxiliary head, a training-only branch, excluded)."""
    auxiliary = getattr(model, 'auxiliary_head', None)
    return dict(total=_count(model) - _count(auxiliary),
                enhancer=_count(_enhancer(model)))


class _Segmentor(nn.Module):
    """The segmentor's ``mode='tensor'`` forward (backbone and decode head)
    as a module of its own, for tracing; the enhancer is not in it (the data
    preprocessor runs it) and is traced on its own."""

    def __init__(self, model: nn.Module):
        super().__init__()
        self.model = model

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        return self.model(inputs, mode='tensor')


def _analyze(module: nn.Module, inputs: torch.Tensor) -> FlopAnalyzer:
    analyzer = FlopAnalyzer(module, (inputs, ))
    analyzer.unsupported_ops_warnings(False)
    analyzer.uncalled_modules_warnings(False)
    analyzer.tracer_warnings('none')
    analyzer.total()  # traces now
    return analyzer


def count_flops(model: nn.Module, num_steps: int,
                size: Tuple[int, int]) -> Dict[str, Any]:
    """FLOPs of one ``(1, T, H, W)`` stream (see module docstring).

    Returns ``{'total', 'enhancer', 'uncounted_ops', 'note'}``;
    ``uncounted_ops`` maps each operator the counter skips to its number of
    calls. An enhancer that ``torch.jit`` cannot trace (a custom autograd
    function) has ``enhancer`` and ``total`` ``None``, and ``note`` says
    why; the segmentor's FLOPs are then ``total`` of a raw-spike twin.
    """
    device = next(model.parameters()).device
    spikes = (torch.rand(1, num_steps, *size, device=device) <
              SPIKE_PROBABILITY).float()
    enhancer = _enhancer(model)
    model.eval()
    with torch.no_grad():
        inputs = spikes if enhancer is None else enhancer(spikes)
        segmentor = _analyze(_Segmentor(model), inputs)
        uncounted = Counter(segmentor.unsupported_ops())
        flops, note = 0, None
        if enhancer is not None:
            try:
                analyzer = _analyze(enhancer, spikes)
            except RuntimeError as error:
                flops = None
                note = (f'{type(enhancer).__name__} cannot be traced by '
                        f'torch.jit ({error}); its FLOPs are unknown')
            else:
                flops = analyzer.total()
                uncounted.update(analyzer.unsupported_ops())
    total = None if flops is None else segmentor.total() + flops
    return dict(total=total, enhancer=flops,
                uncounted_ops=dict(sorted(uncounted.items())), note=note)


def _predict_seconds(model: nn.Module, num_steps: int, size: Tuple[int, int],
                     batch_size: int, repeat: int,
                     warmup: int) -> List[float]:
    device = next(model.parameters()).device
    batch = make_spike_batch(num_steps, *size, batch_size)
    model.eval()
    with torch.no_grad():
        return time_calls(lambda: model.test_step(batch), device, repeat,
                          warmup).wall


def measure_latency(model: nn.Module, num_steps: int, size: Tuple[int, int],
                    repeat: int = 10, warmup: int = 2) -> Dict[str, Any]:
    """Milliseconds of inference on one ``(T, H, W)`` stream (batch 1):
    ``{'median', 'mad', 'samples'}``."""
    seconds = _predict_seconds(model, num_steps, size, 1, repeat, warmup)
    return summarize([1e3 * s for s in seconds])


def measure_throughput(model: nn.Module, num_steps: int,
                       size: Tuple[int, int], batch_size: int,
                       repeat: int = 10, warmup: int = 2) -> Dict[str, Any]:
    """Images per second of inference in batches of ``batch_size``:
    ``{'median', 'mad', 'samples'}``."""
    seconds = _predict_seconds(model, num_steps, size, batch_size, repeat,
                               warmup)
    return summarize([batch_size / s for s in seconds])


def _read_status_kb(field: str) -> Optional[int]:
    try:
        with open('/proc/self/status') as f:
            for line in f:
                if line.startswith(field + ':'):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def _reset_peak_rss() -> bool:
    """Reset the process's peak RSS (Linux >= 4.0); ``False`` if impossible."""
    try:
        with open('/proc/self/clear_refs', 'w') as f:
            f.write('5')
    except OSError:
        return False
    return _read_status_kb('VmHWM') is not None


class _PeakMemory:
    """Peak memory over a block (see the module docstring)."""

    def __init__(self, device: torch.device):
        self.device = device

    def __enter__(self) -> '_PeakMemory':
        if self.device.type == 'cuda':
            torch.cuda.reset_peak_memory_stats(self.device)
            self.kind = 'cuda_max_memory_allocated'
            self.baseline = torch.cuda.memory_allocated(self.device)
        else:
            resettable = _reset_peak_rss()
            self.kind = ('cpu_peak_rss' if resettable else
                         'cpu_peak_rss_process_lifetime')
            self.baseline = 1024 * (_read_status_kb('VmRSS') or 0)
        return self

    def __exit__(self, *exc) -> None:
        if self.device.type == 'cuda':
            self.peak = torch.cuda.max_memory_allocated(self.device)
        elif self.kind == 'cpu_peak_rss':
            self.peak = 1024 * _read_status_kb('VmHWM')
        else:  # ru_maxrss is in kilobytes on Linux, bytes on macOS
            scale = 1 if platform.system() == 'Darwin' else 1024
            self.peak = scale * resource.getrusage(
                resource.RUSAGE_SELF).ru_maxrss

    def as_dict(self) -> Dict[str, Any]:
        return dict(kind=self.kind, peak_mb=self.peak / 2**20,
                    baseline_mb=self.baseline / 2**20)


def measure_train_step(model: nn.Module, optim_wrapper_cfg: dict,
                       num_steps: int, size: Tuple[int, int],
                       batch_size: int, repeat: int = 10,
                       warmup: int = 2) -> Dict[str, Any]:
    """Milliseconds per ``train_step`` and the peak memory of the timed steps.

    Returns ``{'step_ms': {'median', 'mad', 'samples'}, 'memory': {'kind',
    'peak_mb', 'baseline_mb'}}``. The model's weights change (it trains).
    """
    device = next(model.parameters()).device
    batch = make_spike_batch(num_steps, *size, batch_size, labels=True)
    optim_wrapper = build_optim_wrapper(model, optim_wrapper_cfg)
    model.train()
    for _ in range(warmup):  # warm-up also allocates the optimiser state
        model.train_step(batch, optim_wrapper)
    with _PeakMemory(device) as memory:
        seconds = time_calls(lambda: model.train_step(batch, optim_wrapper),
                             device, repeat, 0).wall
    return dict(step_ms=summarize([1e3 * s for s in seconds]),
                memory=memory.as_dict())


def measure_enhancer_step(model: nn.Module, num_steps: int,
                          size: Tuple[int, int], batch_size: int,
                          repeat: int = 10,
                          warmup: int = 2) -> Optional[Dict[str, Any]]:
    """Milliseconds of the enhancer's forward (and backward, when it has
    parameters) on a training batch ``(B, T, H, W)``; ``None`` without an
    enhancer."""
    enhancer = _enhancer(model)
    if enhancer is None:
        return None
    device = next(model.parameters()).device
    spikes = (torch.rand(batch_size, num_steps, *size, device=device) <
              SPIKE_PROBABILITY).float()
    enhancer.train()

    def step():
        out = enhancer(spikes)
        if out.requires_grad:
            out.backward(torch.ones_like(out))

    seconds = time_calls(step, device, repeat, warmup).wall
    enhancer.zero_grad(set_to_none=True)
    return summarize([1e3 * s for s in seconds])


def benchmark_config(config: str, device: str = 'cpu',
                     crop: Optional[Tuple[int, int]] = None,
                     repeat: int = 10, warmup: int = 2,
                     batch_size: Optional[int] = None,
                     cfg_options: Optional[dict] = None,
                     threads: Optional[int] = None) -> Dict[str, Any]:
    """Every measurement of the module docstring for one config.

    ``crop`` (default: the config's ``crop_size``) and ``T`` (the config's
    ``num_steps``, or ``cfg_options['num_steps']``) set the input;
    ``batch_size`` (default: the training batch size) sets throughput and
    training step. Returns a JSON-ready dict.
    """
    if device.startswith('cuda') and not torch.cuda.is_available():
        raise RuntimeError(f'--device {device}: CUDA is not available here')
    if threads is not None:
        torch.set_num_threads(threads)
    options = dict(cfg_options or {})
    if crop is not None:
        options['crop_size'] = ','.join(str(int(s)) for s in crop)
    cfg, model = build_model(config, options, device=device)
    num_steps, size = cfg.num_steps, tuple(cfg.crop_size)
    batch_size = batch_size or cfg.train_dataloader.batch_size
    timing = dict(repeat=repeat, warmup=warmup)
    parameters = inference_parameters(model)
    flops = count_flops(model, num_steps, size)
    latency = measure_latency(model, num_steps, size, **timing)
    throughput = measure_throughput(model, num_steps, size, batch_size,
                                    **timing)
    enhancer = measure_enhancer_step(model, num_steps, size, batch_size,
                                     **timing)
    train = measure_train_step(model, cfg.optim_wrapper, num_steps, size,
                               batch_size, **timing)
    share = (None if enhancer is None else
             enhancer['median'] / train['step_ms']['median'])
    enhancer_cfg = cfg.model.data_preprocessor.get('enhancer')
    return dict(
        config=config, enhancer=None if enhancer_cfg is None else
        enhancer_cfg.get('type'),
        # what ran the enhancer's band networks in the training steps
        enhancer_backend=getattr(_enhancer(model), 'backend_in_use', None),
        num_steps=num_steps, crop=list(size),
        batch_size=batch_size, params=parameters['total'],
        enhancer_params=parameters['enhancer'], flops=flops['total'],
        enhancer_flops=flops['enhancer'],
        uncounted_ops=flops['uncounted_ops'], flops_note=flops['note'],
        latency_ms=latency,
        throughput_img_s=throughput, train_step_ms=train['step_ms'],
        enhancer_step_ms=enhancer, enhancer_share=share,
        memory=train['memory'], environment=machine_record(device))


def validation_cost(config: str, cfg_options: Optional[dict],
                    checkpoint: Optional[str], repeat: int = 10,
                    warmup: int = 2) -> Dict[str, Any]:
    """Parameters and batch-1 latency of a (trained) model at the size of
    its first test sample (the experiment runner's "ms per image").

    Returns ``{'params', 'enhancer_params', 'image_size', 'latency_ms',
    'environment'}``.
    """
    cfg, model = build_model(config, cfg_options, checkpoint)
    init_default_scope(cfg.get('default_scope', 'mmseg'))
    num_steps, height, width = DATASETS.build(
        cfg.test_dataloader.dataset)[0]['inputs'].shape
    parameters = inference_parameters(model)
    return dict(params=parameters['total'],
                enhancer_params=parameters['enhancer'],
                image_size=[height, width],
                latency_ms=measure_latency(model, num_steps, (height, width),
                                           repeat, warmup),
                environment=machine_record())


def _giga(flops: Optional[int]) -> str:
    return '-' if flops is None else f'{flops / 1e9:.2f}'


def _timing(summary: Optional[Dict[str, Any]], digits: int = 1) -> str:
    if summary is None:
        return '-'
    return f"{summary['median']:.{digits}f} ± {summary['mad']:.{digits}f}"


def format_results(results: Sequence[Dict[str, Any]]) -> str:
    """The benchmark table (Markdown) of one or more results of
    :func:`benchmark_config`, with the environment beneath it."""
    headers = ['config', 'T', 'crop', 'params (M)', 'enh. params',
               'enh. backend', 'GFLOPs', 'enh. GFLOPs', 'latency ms (b1)',
               'throughput img/s', 'train step ms', 'enh. share',
               'peak mem MB']
    rows = []
    for r in results:
        share = ('-' if r['enhancer_share'] is None else
                 f"{100 * r['enhancer_share']:.1f}%")
        rows.append([
            os.path.splitext(os.path.basename(r['config']))[0],
            r['num_steps'], '{}x{}'.format(*r['crop']),
            f"{r['params'] / 1e6:.3f}", r['enhancer_params'],
            r.get('enhancer_backend') or '-', _giga(r['flops']),
            _giga(r['enhancer_flops']),
            _timing(r['latency_ms']),
            _timing(r['throughput_img_s'], 2) + f" (b{r['batch_size']})",
            _timing(r['train_step_ms']) + f" (b{r['batch_size']})", share,
            f"{r['memory']['peak_mb']:.0f}"
        ])
    env = results[0]['environment']
    memory_kinds = sorted({r['memory']['kind'] for r in results})
    notes = [
        f"device: {env['device']}" + (f" ({env['gpu']}, CUDA {env['cuda']})"
                                      if 'gpu' in env else '') +
        f"; CPU: {env['cpu']} ({env['cpu_count']} logical cores, "
        f"{env['torch_threads']} torch threads)",
        f"software: python {env['python']}, torch {env['torch']}, "
        f"mmcv {env['mmcv']}, mmengine {env['mmengine']}, "
        f"mmsegmentation {env['mmsegmentation']}, "
        f"wgse_mmseg {env['wgse_mmseg']}; {env['platform']}",
        'times: median ± median absolute deviation over the repeats, after '
        'warm-up; FLOPs: one multiply-add = 1 FLOP, batch 1, auxiliary head '
        'excluded (see wgse_bench/segmentation.py for what is '
        'counted); '
        f"peak memory: {', '.join(memory_kinds)} during the training steps",
    ]
    notes += list(dict.fromkeys(r['flops_note'] for r in results
                                if r['flops_note']))
    return markdown_table(headers, rows) + '\n\n' + '\n'.join(
        f'- {n}' for n in notes)
