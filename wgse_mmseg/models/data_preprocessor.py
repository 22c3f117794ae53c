"""Batching of spike streams for MMSeg segmentors."""
from typing import Any, Dict, List, Optional, Sequence, Tuple

import torch

from mmseg.models.data_preprocessor import SegDataPreProcessor
from mmseg.registry import MODELS
from ..argument_checks import (ArgumentError, check_choice,
                               check_frame_size, check_integer)
from ..limits import MAX_CLASSES, MAX_IMAGE_SIDE
from ..errors import WgseError

__all__ = ['SpikeSegDataPreProcessor', 'SpikeModelMismatchError']

#: the state-dict key of the preprocessor's record, under its prefix
RECORD_KEY = '_extra_state'


class SpikeModelMismatchError(WgseError, ValueError):
    """Weights made for another T or enhancer than the model's."""


def unfit_weights(source: str, num_steps: Optional[int],
                  err: Exception) -> SpikeModelMismatchError:
    """The one message for weights that do not fit a spike model's
    shapes (weights saved without a record of their T): what the loader
    said, after what to change."""
    return SpikeModelMismatchError(
        f'{source}: does not fit the model built from the config '
        f'(num_steps={num_steps}; weights trained with another T need '
        f'--cfg-options num_steps=T, from Python wgse_mmseg.load_config('
        f"config, {{'num_steps': T}})): {err}")


def encode_record(num_steps: Optional[int],
                  enhancer: Optional[str]) -> torch.Tensor:
    """T and the enhancer's class name as one int64 tensor (a state dict
    holds tensors): ``[T or -1, *name's bytes]``."""
    name = (enhancer or '').encode('ascii', 'replace')
    return torch.tensor([-1 if num_steps is None else num_steps, *name],
                        dtype=torch.int64)


def decode_record(record: Any) -> Optional[Tuple[Optional[int], str]]:
    """``(T or None, enhancer name or '')`` of a record, ``None`` for no
    record (a checkpoint made before records, or not a record)."""
    if not isinstance(record, torch.Tensor) or record.dim() != 1 or \
            record.numel() < 1 or record.numel() > 257 or \
            record.dtype != torch.int64:
        return None
    values = record.tolist()
    if not all(0 <= v < 128 for v in values[1:]) or values[0] < -1:
        return None
    return (None if values[0] == -1 else values[0],
            bytes(values[1:]).decode('ascii'))


def _source(data_samples: Optional[list], index: int) -> str:
    """The file of sample ``index``, for error messages."""
    if data_samples is not None and 'img_path' in data_samples[index]:
        return data_samples[index].img_path
    return f'sample {index}'


