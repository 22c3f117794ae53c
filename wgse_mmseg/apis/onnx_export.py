"""Export a spike segmentor, enhancer included, to one ONNX graph.

The graph (:class:`SpikeSegmentorGraph`) maps float spikes ``(B, T, H, W)``
to logits ``(B, K, H, W)`` at the input's size: the enhancer of the
config's ``SpikeSegDataPreProcessor`` (WGSE, TFP, the mean filters, or
none), the segmentor's backbone and decode head, and the final resize, all
inside. ``T``, ``H`` and ``W`` are fixed at export (PSPNet's adaptive
pooling and WGSE's wavelet matrices are constants of them); the batch is
dynamic. :func:`export_onnx` writes it with ``torch.onnx.export(...,
dynamo=True)``; :func:`compare_with_onnx` runs it in ONNX Runtime and
measures its agreement with the torch model (:data:`LOGITS_TOLERANCE`,
:data:`MIN_ARGMAX_AGREEMENT`); :class:`~.onnx_segmentor.OnnxSpikeSegmentor`
runs it.

What exports: WGSE through its ``'reference'`` backend (the band networks'
own ``nn.Conv`` modules; the compiled C kernel and the Triton kernel are
custom code ONNX has no operator for, and the ``'torch'`` backend's
chunked recomputation is a training-memory device), so the export sets
every WGSE's backend to ``'reference'``; synchronised batch norm becomes
batch norm. The input checks of the preprocessor and the enhancers (0 and
1 only, finite values) are data-dependent control flow and stay outside
the graph: :class:`~.onnx_segmentor.OnnxSpikeSegmentor` makes them.
"""
from ..openmmlab_stack import check_mmseg_layer

check_mmseg_layer('wgse_mmseg.apis.onnx_export')  # before MMSeg is imported

import json
import os
import warnings
from typing import Any, Callable, Dict, Optional, Sequence

import onnx
import torch
from mmengine.model import revert_sync_batchnorm
from torch import nn

from ..argument_checks import ArgumentError, check_integer, check_path
from ..limits import MAX_IMAGE_SIDE, MAX_NUM_STEPS
from ..core.wgse import WGSE
from ..fileio.atomic import atomic_path
from ..utils.cross_checks import check_input_fits
from .onnx_segmentor import (INPUT, OUTPUT, OnnxSpikeSegmentor,
                             check_dataset_meta)
from .onnx_settings import (LOGITS_TOLERANCE, MIN_ARGMAX_AGREEMENT, OPSET,
                            OPSETS)

__all__ = ['export_onnx']

#: spike probability of the random streams of :func:`compare_with_onnx`
SPIKE_PROBABILITY = 0.3


class SpikeSegmentorGraph(nn.Module):
    """A built MMSeg segmentor with a ``SpikeSegDataPreProcessor`` as one
    module: float spikes ``(B, T, H, W)`` -> logits ``(B, K, H, W)``.

    The preprocessor's enhancer (if any) runs first; then the segmentor's
    ``encode_decode``, whose decode head resizes its logits to the input's
    ``(H, W)``. Every WGSE inside runs its ``'reference'`` backend (the
    only one ONNX can hold; see the module docstring). ``segmentor`` is
    put in evaluation mode, with synchronised batch norm reverted.
    """

    def __init__(self, segmentor: nn.Module):
        super().__init__()
        self.segmentor = revert_sync_batchnorm(segmentor).eval()
        self.enhancer = getattr(segmentor.data_preprocessor, 'enhancer',
                                None)
        if self.enhancer is not None:
            for module in self.enhancer.modules():
                if isinstance(module, WGSE):
                    module.backend = 'reference'

    def forward(self, spikes: torch.Tensor) -> torch.Tensor:
        """``(B, T, H, W)`` float spikes -> ``(B, K, H, W)`` logits."""
        inputs = spikes if self.enhancer is None else self.enhancer(spikes)
        size = tuple(spikes.shape[-2:])
        meta = dict(img_shape=size, ori_shape=size, pad_shape=size)
        return self.segmentor.encode_decode(inputs, [meta])


def random_spikes(shape: Sequence[int], seed: int) -> torch.Tensor:
    """Bernoulli(:data:`SPIKE_PROBABILITY`) float32 spikes of ``shape``
    (``(B, T, H, W)``), from a generator seeded with ``seed``."""
    generator = torch.Generator().manual_seed(seed)
    return (torch.rand(*shape, generator=generator) <
            SPIKE_PROBABILITY).float()


