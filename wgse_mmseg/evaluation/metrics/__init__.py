"""Reconstruction quality: PSNR, SSIM, 2-D entropy (:mod:`.image_quality`)
and the registered ``ReconstructionMetric``."""
from .image_quality import entropy_2d, gaussian_window, psnr, ssim
from .reconstruction_metric import ReconstructionMetric

__all__ = ['ReconstructionMetric', 'psnr', 'ssim', 'entropy_2d']
