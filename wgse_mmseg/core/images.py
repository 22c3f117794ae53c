"""The grey images the image-quality measures take.

Every measure takes an ``(H, W)`` array: ``uint8`` (read as ``value / 255``)
or any real dtype with 1 = white. No-reference measures score an image as it
is shown, i.e. as 8 bits (:func:`as_grey_levels`).
"""
import numpy as np

__all__ = ['as_unit_grey', 'as_grey_levels']


def as_unit_grey(image, name: str = 'image') -> np.ndarray:
    """``image`` as an ``(H, W)`` float64 array, 1 = white.

    Raises ``ValueError`` naming ``name`` for anything but a non-empty,
    finite, real ``(H, W)`` array.
    """
    array = np.asarray(image)
    if array.ndim != 2 or array.size == 0:
        raise ValueError(f'{name} must be a non-empty (H, W) image, got '
                         f'shape {array.shape}')
    if not (array.dtype == np.bool_ or np.issubdtype(array.dtype, np.integer)
            or np.issubdtype(array.dtype, np.floating)):
        raise ValueError(f'{name} must hold real numbers, got dtype '
                         f'{array.dtype}')
    if array.dtype == np.uint8:
        return array.astype(np.float64) / 255.0
    values = array.astype(np.float64)
    if not np.isfinite(values).all():
        raise ValueError(f'{name} holds {int((~np.isfinite(values)).sum())} '
                         f'non-finite value(s) of {values.size}')
    return values


def as_grey_levels(image, name: str = 'image') -> np.ndarray:
    """``image`` as shown in 8 bits: ``(H, W)`` float64 integers in
    ``[0, 255]`` (rounded, clipped)."""
    return np.clip(np.round(as_unit_grey(image, name) * 255), 0, 255)
