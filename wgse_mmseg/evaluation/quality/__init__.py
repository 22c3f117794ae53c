"""No-reference image quality: the measures for reconstructions of real
recordings, which have no ground truth. Needs numpy and OpenCV only.

* :func:`~.niqe.niqe`: NIQE (lower is better), as the authors' MATLAB
  release and basicsr 1.4.2 compute it;
* :func:`~.brisque.brisque`: BRISQUE (lower is better), as the brisque 0.2.0
  package computes it;
* :func:`~.entropy.entropy_2d`: two-dimensional entropy in bits (higher
  means more detail);
* :func:`~.no_reference.no_reference_scores`: all three of one image.

Each takes an ``(H, W)`` grey image of any kind
:mod:`wgse_mmseg.core.image_values` accepts (bool, 8 or 16 bits, float in
[0, 1]) and scores it as shown, in 8 bits, within the memory its docstring
states (bytes per pixel, measured by ``tests/core/test_images.py``). The model
data NIQE and BRISQUE need ships in ``data/`` (:mod:`.model_data`). The
full-reference measures (PSNR, SSIM) are the MMSeg layer's
(:mod:`wgse_mmseg.evaluation.metrics.image_quality`).
"""
from .brisque import brisque
from .entropy import entropy_2d
from ...core.image_values import as_grey_levels, as_unit_grey
from .niqe import niqe
from .no_reference import NO_REFERENCE_METRICS, no_reference_scores

__all__ = ['entropy_2d']
