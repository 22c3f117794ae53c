"""Natural-scene statistics that NIQE and BRISQUE share.

Both measures normalise an image's local contrast (MSCN coefficients,
:func:`mscn`) and describe the coefficients, and products of neighbouring
ones, by an asymmetric generalised Gaussian distribution (AGGD) of shape
``alpha`` and left/right spreads. Each reference implementation estimates
the AGGD its own way, so each has its estimator here:
:func:`fit_aggd_grid` (NIQE: the MATLAB release, as basicsr 1.4.2 ports it)
and :func:`fit_aggd_root` (BRISQUE: the brisque 0.2.0 package).
"""
import functools
import math
from typing import NamedTuple, Optional

import cv2
import numpy as np

__all__ = []

#: ``|I - mu|`` below this (on the 0-255 scale) is rounding error: a
#: genuine difference of 8-bit levels under a 7x7 window is above 1e-5
FLAT = 1e-9
#: bracket of the shape ``alpha`` that :func:`fit_aggd_root` searches
ROOT_ALPHA_RANGE = (0.01, 100.0)


def mscn(levels: np.ndarray, window: np.ndarray, border: int) -> np.ndarray:
    """Mean-subtracted, contrast-normalised coefficients, ``(H, W)``.

    ``(I - mu) / (sigma + 1)`` for an image ``I`` on the 0-255 scale, where
    ``mu`` and ``sigma**2 = |E[I**2] - mu**2|`` are local moments weighted
    by ``window`` (odd, symmetric) and ``border`` is an OpenCV border mode
    (``cv2.BORDER_REPLICATE`` or ``cv2.BORDER_CONSTANT``, i.e. zeros).
    Where ``I - mu`` is within rounding error of 0 (:data:`FLAT`), as in a
    flat region, the coefficient is exactly 0: the reference
    implementations leave the sign of that rounding noise to their
    convolution code, and the AGGD fits count signs.
    """
    def local_mean(x):
        return cv2.filter2D(x, cv2.CV_64F, window, borderType=border)

    mu = local_mean(levels)
    sigma = np.sqrt(np.abs(local_mean(levels * levels) - mu * mu))
    centred = levels - mu
    centred[np.abs(centred) < FLAT] = 0
    return centred / (sigma + 1)


def _ggd_ratio(alpha: float) -> float:
    return math.exp(2 * math.lgamma(2 / alpha) - math.lgamma(1 / alpha)
                    - math.lgamma(3 / alpha))


def ggd_ratio(alpha):
    """``Gamma(2/a)**2 / (Gamma(1/a) Gamma(3/a))`` of a shape ``alpha > 0``
    (scalar or array): the ratio ``E|x|**2 / E[x**2]`` of a generalised
    Gaussian, increasing from 0 to 3/4."""
    if np.ndim(alpha) == 0:
        return _ggd_ratio(float(alpha))
    return np.array([_ggd_ratio(a) for a in np.asarray(alpha, np.float64)])


@functools.lru_cache(maxsize=1)
def _alpha_grid():
    """The MATLAB release's shapes 0.2, 0.201, ..., 10 and their ratios."""
    alphas = np.arange(0.2, 10.001, 0.001)
    return alphas, ggd_ratio(alphas)


class Aggd(NamedTuple):
    """An AGGD fit: shape, and left and right spreads (what the spreads
    mean depends on the estimator)."""
    alpha: float
    left: float
    right: float


def _normalised_ratio(x: np.ndarray, gamma_hat: float) -> float:
    r_hat = np.mean(np.abs(x)) ** 2 / np.mean(x * x)
    return r_hat * (gamma_hat ** 3 + 1) * (gamma_hat + 1) / (
        gamma_hat ** 2 + 1) ** 2


def fit_aggd_grid(x: np.ndarray) -> Optional[Aggd]:
    """NIQE's fit: ``alpha`` the nearest grid shape (0.2 to 10, step 0.001)
    by moment matching, ``left``/``right`` the scale parameters ``beta``
    (the standard deviations of the values below / above zero times
    ``sqrt(Gamma(1/a) / Gamma(3/a))``). ``None`` when ``x`` has no value
    below or none above zero (no AGGD to fit)."""
    x = np.asarray(x, np.float64).ravel()
    negative, positive = x[x < 0], x[x > 0]
    if negative.size == 0 or positive.size == 0:
        return None
    left_std = math.sqrt(np.mean(negative * negative))
    right_std = math.sqrt(np.mean(positive * positive))
    target = _normalised_ratio(x, left_std / right_std)
    alphas, ratios = _alpha_grid()
    alpha = float(alphas[np.argmin((ratios - target) ** 2)])
    scale = math.sqrt(math.gamma(1 / alpha) / math.gamma(3 / alpha))
    return Aggd(alpha, left_std * scale, right_std * scale)


def fit_aggd_root(x: np.ndarray) -> Optional[Aggd]:
    """BRISQUE's fit: ``alpha`` solves ``ggd_ratio(alpha) = R`` (the
    moment ratio; clamped to :data:`ROOT_ALPHA_RANGE` where no shape in it
    matches), ``left``/``right`` the root mean squares of the values below
    zero / at or above zero. ``None`` when either mean square is 0 or
    undefined (no AGGD to fit)."""
    x = np.asarray(x, np.float64).ravel()
    negative, rest = x[x < 0], x[x >= 0]
    if negative.size == 0 or not np.any(rest):
        return None
    left = math.sqrt(np.mean(negative * negative))
    right = math.sqrt(np.mean(rest * rest))
    target = _normalised_ratio(x, left / right)
    low, high = ROOT_ALPHA_RANGE
    if target <= _ggd_ratio(low):
        return Aggd(low, left, right)
    if target >= _ggd_ratio(high):
        return Aggd(high, left, right)
    for _ in range(200):  # bisection: the ratio increases with alpha
        middle = 0.5 * (low + high)
        if middle in (low, high):
            break
        if _ggd_ratio(middle) < target:
            low = middle
        else:
            high = middle
    return Aggd(0.5 * (low + high), left, right)