@MODELS.register_module()
class SpikeSegDataPreProcessor(SegDataPreProcessor):
    """Batch ``T``-channel spike tensors and optionally enhance them.

    Takes the packed samples of ``PackSegInputs`` (each ``(T, H, W)``, binary
    ``uint8``/``bool``), casts them to float, pads them like
    :class:`mmseg.models.SegDataPreProcessor` (spikes with ``pad_val``, i.e.
    no spike; labels with ``seg_pad_val``, the ignore index) and stacks them
    into ``(B, T, H, W)``. If ``enhancer`` is given (for example
    ``dict(type='WGSE')``), its output ``(B, C, H, W)`` is what the backbone
    receives, whatever segmentor holds this preprocessor (MMSeg's
    ``EncoderDecoder``, ``CascadeEncoderDecoder``, ...): the enhancer is a
    module of the model (parameters ``data_preprocessor.enhancer.*``) and
    runs here and nowhere else. Its parameters train with the model: mmengine
    calls the preprocessor inside ``train_step`` (also
    ``MMDistributedDataParallel``'s, whose gradient averaging covers every
    parameter the loss depends on), so the loss backpropagates into it.
    What measures only the model's forward (mmengine's
    ``get_model_complexity_info``) leaves the enhancer out; the project's
    benchmark (``wgse_bench.segmentation.count_flops``) counts it on its own
    and adds it.

    Args:
        num_steps: the ``T`` the model is built for (the backbone's
            ``in_channels``); a batch with another ``T`` fails at once with a
            message naming both numbers and the file. ``None`` skips the
            check.
        enhancer: config of a registered module mapping ``(B, T, H, W)`` to
            ``(B, C, H, W)``.
        num_classes: when given, every label map must hold only
            ``0 .. num_classes - 1`` and ``seg_pad_val`` (the ignore index);
            another value fails at once, naming the label file and the
            values, instead of deep inside the loss.
        size, size_divisor, pad_val, seg_pad_val, batch_augments, test_cfg:
            as in ``SegDataPreProcessor``. No mean/std normalisation and no
            colour conversion: spikes have neither.

    Every input must hold only 0 and 1 (any dtype); another value (NaN, a
    grey level, a negative) fails naming the file.

    Its state dict records the model's T and enhancer
    (``data_preprocessor._extra_state``), so weights made for another T
    or enhancer are refused when they are loaded, by every loader
    (``load_state_dict``, mmengine's ``load_checkpoint``, MMSeg's
    ``init_model``, the tools), with a :class:`SpikeModelMismatchError`
    naming both, instead of loading around a mismatched stem. Weights
    without a record (saved before it existed) load as before.
    """

    def __init__(self,
                 num_steps: Optional[int] = None,
                 enhancer: Optional[dict] = None,
                 num_classes: Optional[int] = None,
                 size: Optional[Sequence[int]] = None,
                 size_divisor: Optional[int] = None,
                 pad_val: float = 0,
                 seg_pad_val: int = 255,
                 batch_augments: Optional[List[dict]] = None,
                 test_cfg: Optional[dict] = None):
        entry = 'SpikeSegDataPreProcessor'
        check_integer(entry, 'num_steps', num_steps, 1, optional=True)
        if enhancer is not None and not isinstance(enhancer, dict):
            raise ArgumentError(entry, 'enhancer', "a model config (a dict "
                                "with 'type') or None", enhancer)
        check_integer(entry, 'num_classes', num_classes, 1, MAX_CLASSES,
                      optional=True)
        if size is not None:
            check_frame_size(entry, 'size', size)
        check_integer(entry, 'size_divisor', size_divisor, 1, MAX_IMAGE_SIDE,
                      optional=True)
        check_choice(entry, 'pad_val', pad_val, (0, 1, 0.0, 1.0))
        check_integer(entry, 'seg_pad_val', seg_pad_val, 0, 255)
        super().__init__(
            mean=None,
            std=None,
            size=size,
            size_divisor=size_divisor,
            pad_val=pad_val,
            seg_pad_val=seg_pad_val,
            bgr_to_rgb=False,
            rgb_to_bgr=False,
            batch_augments=batch_augments,
            test_cfg=test_cfg)
        self.num_steps = num_steps
        self.num_classes = num_classes
        self.enhancer = MODELS.build(enhancer) if enhancer else None
        self._register_load_state_dict_pre_hook(self._record_or_none)

    def _enhancer_name(self) -> str:
        return '' if self.enhancer is None else type(self.enhancer).__name__

    def get_extra_state(self) -> torch.Tensor:
        """The record of T and the enhancer (:func:`encode_record`)."""
        return encode_record(self.num_steps, self._enhancer_name())

    @staticmethod
    def _record_or_none(state_dict, prefix, *args) -> None:
        """Weights without a record load as before: an empty record."""
        state_dict.setdefault(prefix + RECORD_KEY,
                              torch.empty(0, dtype=torch.int64))

    def set_extra_state(self, state: Any) -> None:
        """Refuse weights whose record names another T or enhancer.

        Raises:
            SpikeModelMismatchError: naming both and the setting to change.
        """
        record = decode_record(state)
        if record is None:
            return
        num_steps, enhancer = record
        ours = self._enhancer_name()
        if num_steps is not None and self.num_steps is not None and \
                num_steps != self.num_steps:
            raise SpikeModelMismatchError(
                f'the weights were trained with num_steps={num_steps}, the '
                f'model is built for num_steps={self.num_steps}: load them '
                f'into a model of the same T (--cfg-options num_steps='
                f'{num_steps}; from Python wgse_mmseg.load_config(config, '
                f"{{'num_steps': {num_steps}}}))")
        if enhancer != ours:
            raise SpikeModelMismatchError(
                f'the weights were trained with enhancer '
                f'{enhancer or "None"}, the model has {ours or "None"} '
                f'(model.data_preprocessor.enhancer): use the config they '
                f'were trained with')

    def _check_num_steps(self, inputs: Sequence[torch.Tensor],
                         data_samples: Optional[list]) -> None:
        if self.num_steps is None:  # then one T for the whole batch
            for index, spikes in enumerate(inputs):
                if spikes.dim() != 3 or spikes.shape[0] != inputs[0].shape[0]:
                    raise ValueError(
                        f'{_source(data_samples, index)}: spike stream '
                        f'shaped {tuple(spikes.shape)} in a batch whose '
                        f'first, {_source(data_samples, 0)}, is '
                        f'{tuple(inputs[0].shape)}; a batch holds (T, H, W) '
                        f'windows of one T (set num_steps in the config)')
            return
        for index, spikes in enumerate(inputs):
            if spikes.dim() != 3 or spikes.shape[0] != self.num_steps:
                source = _source(data_samples, index)
                found = (f'T={spikes.shape[0]}' if spikes.dim() == 3 else
                         f'shape {tuple(spikes.shape)}')
                raise ValueError(
                    f'{source}: spike stream has {found} but the model is '
                    f'built for T={self.num_steps} '
                    f'(model.data_preprocessor.num_steps, which must equal '
                    f'model.backbone.in_channels); set num_steps in the '
                    f'config, e.g. --cfg-options num_steps='
                    f'{spikes.shape[0] if spikes.dim() == 3 else "T"}')

    @staticmethod
    def _check_values(inputs: Sequence[torch.Tensor],
                      data_samples: Optional[list]) -> None:
        """Every input holds spikes: 0 or 1, nothing else (no NaN)."""
        for index, spikes in enumerate(inputs):
            if 0 in spikes.shape:
                raise ValueError(
                    f'{_source(data_samples, index)}: empty spike stream, '
                    f'shape {tuple(spikes.shape)}')
            if spikes.dtype == torch.bool:
                continue
            if not spikes.is_floating_point():
                # integers: one reduction, not an elementwise pass per step
                low, high = torch.aminmax(spikes)
                if low >= 0 and high <= 1:
                    continue
            bad = (spikes != 0) & (spikes != 1)
            if bad.any():
                values = spikes[bad].unique()[:5].tolist()
                raise ValueError(
                    f'{_source(data_samples, index)}: a spike stream holds '
                    f'only 0 and 1, found {values} ({spikes.dtype})')

    def _check_labels(self, inputs: Sequence[torch.Tensor],
                      data_samples: Optional[list], training: bool) -> None:
        """Labels in range; in training also of the stream's size (a test
        pipeline may resize the stream and keep labels at full size)."""
        if not data_samples:
            return
        for spikes, sample in zip(inputs, data_samples):
            if 'gt_sem_seg' not in sample:
                continue
            labels = sample.gt_sem_seg.data
            if training and labels.shape[-2:] != spikes.shape[-2:]:
                raise ValueError(
                    f'{sample.get("seg_map_path", "a label map")}: label '
                    f'map is {tuple(labels.shape[-2:])} but its spike '
                    f'stream {sample.get("img_path", "")} is '
                    f'{tuple(spikes.shape[-2:])} (H, W)')
            if self.num_classes is None:
                continue
            bad = ((labels < 0) | (labels >= self.num_classes) |
                   (labels != labels.round())) & (labels != self.seg_pad_val)
            if bad.any():
                values = labels[bad].unique().tolist()
                raise ValueError(
                    f'{sample.get("seg_map_path", "a label map")}: label '
                    f'values {values[:10]} are outside the '
                    f'{self.num_classes} classes (0..{self.num_classes - 1})'
                    f' and the ignore index {self.seg_pad_val}; Cityscapes '
                    f'labels must be train ids (*_labelTrainIds.png), not '
                    f'label ids')

    def forward(self, data: dict, training: bool = False) -> Dict[str, Any]:
        """``data['inputs']``: list of ``(T, H, W)``; returns
        ``(B, C, H, W)``."""
        self._check_num_steps(data['inputs'], data.get('data_samples'))
        self._check_values(data['inputs'], data.get('data_samples'))
        self._check_labels(data['inputs'], data.get('data_samples'),
                           training)
        if training and self.size is None and self.size_divisor is None:
            raise ValueError(
                'SpikeSegDataPreProcessor needs size (H, W) or size_divisor '
                'to stack a training batch (the configs set size to '
                'crop_size)')
        data = super().forward(data, training)
        if self.enhancer is not None:
            data['inputs'] = self.enhancer(data['inputs'])
        return data
