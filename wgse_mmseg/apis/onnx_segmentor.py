"""Run an exported spike segmentor (``tools/deployment/pytorch2onnx.py``)
in ONNX Runtime.

:class:`OnnxSpikeSegmentor` maps float spikes ``(B, T, H, W)`` to logits
``(B, K, H, W)`` as the torch model does (preprocessing, enhancer and
resize are inside the graph, :mod:`.onnx_export`), checking its input
first: the graph holds no checks of its own. A file is checked against that
interface when it is opened (:func:`check_interface`): one input
``spikes`` ``(batch, T, H, W)`` with ``T``, ``H``, ``W`` fixed and a
numeric element type (the spikes are fed in it: 0 and 1 are exact in every
one), one output ``logits`` ``(batch, K, H, W)`` of floats, ``K`` the
number of classes the file records; a fixed batch is run in chunks of it.
Every result is checked against the same interface. It needs
``onnxruntime`` and torch, not OpenMMLab.
"""
import os.path as osp
from typing import NamedTuple, Optional, Tuple

import numpy as np
import torch

from ..fileio.bounded_reads import check_utf8_path, parse_json
from ..fileio.input_guard import note_input
from ..utils.checkpoint import check_dataset_meta

__all__ = ['OnnxSpikeSegmentor']

#: the names of an exported graph's input and output
INPUT, OUTPUT = 'spikes', 'logits'
#: ONNX Runtime's input element types -> the NumPy dtype the spikes are fed
#: in (0 and 1 are exact in each)
_INPUT_TYPES = {'tensor(float)': np.float32, 'tensor(float16)': np.float16,
                'tensor(double)': np.float64, 'tensor(uint8)': np.uint8,
                'tensor(int8)': np.int8, 'tensor(int32)': np.int32,
                'tensor(int64)': np.int64, 'tensor(bool)': np.bool_}
#: the output element types that can hold logits
_OUTPUT_TYPES = ('tensor(float)', 'tensor(float16)', 'tensor(double)')


class OnnxInterface(NamedTuple):
    """What an exported spike segmentor's file declares."""
    #: ``(T, H, W)`` of its input
    input_shape: Tuple[int, int, int]
    #: the NumPy dtype its input is fed in
    input_dtype: type
    #: its fixed batch size, or ``None`` for a dynamic batch
    batch: Optional[int]
    #: ``K``, the classes of its output, or ``None`` where not fixed
    num_classes: Optional[int]


def _fixed(dim) -> bool:
    return isinstance(dim, int) and dim > 0


