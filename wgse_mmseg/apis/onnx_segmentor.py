"""Run an exported spike segmentor (``tools/deployment/pytorch2onnx.py``)
in ONNX Runtime.

:class:`OnnxSpikeSegmentor` maps float spikes ``(B, T, H, W)`` to logits
``(B, K, H, W)`` as the torch model does (preprocessing, enhancer and
resize are inside the graph, :mod:`.onnx_export`), checking its input
first: the graph holds no checks of its own. It needs ``onnxruntime`` and
torch, not OpenMMLab.
"""
import json
import os.path as osp
from typing import Optional, Tuple

import numpy as np
import torch

__all__ = ['OnnxSpikeSegmentor']


def _static_shape(path: str, dims) -> Tuple[int, int, int]:
    """``(T, H, W)`` of the graph's input ``(batch, T, H, W)``."""
    if len(dims) != 4 or not all(isinstance(d, int) and d > 0
                                 for d in dims[1:]):
        raise ValueError(
            f'{path}: the graph input is {list(dims)}; an exported spike '
            f'segmentor takes (batch, T, H, W) with T, H, W fixed')
    return tuple(dims[1:])


class OnnxSpikeSegmentor:
    """An exported spike segmentor on ONNX Runtime's CPU (or CUDA)
    provider.

    Args:
        onnx_path: a file of ``tools/deployment/pytorch2onnx.py``.
        device: ``'cpu'``, or ``'cuda'``/``'cuda:N'`` where ONNX Runtime
            has its CUDA provider.
        threads: ONNX Runtime's intra-op threads; ``None``: its default
            (one per core).

    Attributes:
        input_shape: the ``(T, H, W)`` the model was exported for.
        dataset_meta: ``classes`` and ``palette`` recorded at export
            (read as JSON, data only), or ``None``.
    """

    def __init__(self, onnx_path: str, device: str = 'cpu',
                 threads: Optional[int] = None):
        import onnxruntime
        if not osp.isfile(onnx_path):
            raise FileNotFoundError(f'{onnx_path}: no such ONNX file')
        providers = ['CPUExecutionProvider']
        if device.startswith('cuda'):
            if 'CUDAExecutionProvider' not in \
                    onnxruntime.get_available_providers():
                raise ValueError(
                    f'device={device!r}: this onnxruntime has no CUDA '
                    f'provider (install onnxruntime-gpu), or use '
                    f"device='cpu'")
            index = int(device.partition(':')[2] or 0)
            providers = [('CUDAExecutionProvider', dict(device_id=index))]
        elif device != 'cpu':
            raise ValueError(f"device must be 'cpu' or 'cuda[:N]', got "
                             f'{device!r}')
        options = onnxruntime.SessionOptions()
        if threads is not None:
            if isinstance(threads, bool) or not isinstance(threads, int) \
                    or threads < 1:
                raise ValueError(f'threads must be an integer >= 1 or None, '
                                 f'got {threads!r}')
            options.intra_op_num_threads = threads
        try:
            self.session = onnxruntime.InferenceSession(
                onnx_path, options, providers=providers)
        except Exception as err:  # onnxruntime raises its own types
            raise ValueError(
                f'{onnx_path}: not a model ONNX Runtime can load '
                f'({type(err).__name__}: {str(err)[:300]})') from err
        inputs, outputs = self.session.get_inputs(), \
            self.session.get_outputs()
        if len(inputs) != 1 or len(outputs) != 1:
            raise ValueError(
                f'{onnx_path}: an exported spike segmentor has one input '
                f'and one output, found {len(inputs)} and {len(outputs)}')
        self.path = onnx_path
        self.device = device
        self.input_name = inputs[0].name
        self.input_shape = _static_shape(onnx_path, inputs[0].shape)
        self.dataset_meta = self._read_dataset_meta()

    def _read_dataset_meta(self) -> Optional[dict]:
        text = self.session.get_modelmeta().custom_metadata_map.get(
            'dataset_meta')
        if text is None:
            return None
        try:
            meta = json.loads(text)
            classes, palette = meta['classes'], meta['palette']
        except (ValueError, TypeError, KeyError):
            raise ValueError(f'{self.path}: its dataset_meta is not the '
                             f'JSON of classes and palette') from None
        if not (isinstance(classes, list) and
                all(isinstance(c, str) for c in classes) and
                isinstance(palette, list) and all(
                    isinstance(c, list) and len(c) == 3 and
                    all(isinstance(v, int) and 0 <= v <= 255 for v in c)
                    for c in palette)):
            raise ValueError(f'{self.path}: its dataset_meta holds classes '
                             f'(names) and palette (RGB triples in 0..255)')
        return dict(classes=classes, palette=palette)

    def _check(self, spikes: torch.Tensor) -> None:
        if not isinstance(spikes, torch.Tensor):
            raise TypeError(f'OnnxSpikeSegmentor takes a torch.Tensor of '
                            f'spikes, got {type(spikes).__name__}')
        expected = ('B', ) + self.input_shape
        if spikes.dim() != 4 or tuple(spikes.shape[1:]) != self.input_shape:
            raise ValueError(
                f'{self.path}: exported for spikes (B, T, H, W) = '
                f'{expected}, got {tuple(spikes.shape)}; export again '
                f'with --shape for another T, H, W')
        if spikes.shape[0] == 0:
            raise ValueError(f'{self.path}: an empty batch, shape '
                             f'{tuple(spikes.shape)}')
        bad = (spikes != 0) & (spikes != 1)
        if spikes.dtype != torch.bool and bool(bad.any()):
            values = spikes[bad]
            nan = torch.isnan(values) if values.is_floating_point() else \
                torch.zeros_like(values, dtype=torch.bool)
            shown = (['nan'] if nan.any() else []) + \
                values[~nan].unique()[:5].tolist()
            raise ValueError(f'spikes hold only 0 and 1, found {shown} '
                             f'({spikes.dtype})')

    def __call__(self, spikes: torch.Tensor) -> torch.Tensor:
        """``(B, T, H, W)`` spikes (0 and 1, any dtype) -> ``(B, K, H, W)``
        float32 logits on the CPU."""
        self._check(spikes)
        array = spikes.detach().to('cpu', torch.float32).numpy()
        logits, = self.session.run(None, {self.input_name:
                                          np.ascontiguousarray(array)})
        return torch.from_numpy(logits)
