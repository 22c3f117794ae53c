"""BRISQUE, the Blind/Referenceless Image Spatial Quality Evaluator
(Mittal et al., 2012).

A no-reference measure: 36 natural-scene features (AGGD fits of the MSCN
coefficients and of their horizontal, vertical and diagonal neighbour
products, at full and half size) mapped by a support-vector regression
trained on human opinion scores. Lower is better; the scale is roughly
0-100, and very clean images can score below 0. This follows the brisque
0.2.0 package (its features, its trained model, shipped in ``data/``) and
matches it within 0.01 on scikit-image's photographs
(``tests/core/test_quality.py``). Scores of other BRISQUE implementations
(MATLAB's, piq's, pyiqa's) use other models and differ.
"""
import math
from typing import List

import cv2
import numpy as np

from ...core.image_values import as_grey_levels
from .model_data import brisque_model
from .natural_scene import fit_aggd_root, mscn

__all__ = []

#: the smallest side BRISQUE takes: the 7x7 window fits the half size
MIN_SIDE = 14
#: the most memory :func:`brisque` allocates per pixel of its image
#: (measured: 66 from 768x768 to 1536x1536)
BYTES_PER_PIXEL = 72
#: brisque 0.2.0's local-moment weights: a 7x7 Gaussian of sigma 7/6
_Y, _X = np.indices((7, 7)) - 3
_WINDOW = np.exp(-(_X ** 2 + _Y ** 2) / (2 * (7 / 6) ** 2))
_WINDOW /= _WINDOW.sum()


def _mean_factor(alpha: float) -> float:
    """``sqrt(G(1/a) / G(3/a)) G(2/a) / G(1/a)``: an AGGD's mean per unit
    of ``right - left`` root mean square."""
    return math.exp(0.5 * (math.lgamma(1 / alpha) - math.lgamma(3 / alpha))
                    + math.lgamma(2 / alpha) - math.lgamma(1 / alpha))


def _scale_features(levels: np.ndarray) -> List[float]:
    """The 18 features at one scale of an image on the 0-255 scale."""
    m = mscn(levels, _WINDOW, cv2.BORDER_CONSTANT)
    coefficients = [m, m[:, :-1] * m[:, 1:], m[:-1, :] * m[1:, :],
                    m[:-1, :-1] * m[1:, 1:], m[1:, :-1] * m[:-1, 1:]]
    features = []
    for index, values in enumerate(coefficients):
        fit = fit_aggd_root(values)
        if fit is None:
            raise ValueError('BRISQUE is undefined for an image without '
                             'texture (its contrast-normalised '
                             'coefficients have no spread to fit)')
        if index == 0:
            features += [fit.alpha, (fit.left ** 2 + fit.right ** 2) / 2]
        else:
            mean = (fit.right - fit.left) * _mean_factor(fit.alpha)
            features += [fit.alpha, mean, fit.left ** 2, fit.right ** 2]
    return features


def brisque(image) -> float:
    """BRISQUE score of an ``(H, W)`` grey image (any kind
    :mod:`wgse_mmseg.core.image_values` accepts; scored as 8 bits). Lower is
    better. Memory: at most :data:`BYTES_PER_PIXEL` bytes per pixel (the
    float64 coefficients of the whole image and their four neighbour
    products).

    Raises ``ValueError`` for an image with a side below :data:`MIN_SIDE`
    or without texture (flat).
    """
    levels = as_grey_levels(image).astype(np.float64)
    if min(levels.shape) < MIN_SIDE:
        raise ValueError(f'BRISQUE needs an image of at least {MIN_SIDE}x'
                         f'{MIN_SIDE}; got {levels.shape[0]}x'
                         f'{levels.shape[1]}')
    half = cv2.resize(levels, None, fx=0.5, fy=0.5,
                      interpolation=cv2.INTER_CUBIC)
    features = np.array(_scale_features(levels) + _scale_features(half))
    model = brisque_model()
    scaled = -1 + 2.0 / (model.feature_max - model.feature_min) * (
        features - model.feature_min)
    kernel = np.exp(-model.gamma * ((model.support_vectors - scaled) ** 2
                                    ).sum(axis=1))
    return float(model.dual_coef @ kernel - model.rho)
