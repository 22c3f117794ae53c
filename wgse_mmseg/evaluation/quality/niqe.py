"""NIQE, the Natural Image Quality Evaluator (Mittal et al., 2013).

A no-reference measure: the distance between a multivariate Gaussian fitted
to an image's natural-scene features (per 96x96 block, at full and half
size) and the one fitted to pristine photographs. Lower is better (more
natural). This follows the authors' MATLAB release as basicsr 1.4.2's
``calculate_niqe`` ports it (its pristine model, shipped in ``data/``; grey
image, no border crop, 96x96 blocks without overlap, MATLAB's bicubic
``imresize`` for the half size) and matches it within 0.002 on
scikit-image's photographs (``tests/core/test_quality.py``).
"""
import math

import cv2
import numpy as np

from ...core.image_values import as_grey_levels
from .model_data import niqe_model
from .natural_scene import fit_aggd_grid, mscn

__all__ = []

#: the side of NIQE's square blocks, in pixels of the full-size image
BLOCK = 96
#: the most memory :func:`niqe` allocates per pixel of its image
#: (measured: 43 to 48 from 768x768 to 1536x1536)
BYTES_PER_PIXEL = 56
#: MATLAB's bicubic kernel (a = -0.5) stretched to halve: the weights of
#: the 8 input pixels at distances 3.5, 2.5, 1.5, 0.5 on either side of an
#: output pixel's centre, summing to 1
_HALF_TAPS = np.array([
    0.5 * (1.5 * d ** 3 - 2.5 * d ** 2 + 1) if d <= 1 else
    0.5 * (-0.5 * d ** 3 + 2.5 * d ** 2 - 4 * d + 2)
    for d in (1.75, 1.25, 0.75, 0.25, 0.25, 0.75, 1.25, 1.75)])
_HALF_TAPS /= _HALF_TAPS.sum()


def matlab_half_size(image: np.ndarray) -> np.ndarray:
    """MATLAB's ``imresize(image, 0.5)`` (bicubic, antialiased) of an
    ``(H, W)`` float image of even sides: ``(H/2, W/2)``, mirrored at the
    border as MATLAB does."""
    for axis in (0, 1):
        padded = np.pad(image, [(3, 3) if a == axis else (0, 0)
                                for a in (0, 1)], mode='symmetric')
        size = image.shape[axis] // 2
        image = sum(weight * np.take(padded, np.arange(size) * 2 + tap,
                                     axis=axis)
                    for tap, weight in enumerate(_HALF_TAPS))
    return image


def _block_features(block: np.ndarray):
    """The 18 features of one block of MSCN coefficients, or ``None``
    where it has no texture (an AGGD cannot be fitted)."""
    fit = fit_aggd_grid(block)
    if fit is None:
        return None
    features = [fit.alpha, (fit.left + fit.right) / 2]
    for shift in ((0, 1), (1, 0), (1, 1), (1, -1)):
        fit = fit_aggd_grid(block * np.roll(block, shift, axis=(0, 1)))
        if fit is None:
            return None
        mean = (fit.right - fit.left) * math.gamma(2 / fit.alpha) / \
            math.gamma(1 / fit.alpha)
        features += [fit.alpha, mean, fit.left, fit.right]
    return features


def niqe(image) -> float:
    """NIQE score of an ``(H, W)`` grey image (any kind
    :mod:`wgse_mmseg.core.image_values` accepts; scored as 8 bits). Lower is
    better; photographs score about 3-6. Memory: at most
    :data:`BYTES_PER_PIXEL` bytes per pixel (the float64 local moments of
    the whole image).

    The image is cropped to whole 96x96 blocks (top left). Raises
    ``ValueError`` for an image with fewer than two blocks (smaller than
    96x192 either way) or fewer than two blocks with texture (a flat image
    has no natural-scene statistics); blocks without texture are left out
    as in the reference.
    """
    levels = as_grey_levels(image).astype(np.float64)
    height, width = levels.shape
    rows, cols = height // BLOCK, width // BLOCK
    if rows * cols < 2:
        raise ValueError(f'NIQE needs an image of at least two {BLOCK}x'
                         f'{BLOCK} blocks (e.g. {BLOCK}x{2 * BLOCK}); got '
                         f'{height}x{width}')
    model = niqe_model()
    levels = levels[:rows * BLOCK, :cols * BLOCK]
    features = [[] for _ in range(rows * cols)]
    for scale in (1, 2):
        coefficients = mscn(levels, model.window, cv2.BORDER_REPLICATE)
        side = BLOCK // scale
        for index in range(rows * cols):
            row, col = divmod(index, cols)
            block = coefficients[row * side:(row + 1) * side,
                                 col * side:(col + 1) * side]
            if features[index] is not None:
                found = _block_features(block)
                features[index] = None if found is None else \
                    features[index] + found
        levels = matlab_half_size(levels)
    textured = np.array([f for f in features if f is not None])
    if len(textured) < 2:
        raise ValueError(f'NIQE needs at least two {BLOCK}x{BLOCK} blocks '
                         f'with texture; {len(textured)} of the image\'s '
                         f'{rows * cols} have any (a flat image has no '
                         f'natural-scene statistics)')
    difference = model.mean - textured.mean(axis=0)
    covariance = (model.covariance + np.cov(textured, rowvar=False)) / 2
    distance = difference @ np.linalg.pinv(covariance) @ difference
    return float(math.sqrt(max(distance, 0.0)))