def check_interface(path: str, inputs, outputs) -> OnnxInterface:
    """The :class:`OnnxInterface` of a graph's ``inputs`` and ``outputs``
    (ONNX Runtime's ``NodeArg`` lists: ``name``, ``type``, ``shape``).

    Raises:
        ValueError: naming ``path`` and what an exported spike segmentor
            has, for any other count, name, rank, element type or fixed
            dimension.
    """
    if len(inputs) != 1 or len(outputs) != 1:
        raise ValueError(
            f'{path}: an exported spike segmentor has one input and one '
            f'output, found {len(inputs)} and {len(outputs)}')
    spikes, logits = inputs[0], outputs[0]
    dims = list(spikes.shape or ())
    if len(dims) != 4 or not all(_fixed(d) for d in dims[1:]):
        raise ValueError(
            f'{path}: the graph input is {dims}; an exported spike '
            f'segmentor takes (batch, T, H, W) with T, H, W fixed')
    if (spikes.name, logits.name) != (INPUT, OUTPUT):
        raise ValueError(
            f'{path}: an exported spike segmentor\'s input is named '
            f'{INPUT!r} and its output {OUTPUT!r}, found {spikes.name!r} and '
            f'{logits.name!r}')
    if spikes.type not in _INPUT_TYPES:
        raise ValueError(
            f'{path}: the input {INPUT!r} holds {spikes.type}; an exported '
            f'spike segmentor takes one of {sorted(_INPUT_TYPES)}')
    out = list(logits.shape or ())  # [] where the rank is not known:
    if out and len(out) != 4:  # then each result is checked
        raise ValueError(
            f'{path}: the output {OUTPUT!r} is {out}; an exported spike '
            f'segmentor gives logits (batch, K, H, W)')
    if logits.type not in _OUTPUT_TYPES:
        raise ValueError(
            f'{path}: the output {OUTPUT!r} holds {logits.type}; logits are '
            f'one of {list(_OUTPUT_TYPES)}')
    out = out or [None] * 4
    for axis, (got, size) in enumerate(zip(out[2:], dims[2:]), 2):
        if _fixed(got) and got != size:
            raise ValueError(
                f'{path}: the output\'s dimension {axis} is {got}, not the '
                f'input\'s {size}; logits (batch, K, H, W) are at the '
                f'input\'s size')
    batch = dims[0] if _fixed(dims[0]) else None
    if batch is not None and _fixed(out[0]) and out[0] != batch:
        raise ValueError(f'{path}: a batch of {batch} windows in gives '
                         f'{out[0]} results out')
    return OnnxInterface(tuple(dims[1:]), _INPUT_TYPES[spikes.type], batch,
                         out[1] if _fixed(out[1]) else None)


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
        note_input(onnx_path)
        check_utf8_path(onnx_path, 'ONNX Runtime')
        try:
            self.session = onnxruntime.InferenceSession(
                onnx_path, options, providers=providers)
        except Exception as err:  # onnxruntime raises its own types
            raise ValueError(
                f'{onnx_path}: not a model ONNX Runtime can load '
                f'({type(err).__name__}: {str(err)[:300]})') from err
        self.path = onnx_path
        self.device = device
        self.interface = check_interface(onnx_path, self.session.get_inputs(),
                                         self.session.get_outputs())
        self.input_shape = self.interface.input_shape
        self.dataset_meta = self._read_dataset_meta()
        recorded = self.dataset_meta and len(self.dataset_meta['classes'])
        if recorded and self.interface.num_classes not in (None, recorded):
            raise ValueError(
                f'{onnx_path}: its logits have {self.interface.num_classes} '
                f'classes but its dataset_meta names {recorded}')

    @property
    def num_classes(self) -> Optional[int]:
        """``K`` of the logits where the file fixes it or records its
        classes, else ``None``."""
        return self.interface.num_classes or (
            self.dataset_meta and len(self.dataset_meta['classes']))

    def _read_dataset_meta(self) -> Optional[dict]:
        text = self.session.get_modelmeta().custom_metadata_map.get(
            'dataset_meta')
        if text is None:
            return None
        meta = parse_json(text, f'{self.path} (metadata dataset_meta)',
                          'dataset meta')
        return check_dataset_meta(f'{self.path} (metadata)', meta)

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

    def _run(self, array: np.ndarray) -> np.ndarray:
        """The graph on ``array`` ``(B, T, H, W)`` in its input dtype, in
        chunks of a fixed batch (the last padded with zeros)."""
        batch = self.interface.batch
        if batch is None:
            return self._graph(array)
        chunks = []
        for first in range(0, len(array), batch):
            chunk = array[first:first + batch]
            padded = np.zeros((batch, ) + array.shape[1:], array.dtype)
            padded[:len(chunk)] = chunk
            chunks.append(self._graph(padded)[:len(chunk)])
        return np.concatenate(chunks)

    def _graph(self, array: np.ndarray) -> np.ndarray:
        """One run of the graph; an error inside it (a model that passes
        the interface checks but fails in an operator) names the file."""
        try:
            return self.session.run(None, {INPUT: array})[0]
        except Exception as err:  # onnxruntime raises its own types
            raise ValueError(
                f'{self.path}: the model failed inside its graph on input '
                f'{array.shape} ({type(err).__name__}: {str(err)[:300]})'
            ) from err

    def __call__(self, spikes: torch.Tensor) -> torch.Tensor:
        """``(B, T, H, W)`` spikes (0 and 1, any dtype) -> ``(B, K, H, W)``
        float32 logits on the CPU."""
        self._check(spikes)
        array = np.ascontiguousarray(spikes.detach().to('cpu').numpy()
                                     .astype(self.interface.input_dtype))
        logits = self._run(array)
        expected = (len(array), self.num_classes or 'K') + \
            self.input_shape[1:]
        if logits.ndim != 4 or any(
                isinstance(e, int) and g != e
                for g, e in zip(logits.shape, expected)):
            raise ValueError(
                f'{self.path}: gave {OUTPUT} of shape {logits.shape}; an '
                f'exported spike segmentor gives (B, K, H, W) = {expected}')
        logits = logits.astype(np.float32, copy=False)
        finite = np.isfinite(logits)
        if not finite.all():
            raise ValueError(f'{self.path}: gave {int((~finite).sum())} '
                             f'non-finite logits of {logits.size}')
        return torch.from_numpy(logits)
