"""Metrics beyond MMSeg's: reconstruction quality (PSNR, SSIM, 2-D entropy)."""
from ..openmmlab_stack import check_mmseg_layer

check_mmseg_layer('wgse_mmseg.evaluation')

from .metrics import (ReconstructionMetric, entropy_2d,  # noqa: E402
                      gaussian_window, psnr, ssim)

__all__ = ['ReconstructionMetric', 'psnr', 'ssim', 'entropy_2d']
