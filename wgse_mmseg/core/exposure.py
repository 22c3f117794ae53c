"""Exposure normalisation of images made from spikes.

A dark recording (few spikes per pixel) gives an image far below white on
the REDS scale (spike rate / 0.6), nearly black as 8 bits. :func:`apply_exposure`
scales an image so that its bright end (the ``percentile``-th value, which
ignores a few hot pixels) becomes white, and says by how much; the tools
that write images (``tools/misc/reconstruct.py``, ``tools/demo.py``) do it by
default and take ``--exposure none`` or a fixed gain instead.
"""
from typing import Tuple, Union

import numpy as np

__all__ = ['EXPOSURE_CHOICES', 'exposure_gain', 'apply_exposure',
           'parse_exposure']

#: the non-numeric values of an ``exposure`` argument
EXPOSURE_CHOICES = ('auto', 'none')

Exposure = Union[str, float]


def exposure_gain(image: np.ndarray, percentile: float = 99.5,
                  max_gain: float = 64.0) -> float:
    """The gain that maps the ``percentile``-th value of ``image`` to 1.

    Args:
        image: ``(H, W)`` non-negative intensities, 1 = white.
        percentile: in ``(0, 100]``; below 100 so that hot pixels do not set
            the exposure.
        max_gain: the gain is limited to ``[1 / max_gain, max_gain]``. An
            image that is black at ``percentile`` but not everywhere gets
            ``max_gain``; one that is black everywhere gets 1.

    Returns:
        The gain, a positive float.
    """
    values = np.asarray(image, dtype=np.float64)
    if values.size == 0 or not np.isfinite(values).all():
        raise ValueError(f'exposure needs a non-empty, finite image; got '
                         f'shape {values.shape} with '
                         f'{np.size(values) - np.isfinite(values).sum()} '
                         f'non-finite values')
    if not 0 < percentile <= 100 or max_gain < 1:
        raise ValueError(f'percentile must be in (0, 100] and max_gain >= 1;'
                         f' got {percentile}, {max_gain}')
    bright = float(np.percentile(values, percentile))
    if bright <= 0:
        return 1.0 if values.max() <= 0 else float(max_gain)
    return float(np.clip(1.0 / bright, 1.0 / max_gain, max_gain))


def apply_exposure(image: np.ndarray,
                   exposure: Exposure = 'auto') -> Tuple[np.ndarray, float]:
    """``image`` times a gain, clipped to ``[0, 1]``.

    Args:
        image: ``(H, W)`` non-negative intensities, 1 = white.
        exposure: ``'auto'`` (:func:`exposure_gain`), ``'none'`` (gain 1) or
            a positive gain.

    Returns:
        ``(H, W)`` float32 image in ``[0, 1]`` and the gain applied.
    """
    if isinstance(exposure, str):
        if exposure not in EXPOSURE_CHOICES:
            raise ValueError(f'exposure must be one of {EXPOSURE_CHOICES} '
                             f'or a positive gain, got {exposure!r}')
        gain = exposure_gain(image) if exposure == 'auto' else 1.0
    else:
        gain = float(exposure)
        if not np.isfinite(gain) or gain <= 0:
            raise ValueError(f'exposure gain must be positive and finite, '
                             f'got {exposure!r}')
    scaled = np.clip(np.asarray(image, dtype=np.float32) * gain, 0, 1)
    return scaled, gain


def parse_exposure(text: str) -> Exposure:
    """A command line's ``--exposure``: ``auto``, ``none`` or a gain > 0."""
    if text in EXPOSURE_CHOICES:
        return text
    try:
        gain = float(text)
    except ValueError:
        gain = float('nan')
    if not np.isfinite(gain) or gain <= 0:
        raise ValueError(f'--exposure must be auto, none or a positive gain, '
                         f'got {text!r}')
    return gain
