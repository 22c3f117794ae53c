"""Grey images: the one place an image array is given its meaning.

Every image the package measures goes through here, so that each
kind keeps its meaning (1 = white) or is refused with a clear error:

* ``bool``: ``False``/``True`` -> 0/1;
* ``uint8``: ``value / 255``; ``uint16`` (16-bit PNG/TIFF): ``value /
  65535``;
* float: the value itself, which must be finite and in ``[0, 1]``;
* anything else (signed or wider integers, whose white is unknown;
  complex; strings) is refused.

:func:`as_unit_grey` gives an ``(H, W)`` float64 array (the full-reference
measures, 8 bytes per pixel); :func:`as_grey_levels` the image as shown in
8 bits, ``uint8`` (the no-reference measures), converted by blocks of rows
so that it needs 1 byte per pixel plus a fixed
:data:`BLOCK_PIXELS`-sized working set.
:func:`fit_within` scales an image down to a bound, never to 0 pixels.
Image files are :mod:`wgse_mmseg.fileio.images`'.
"""
from typing import Iterator, Tuple

import numpy as np

#: ``cv2.INTER_AREA``, without importing OpenCV where no image is scaled
INTER_AREA = 3


__all__ = []


#: pixels per block of rows a conversion or a measure works on at once
BLOCK_PIXELS = 1 << 16


#: integer dtypes with a known white
_WHITE = {np.dtype(np.uint8): 255, np.dtype(np.uint16): 65535}


def row_blocks(height: int, width: int) -> Iterator[Tuple[int, int]]:
    """``(first, stop)`` row ranges of about :data:`BLOCK_PIXELS` pixels
    covering ``height`` rows of ``width`` pixels."""
    rows = max(1, BLOCK_PIXELS // max(1, width))
    for first in range(0, height, rows):
        yield first, min(height, first + rows)


def full_scale(dtype, name: str) -> int:
    """The value of white in an image of ``dtype``: 255 (``uint8``),
    65535 (``uint16``), 1 (``bool``, float).

    Raises:
        ValueError: naming ``name``, for any other dtype (its white is not
            known).
    """
    dtype = np.dtype(dtype)
    if dtype in _WHITE:
        return _WHITE[dtype]
    if dtype == np.bool_ or np.issubdtype(dtype, np.floating):
        return 1
    raise ValueError(
        f'{name} must be a bool, uint8 (0-255), uint16 (0-65535) or '
        f'float (0-1) image, got dtype {dtype} (its white is not known: '
        f'scale it to one of these)')


def check_unit_range(values: np.ndarray, name: str) -> None:
    """Refuse float ``values`` that are not finite or not in [0, 1]
    (``ValueError`` naming ``name`` and the range found)."""
    bad = ~np.isfinite(values)
    if bad.any():
        raise ValueError(f'{name}: a float image must lie in [0, 1] (1 = '
                         f'white), found {int(bad.sum())} non-finite '
                         f'value(s)')
    low, high = float(values.min()), float(values.max())
    if low < 0 or high > 1:
        raise ValueError(
            f'{name}: a float image must lie in [0, 1] (1 = white), found '
            f'values in [{low:.6g}, {high:.6g}]; clip or rescale it')


def _checked(image, name: str) -> np.ndarray:
    """``image`` as an ``(H, W)`` array of an accepted kind (not yet
    converted)."""
    array = np.asarray(image)
    if array.ndim != 2 or array.size == 0:
        raise ValueError(f'{name} must be a non-empty (H, W) image, got '
                         f'shape {array.shape}')
    full_scale(array.dtype, name)
    return array


def _unit_block(block: np.ndarray, name: str) -> np.ndarray:
    """A block of rows of a :func:`_checked` image as float64, 1 = white;
    float values are checked to be finite and in [0, 1]."""
    values = block.astype(np.float64)
    if np.issubdtype(block.dtype, np.floating):
        check_unit_range(values, name)
    return values / full_scale(block.dtype, name)


def as_unit_grey(image, name: str = 'image') -> np.ndarray:
    """``image`` as an ``(H, W)`` float64 array in [0, 1], 1 = white.

    Raises ``ValueError`` naming ``name`` for anything but a non-empty
    ``(H, W)`` image of an accepted kind (module docstring).
    """
    return _unit_block(_checked(image, name), name)


def as_grey_levels(image, name: str = 'image') -> np.ndarray:
    """``image`` as shown in 8 bits: ``(H, W)`` ``uint8``, ``round(255 *
    value)`` of :func:`as_unit_grey`'s value (a ``uint8`` image as it is).

    Converted by :func:`row_blocks`: 1 byte per pixel for the result plus
    a working set of about ``24 * BLOCK_PIXELS`` bytes.
    """
    array = _checked(image, name)
    if array.dtype == np.uint8:
        return array
    levels = np.empty(array.shape, np.uint8)
    for first, stop in row_blocks(*array.shape):
        levels[first:stop] = np.round(
            _unit_block(array[first:stop], name) * 255)
    return levels


def fit_within(image: np.ndarray, max_side: int,
               interpolation: int = INTER_AREA) -> np.ndarray:
    """``image`` ``(H, W[, C])`` scaled down by one factor so that neither
    side exceeds ``max_side``, each side at least 1 pixel (a 100000x1
    image does not become 0 pixels wide); as it is where it fits."""
    height, width = image.shape[:2]
    scale = max_side / max(height, width)
    if scale >= 1:
        return image
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    import cv2
    return cv2.resize(image, size, interpolation=interpolation)
