"""Metrics beyond MMSeg's: reconstruction quality (PSNR, SSIM, 2-D entropy)."""
from .._openmmlab import require_openmmlab

require_openmmlab('wgse_mmseg.evaluation')

from .image_quality import entropy_2d, gaussian_window, psnr, ssim  # noqa: E402
from .reconstruction_metric import ReconstructionMetric  # noqa: E402

__all__ = ['ReconstructionMetric', 'psnr', 'ssim', 'entropy_2d',
           'gaussian_window']
