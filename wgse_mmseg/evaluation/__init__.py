"""Metrics beyond MMSeg's: reconstruction quality (PSNR, SSIM, 2-D entropy)."""
from .image_quality import entropy_2d, gaussian_window, psnr, ssim
from .reconstruction_metric import ReconstructionMetric

__all__ = ['ReconstructionMetric', 'psnr', 'ssim', 'entropy_2d',
           'gaussian_window']
