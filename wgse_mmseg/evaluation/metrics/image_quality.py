"""Image quality measures for reconstructed grey images.

Full-reference (against ground truth): :func:`psnr` and :func:`ssim`, on
images in [0, 1] (data range 1). No-reference (real recordings without ground
truth): :func:`entropy_2d`, re-exported from
:mod:`wgse_mmseg.evaluation.quality`, the one home of the no-reference measures
(with NIQE and BRISQUE).

Every function takes ``(H, W)`` arrays: float in [0, 1], or ``uint8`` (read
as ``value / 255``).
"""
import cv2
import numpy as np

from ...argument_checks import check_integer, check_number
from ...limits import MAX_IMAGE_SIDE
from ..quality import as_unit_grey, entropy_2d

__all__ = ['psnr', 'ssim', 'entropy_2d']

#: SSIM constants of Wang et al. (2004) for data range 1.
_K1, _K2 = 0.01, 0.03


def _pair(pred, gt):
    pred, gt = as_unit_grey(pred, 'pred'), as_unit_grey(gt, 'gt')
    if pred.shape != gt.shape:
        raise ValueError(f'pred {pred.shape} and gt {gt.shape} differ in size')
    return pred, gt


def psnr(pred, gt) -> float:
    """Peak signal-to-noise ratio in dB for data range 1 (inf if equal)."""
    pred, gt = _pair(pred, gt)
    mse = np.mean((pred - gt) ** 2)
    return float('inf') if mse == 0 else float(10 * np.log10(1.0 / mse))


def _check_window(entry: str, size: int, sigma: float) -> None:
    """The window of :func:`ssim` and :func:`gaussian_window`: an odd side
    (a centred window) and a finite standard deviation > 0."""
    check_integer(entry, 'size', size, 1, MAX_IMAGE_SIDE, odd=True)
    check_number(entry, 'sigma', sigma, 0, MAX_IMAGE_SIDE,
                 strict_minimum=True)


def gaussian_window(size: int = 11, sigma: float = 1.5) -> np.ndarray:
    """``(size, size)`` Gaussian weights summing to 1 (MATLAB ``fspecial``)."""
    _check_window('gaussian_window', size, sigma)
    return _gaussian_window(size, sigma)


def _gaussian_window(size: int, sigma: float) -> np.ndarray:
    """:func:`gaussian_window`, its arguments checked."""
    axis = np.arange(size, dtype=np.float64) - (size - 1) / 2
    with np.errstate(over='ignore'):  # a tiny sigma: weight 0 off centre
        g = np.exp(-0.5 * (axis / sigma) ** 2)
    g /= g.sum()
    return np.outer(g, g)


def ssim(pred, gt, size: int = 11, sigma: float = 1.5) -> float:
    """Mean structural similarity (Wang et al., 2004), data range 1.

    The usual definition: local means, variances and covariance weighted by
    an 11x11 Gaussian (sigma 1.5), ``K1 = 0.01``, ``K2 = 0.03``, population
    (not sample) statistics, averaged over the windows that lie inside the
    image ('valid'); equals ``skimage.metrics.structural_similarity(...,
    gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
    data_range=1)``. ``size`` (odd, >= 1) and ``sigma`` (finite, > 0)
    are checked: an error naming the parameter.
    """
    _check_window('ssim', size, sigma)
    pred, gt = _pair(pred, gt)
    if min(pred.shape) < size:
        raise ValueError(f'SSIM needs images of at least {size}x{size}, got '
                         f'{pred.shape[0]}x{pred.shape[1]}')
    window = _gaussian_window(size, sigma)
    pad = size // 2

    def local_mean(x):
        return cv2.filter2D(x, cv2.CV_64F, window,
                            borderType=cv2.BORDER_REFLECT)[
                                pad:x.shape[0] - pad, pad:x.shape[1] - pad]

    c1, c2 = _K1 ** 2, _K2 ** 2
    mu_x, mu_y = local_mean(pred), local_mean(gt)
    var_x = local_mean(pred * pred) - mu_x ** 2
    var_y = local_mean(gt * gt) - mu_y ** 2
    cov = local_mean(pred * gt) - mu_x * mu_y
    ssim_map = ((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / (
        (mu_x ** 2 + mu_y ** 2 + c1) * (var_x + var_y + c2))
    return float(ssim_map.mean())
