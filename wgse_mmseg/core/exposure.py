"""Exposure of images made from spikes.

Images on the REDS scale (spike rate / 0.6, 1 = white) are calibrated: a
stream of normal brightness already spans black to white, and scaling it
only shifts its intensities away from the truth. A dark recording (few
spikes per pixel, e.g. 1 in 50 steps) gives an image far below white, nearly
black as 8 bits. ``'auto'`` exposure (:func:`auto_exposure`) therefore acts
only on images that are clearly under-exposed for that calibration, those
whose bright end (the ``percentile``-th value, which ignores a few hot
pixels) lies below :data:`UNDER_EXPOSED_BELOW` of white, and scales their
bright end to white; every other image passes untouched. The tools that
write images (``tools/misc/reconstruct.py``, ``tools/demo.py``) apply it by
default, say what it did and why, and take ``--exposure none`` or a fixed
gain instead.
"""
from typing import NamedTuple, Tuple, Union

import numpy as np

from ..argument_checks import (EXPOSURE_CHOICES, ArgumentError,
                               check_number, is_choice, is_number)

__all__ = ['apply_exposure']

#: ``'auto'`` brightens an image only when its bright end is below this
#: fraction of white, i.e. when it would need a gain above 4. Calibrated
#: streams of normal brightness sit far above it (the REDS streams' 99.5th
#: percentile of TFP is 0.73-0.85); dark real recordings far below (the UHSR
#: helicopter's is 0.12, a stream of 1 spike in 50 steps about 0.03-0.16).
UNDER_EXPOSED_BELOW = 0.25

Exposure = Union[str, float]


class Exposed(NamedTuple):
    """What :func:`apply_exposure` returns."""

    #: ``(H, W)`` float32 image in ``[0, 1]``
    image: np.ndarray
    #: the gain applied
    gain: float
    #: one sentence saying what was done and why
    reason: str


def _bright_end(image: np.ndarray, percentile: float) -> float:
    values = np.asarray(image, dtype=np.float64)
    if values.size == 0 or not np.isfinite(values).all():
        raise ValueError(f'exposure needs a non-empty, finite image; got '
                         f'shape {values.shape} with '
                         f'{np.size(values) - np.isfinite(values).sum()} '
                         f'non-finite values')
    return float(np.percentile(values, percentile))


def auto_exposure(image: np.ndarray, percentile: float = 99.5,
                  max_gain: float = 64.0,
                  under_exposed_below: float = UNDER_EXPOSED_BELOW
                  ) -> Tuple[float, str]:
    """The gain ``'auto'`` exposure gives ``image``, and why.

    Args:
        image: ``(H, W)`` non-negative intensities, 1 = white.
        percentile: in ``(0, 100]``; below 100 so that hot pixels do not set
            the exposure.
        max_gain: an under-exposed image gets at most this gain (>= 1); one
            that is black at ``percentile`` but not everywhere gets it.
        under_exposed_below: in ``(0, 1]``; an image whose bright end is at
            or above this fraction of white is left as it is (gain 1).

    Returns:
        ``(gain, reason)``: a gain >= 1, and one sentence saying why.
    """
    check_number('auto_exposure', 'percentile', percentile, 0, 100,
                 strict_minimum=True)
    check_number('auto_exposure', 'max_gain', max_gain, 1)
    check_number('auto_exposure', 'under_exposed_below', under_exposed_below,
                 0, 1, strict_minimum=True)
    bright = _bright_end(image, percentile)
    where = f'bright end ({percentile:g}th percentile) {bright:.3g} of white'
    if bright >= under_exposed_below:
        return 1.0, (f'{where} >= {under_exposed_below:g}: normal brightness,'
                     f' left as it is')
    if bright <= 0:
        if np.max(image) <= 0:
            return 1.0, f'{where}: black everywhere, left as it is'
        return float(max_gain), (f'{where}: under-exposed (< '
                                 f'{under_exposed_below:g}), the largest '
                                 f'gain {max_gain:g} applied')
    gain = min(1.0 / bright, float(max_gain))
    return gain, (f'{where} < {under_exposed_below:g}: under-exposed, gain '
                  f'{gain:.3g} brings it to white')


def exposure_gain(image: np.ndarray, **kwargs) -> float:
    """The gain of :func:`auto_exposure` (same arguments), without the
    reason."""
    return auto_exposure(image, **kwargs)[0]


def apply_exposure(image: np.ndarray, exposure: Exposure = 'auto') -> Exposed:
    """``image`` times a gain, clipped to ``[0, 1]``.

    Args:
        image: ``(H, W)`` non-negative intensities, 1 = white.
        exposure: ``'auto'`` (only a clearly under-exposed image is
            brightened: its 99.5th percentile to white), ``'none'`` (gain 1) or
            a positive gain.

    Returns:
        The ``(H, W)`` float32 image in ``[0, 1]`` (``image``), the gain
        applied (``gain``) and the reason (``reason``), as a named tuple.
    """
    if not (is_choice(exposure, EXPOSURE_CHOICES) or
            is_number(exposure, 0, strict_minimum=True)):
        raise ArgumentError('apply_exposure', 'exposure',
                            "'auto', 'none' or a finite number > 0",
                            exposure)
    if exposure == 'auto':
        gain, reason = auto_exposure(image)
    elif exposure == 'none':
        gain, reason = 1.0, 'exposure none: left as it is'
    else:
        gain = float(exposure)
        reason = f'fixed gain {gain:g}'
    scaled = np.clip(np.asarray(image, dtype=np.float32) * gain, 0, 1)
    return Exposed(scaled, gain, reason)
