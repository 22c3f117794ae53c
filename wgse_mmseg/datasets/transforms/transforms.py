"""Augmentations of spike streams over all ``T`` channels at once.

The stream is ``results['img']``, ``(H, W, T)`` ``uint8`` (see
:mod:`.loading`); crops and flips move its label maps with it.
"""
from typing import Sequence, Union

import numpy as np
from mmcv.transforms import BaseTransform

from mmseg.datasets.transforms import RandomCrop
from mmseg.registry import TRANSFORMS
from ...argument_checks import (ArgumentError, check_frame_size,
                                check_integer, check_number, is_choice,
                                is_number)

__all__ = ['SpikeRandomCrop', 'SpikeRandomFlip']


def _source(results: dict) -> str:
    return results.get('img_path', '<spike stream>')


def _check_label_matches(results: dict) -> None:
    """Fail clearly when a label map's size differs from the stream's."""
    height, width = results['img'].shape[:2]
    for key in results.get('seg_fields', []):
        if results[key].shape[:2] != (height, width):
            raise ValueError(
                f'{_source(results)}: spike frames are {height}x{width} but '
                f'{key} ({results.get("seg_map_path", "label")}) is '
                f'{results[key].shape[0]}x{results[key].shape[1]}')


@TRANSFORMS.register_module()
class SpikeRandomCrop(RandomCrop):
    """Random crop of a spike stream and its label maps, over all ``T``.

    The crop box is drawn as in MMSeg's ``RandomCrop``, including
    ``cat_max_ratio`` (retry up to 10 times until no class covers more than
    that share of the crop); ``ignore_index`` pixels are not counted. Streams
    smaller than the crop are kept whole (the preprocessor pads them).

    Args:
        crop_size: ``(h, w)``, integers >= 1 (or one integer for both).
        cat_max_ratio: in ``(0, 1]``; 1 accepts every crop.
        ignore_index: label not counted for ``cat_max_ratio``.
    """

    def __init__(self, crop_size, cat_max_ratio: float = 1.,
                 ignore_index: int = 255):
        entry = 'SpikeRandomCrop'
        sizes = check_frame_size(entry, 'crop_size', crop_size, side=True)
        check_number(entry, 'cat_max_ratio', cat_max_ratio, 0, 1,
                     strict_minimum=True)
        check_integer(entry, 'ignore_index', ignore_index)
        super().__init__(sizes, cat_max_ratio, ignore_index)

    def transform(self, results: dict) -> dict:
        _check_label_matches(results)
        if self.cat_max_ratio < 1. and 'gt_seg_map' not in results:
            raise ValueError(
                f'SpikeRandomCrop: cat_max_ratio={self.cat_max_ratio} '
                f'weighs the crop by its labels, and '
                f'{results.get("img_path", "this sample")} has none '
                f'(gt_seg_map; LoadAnnotations before the crop), or set '
                f'cat_max_ratio=1')
        return super().transform(results)


#: the directions of a flip
_DIRECTIONS = ('horizontal', 'vertical')


def _one_or_two(value, accepts) -> bool:
    """``value`` is accepted, or a list or tuple of one or two accepted."""
    return accepts(value) or (isinstance(value, (list, tuple)) and
                              1 <= len(value) <= 2 and
                              all(accepts(v) for v in value))


@TRANSFORMS.register_module()
class SpikeRandomFlip(BaseTransform):
    """Flip a spike stream and its label maps, over all ``T`` channels.

    Horizontal and vertical flips are drawn independently.

    Args:
        prob: probability of each flip, or ``(p_horizontal, p_vertical)``.
        direction: ``'horizontal'``, ``'vertical'`` or both (a sequence).

    Added keys: ``flip`` (bool), ``flip_direction`` (``None``,
    ``'horizontal'``, ``'vertical'`` or ``'diagonal'`` for both, as in mmcv).
    """

    def __init__(self, prob: Union[float, Sequence[float]] = 0.5,
                 direction: Union[str, Sequence[str]] = ('horizontal',
                                                         'vertical')):
        super().__init__()
        entry = 'SpikeRandomFlip'
        if not _one_or_two(prob, lambda p: is_number(p, 0, 1)):
            raise ArgumentError(entry, 'prob', 'a probability in [0, 1], or '
                                'a sequence of one or two', prob)
        if not _one_or_two(direction,
                           lambda d: is_choice(d, _DIRECTIONS)):
            raise ArgumentError(entry, 'direction', f'one of '
                                f'{list(_DIRECTIONS)}, or a sequence of one '
                                f'or two', direction)
        directions = [direction] if isinstance(direction, str) else list(
            direction)
        probs = [prob] * len(directions) if is_number(prob) else list(prob)
        if len(probs) != len(directions):
            raise ValueError(
                f'SpikeRandomFlip: prob must be one probability or one per '
                f'direction {directions}; got {prob!r}')
        self.probs = dict(zip(directions, probs))

    def transform(self, results: dict) -> dict:
        _check_label_matches(results)
        flipped = [d for d, p in self.probs.items() if np.random.rand() < p]
        axes = {'vertical': 0, 'horizontal': 1}
        for direction in flipped:
            axis = axes[direction]
            results['img'] = np.flip(results['img'], axis=axis)
            for key in results.get('seg_fields', []):
                results[key] = np.flip(results[key], axis=axis)
        results['img'] = np.ascontiguousarray(results['img'])
        for key in results.get('seg_fields', []):
            results[key] = np.ascontiguousarray(results[key])
        results['flip'] = bool(flipped)
        results['flip_direction'] = (None if not flipped else flipped[0]
                                     if len(flipped) == 1 else 'diagonal')
        return results

    def __repr__(self):
        return f'{self.__class__.__name__}(probs={self.probs})'
