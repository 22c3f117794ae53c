"""Two-dimensional image entropy, a no-reference measure of detail."""
import cv2
import numpy as np

from .grey import as_grey_levels

__all__ = ['entropy_2d']


def entropy_2d(image) -> float:
    """Two-dimensional image entropy in bits of an ``(H, W)`` image (no
    reference needed).

    The joint distribution of each pixel's 8-bit grey level ``i`` and the
    mean ``j`` of its 3x3 neighbourhood (reflected at the border, rounded to
    8 bits): ``-sum p(i, j) log2 p(i, j)``. Between 0 (flat) and 16 bits;
    higher means more detail (noise counts as detail too, so compare
    reconstructions of the same recording).
    """
    grey = as_grey_levels(image)
    neighbourhood = cv2.blur(grey, (3, 3), borderType=cv2.BORDER_REFLECT)
    joint = grey.astype(np.int64) * 256 + np.round(neighbourhood).astype(
        np.int64)
    counts = np.bincount(joint.ravel(), minlength=256 * 256)
    p = counts[counts > 0] / joint.size
    return float(-(p * np.log2(p)).sum())