def export_onnx(graph: SpikeSegmentorGraph, path: str, num_steps: int,
                height: int, width: int, opset: int = OPSET,
                dataset_meta: Optional[dict] = None,
                check: Optional[Callable[[str], None]] = None) -> str:
    """Write ``graph`` as ONNX to ``path``, verified before it is
    published: whole and passing every check, or not at all.

    The input ``spikes`` is ``(batch, num_steps, height, width)`` float32
    with a dynamic batch; the output ``logits`` ``(batch, K, height,
    width)``. ``dataset_meta`` (``classes``, ``palette``; checked
    before anything is done) is
    stored as JSON in the model's metadata (``dataset_meta``). The file is
    written to a temporary beside ``path``, opened as
    :class:`~.onnx_segmentor.OnnxSpikeSegmentor` opens it (its interface
    and metadata checked), then given to ``check`` (which raises to refuse
    it; the tool's comparison with the torch model), and only then renamed
    to ``path``. Returns ``path``.

    Raises:
        ValueError: naming ``path``, for a shape below the smallest input
            the model takes (the check a training's start makes), a
            model the exporter cannot trace
            (TFI's data-dependent scans), metadata that is not classes and
            a palette, or a file its own checks refuse; nothing is left.
    """
    check_integer('export_onnx', 'num_steps', num_steps, 1, MAX_NUM_STEPS)
    check_integer('export_onnx', 'height', height, 1, MAX_IMAGE_SIDE)
    check_integer('export_onnx', 'width', width, 1, MAX_IMAGE_SIDE)
    check_integer('export_onnx', 'opset', opset, OPSETS.minimum,
                  OPSETS.maximum)
    check_path('export_onnx', 'path', path)
    if os.path.isdir(path):
        raise ArgumentError('export_onnx', 'path', 'the path of the file to '
                            'write, not a folder', path)
    if not isinstance(graph, SpikeSegmentorGraph):
        raise ArgumentError('export_onnx', 'graph', 'a SpikeSegmentorGraph '
                            '(a built segmentor as one module)', graph)
    if dataset_meta is not None:
        dataset_meta = check_dataset_meta(f'{path} (dataset_meta)',
                                          dataset_meta)
        classes = getattr(getattr(graph.segmentor, 'decode_head', None),
                          'num_classes', None)
        if classes not in (None, len(dataset_meta['classes'])):
            raise ValueError(
                f'{path}: the model has {classes} classes but its '
                f'dataset_meta names {len(dataset_meta["classes"])}')
    check_input_fits(graph.segmentor, num_steps, height, width,
                     f'{path} (the export shape)')
    example = random_spikes((2, num_steps, height, width), seed=0)
    batch = torch.export.Dim('batch', min=1, max=4096)
    try:
        with torch.no_grad(), warnings.catch_warnings():
            warnings.simplefilter('ignore')  # the exporter's notes
            program = torch.onnx.export(
                graph.eval(), (example, ), dynamo=True, opset_version=opset,
                input_names=[INPUT], output_names=[OUTPUT],
                dynamic_shapes=({0: batch}, ), verbose=False)
    except Exception as err:  # the exporter raises many types
        summary = str(err).strip().splitlines()
        raise ValueError(
            f'{path}: this model does not export to ONNX '
            f'({type(graph.enhancer).__name__} enhancer; TFI does not: '
            f'see docs/user_guide.md, "Export to ONNX"): '
            f'{type(err).__name__}: '
            f'{summary[0][:300] if summary else ""}') from err
    model = program.model_proto
    if dataset_meta is not None:
        entry = model.metadata_props.add()
        entry.key, entry.value = 'dataset_meta', json.dumps(dataset_meta)
    onnx.checker.check_model(model)
    with atomic_path(path) as written:
        with open(written, 'wb') as f:
            f.write(model.SerializeToString())
        try:
            OnnxSpikeSegmentor(written)
        except ValueError as err:
            raise ValueError(f'{path}: the exported file fails its own '
                             f'interface check, not written: {err}') from err
        if check is not None:
            check(written)
    return path


def compare_with_onnx(graph: SpikeSegmentorGraph, onnx_path: str,
                      spikes: torch.Tensor) -> Dict[str, Any]:
    """Run ``graph`` and the ONNX file (ONNX Runtime, CPU) on the same
    float spikes ``(B, T, H, W)`` (:func:`random_spikes` of the file's
    shape, say) and measure how far they agree.

    Returns:
        ``max_abs_diff`` (the largest logit difference), ``scale``
        (``max(1, max |torch logits|)``), ``argmax_agreement`` (the share
        of pixels with the same class), ``shape`` of the logits, and ``ok``:
        ``max_abs_diff <= LOGITS_TOLERANCE * scale`` and
        ``argmax_agreement >= MIN_ARGMAX_AGREEMENT``.
    """
    got = OnnxSpikeSegmentor(onnx_path)(spikes)
    with torch.no_grad():
        expected = graph.eval()(spikes)
    difference = float((got - expected).abs().max())
    scale = max(1.0, float(expected.abs().max()))
    agreement = float((got.argmax(1) == expected.argmax(1)).float().mean())
    return dict(max_abs_diff=difference, scale=scale,
                argmax_agreement=agreement, shape=list(expected.shape),
                ok=bool(difference <= LOGITS_TOLERANCE * scale and
                        agreement >= MIN_ARGMAX_AGREEMENT))
