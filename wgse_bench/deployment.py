"""What deploying a spike segmentor gives: windows per second in torch
(eager) and in ONNX Runtime, the same model and input.

:func:`measure_deployment` builds one config (random weights: the speed of
a forward pass does not depend on their values), times ``model.test_step``
(preprocessing, the enhancer on its default backend, segmentor, resize,
argmax) on a batch of random Bernoulli streams ``(B, T, H, W)``, exports
the model (:mod:`wgse_mmseg.apis.onnx_export`) and times
:class:`~wgse_mmseg.apis.onnx_segmentor.OnnxSpikeSegmentor` and the argmax
on the same batch. Both on the CPU, with the same number of threads
(``threads``). A window is one ``(T, H, W)`` stream: windows per second
is the batch size over the median time of a call. ``tools/analysis_tools/
benchmark_deployment.py`` runs it per entry of an experiment grid and
writes the JSON the experiment report reads (its deployment columns).
"""
from wgse_mmseg.openmmlab_stack import check_mmseg_layer

check_mmseg_layer('wgse_bench.deployment')  # before MMSeg

import os.path as osp
import tempfile
from typing import Any, Dict, List, Optional, Sequence

import torch
from mmengine.registry import init_default_scope

from mmseg.registry import MODELS
from mmseg.structures import SegDataSample
from wgse_mmseg.apis.onnx_export import (SpikeSegmentorGraph, export_onnx,
                                         random_spikes)
from wgse_mmseg.apis.onnx_segmentor import OnnxSpikeSegmentor
from wgse_mmseg.argument_checks import (ArgumentError, check_integer,
                                        check_path, check_text, is_integer)
from wgse_mmseg.limits import (MAX_BATCH_SIZE, MAX_IMAGE_SIDE, MAX_NUM_STEPS,
                               MAX_WORKERS)
from wgse_mmseg.utils.config import load_config

from .machine import machine_record
from .markdown import markdown_table
from .timing import check_repeats, summarize, time_calls

__all__ = ['measure_deployment']

#: the two ways of running a model that are timed
BACKENDS = ('torch_eager', 'onnxruntime')


def _batch(spikes: torch.Tensor) -> dict:
    """``spikes`` ``(B, T, H, W)`` packed as the data loader packs them."""
    height, width = spikes.shape[-2:]
    samples = []
    for _ in spikes:
        sample = SegDataSample()
        sample.set_metainfo(dict(img_shape=(height, width),
                                 ori_shape=(height, width),
                                 pad_shape=(height, width)))
        samples.append(sample)
    return dict(inputs=list(spikes.to(torch.uint8)), data_samples=samples)


def measure_deployment(name: str, config: str,
                       cfg_options: Optional[Dict[str, Any]],
                       shape: Sequence[int], batch_size: int = 1,
                       repeat: int = 5, warmup: int = 1,
                       threads: Optional[int] = None) -> Dict[str, Any]:
    """Windows per second of ``config`` (with ``cfg_options``) in torch
    eager and in ONNX Runtime, on ``batch_size`` streams of ``shape``
    ``(T, H, W)``; ``name`` labels the result. ``threads``: torch's and
    ONNX Runtime's intra-op threads, the same for both (``None``: each
    one's default); one thread gives the steadier figures on a machine
    shared with other work.

    Returns:
        ``name``, ``config``, ``shape``, ``batch_size``, ``threads``, per
        backend (torch eager and ONNX Runtime) the call's wall and CPU
        seconds (``seconds``, ``cpu_seconds``: median and MAD) and
        ``windows_per_s`` (batch over the median wall time), and the machine
        (device, CPU, load, versions). ``repeat`` and ``warmup`` are
        :func:`~.timing.time_calls`'s, checked before anything is built.
    """
    entry = 'measure_deployment'
    check_text(entry, 'name', name)
    if not (isinstance(shape, (list, tuple)) and len(shape) == 3 and
            is_integer(shape[0], 1, MAX_NUM_STEPS) and
            all(is_integer(side, 1, MAX_IMAGE_SIDE) for side in shape[1:])):
        raise ArgumentError(entry, 'shape', f'(T, H, W), T an integer in '
                            f'[1, {MAX_NUM_STEPS}] and H, W in '
                            f'[1, {MAX_IMAGE_SIDE}]', shape)
    check_integer(entry, 'batch_size', batch_size, 1, MAX_BATCH_SIZE)
    check_integer(entry, 'threads', threads, 1, MAX_WORKERS, optional=True)
    check_repeats(entry, repeat, warmup)
    check_path(entry, 'config', config, exists='file')
    previous = torch.get_num_threads()
    if threads is not None:
        torch.set_num_threads(threads)
    try:
        return _measure(name, config, cfg_options, shape, batch_size, repeat,
                        warmup, threads)
    finally:
        torch.set_num_threads(previous)


def _measure(name, config, cfg_options, shape, batch_size, repeat, warmup,
             threads) -> Dict[str, Any]:
    """:func:`measure_deployment` once its threads are set."""
    num_steps, height, width = shape
    cfg = load_config(config, dict(cfg_options or {}, num_steps=num_steps))
    init_default_scope(cfg.get('default_scope', 'mmseg'))
    torch.manual_seed(0)
    model = MODELS.build(cfg.model).eval()
    spikes = random_spikes((batch_size, num_steps, height, width), seed=0)
    batch = _batch(spikes)
    with torch.no_grad():
        eager = time_calls(lambda: model.test_step(batch), 'cpu', repeat,
                           warmup)
        with tempfile.TemporaryDirectory() as folder:
            path = export_onnx(SpikeSegmentorGraph(model),
                               osp.join(folder, 'model.onnx'), num_steps,
                               height, width)
            runner = OnnxSpikeSegmentor(path, threads=threads)
            onnx = time_calls(lambda: runner(spikes).argmax(1), 'cpu',
                              repeat, warmup)
    import onnxruntime
    result = dict(name=name, config=config, cfg_options=cfg_options,
                  shape=list(shape), batch_size=batch_size, threads=threads,
                  environment=dict(machine_record('cpu'),
                                   onnxruntime=onnxruntime.__version__))
    for backend, timings in zip(BACKENDS, (eager, onnx)):
        seconds = summarize(timings.wall)
        result[backend] = dict(seconds=seconds,
                               cpu_seconds=summarize(timings.cpu),
                               windows_per_s=batch_size / seconds['median'])
    return result


def format_deployment(results: List[Dict[str, Any]]) -> str:
    """A Markdown table of :func:`measure_deployment` results, the machine
    beneath it."""
    rows = []
    for r in results:
        speeds = [r[backend]['windows_per_s'] for backend in BACKENDS]
        rows.append([r['name'], 'x'.join(map(str, r['shape'])),
                     r['batch_size']] + [f'{s:.2f}' for s in speeds] +
                    [f'{speeds[1] / speeds[0]:.2f}'])
    table = markdown_table(['entry', 'T x H x W', 'batch',
                            'windows/s torch eager',
                            'windows/s ONNX Runtime', 'ONNX / torch'], rows)
    if not results:
        return table
    env = results[0]['environment']
    loads = ', '.join(f"{r['environment']['load_average']:.2f}"
                      for r in results
                      if r['environment']['load_average'] is not None)
    threads = results[0].get('threads') or 'default'
    return (f"{table}\n\nMachine: {env['cpu']} ({env['cpu_count']} "
            f"logical cores; threads: {threads}); torch "
            f"{env['torch']}, onnxruntime {env['onnxruntime']}, python "
            f"{env['python']}; {env['platform']}. 1-minute load average "
            f"before each entry: {loads or 'unknown'}.")
