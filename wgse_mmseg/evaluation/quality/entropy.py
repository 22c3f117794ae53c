"""Two-dimensional image entropy, a no-reference measure of detail."""
import numpy as np

from ...core.image_values import as_grey_levels, row_blocks

__all__ = ['entropy_2d']


def _joint_codes(levels: np.ndarray, first: int,
                 stop: int) -> np.ndarray:
    """``256 * i + j`` (``uint16``) of rows ``first:stop`` of ``levels``:
    each pixel's level ``i`` and the rounded mean ``j`` of its 3x3
    neighbourhood (the border reflected: for one pixel the edge repeats).
    The 3x3 sum is an integer (at most 2295); ``round(sum / 9)`` is
    ``(2 * sum + 9) // 18`` exactly, as ``sum / 9`` is never halfway."""
    index = np.arange(first, stop)
    rows = levels[index].astype(np.uint16)  # the vertical 3-sums
    rows += levels[np.maximum(index - 1, 0)]
    rows += levels[np.minimum(index + 1, levels.shape[0] - 1)]
    sums = rows.copy()  # plus the left and right neighbours' sums
    sums[:, 1:] += rows[:, :-1]
    sums[:, :1] += rows[:, :1]
    sums[:, :-1] += rows[:, 1:]
    sums[:, -1:] += rows[:, -1:]
    sums *= 2
    sums += 9
    sums //= 18
    sums += levels[first:stop].astype(np.uint16) << 8
    return sums


def entropy_2d(image) -> float:
    """Two-dimensional image entropy in bits of an ``(H, W)`` image (no
    reference needed; bool, 8 or 16 bits, or float in [0, 1], scored as
    8 bits).

    The joint distribution of each pixel's 8-bit grey level ``i`` and the
    mean ``j`` of its 3x3 neighbourhood (reflected at the border, rounded to
    8 bits): ``-sum p(i, j) log2 p(i, j)``. Between 0 (flat) and 16 bits;
    higher means more detail (noise counts as detail too, so compare
    reconstructions of the same recording).

    Memory: the 8-bit image (1 byte per pixel; none for a ``uint8`` image)
    and, per block of rows,
    the integer 3x3 sums and the joint codes, counted into one 256x256
    histogram: at most 2 bytes per pixel beyond the input plus a fixed
    working set, whatever the size.
    """
    levels = as_grey_levels(image)
    counts = np.zeros(256 * 256, np.int64)
    for first, stop in row_blocks(*levels.shape):
        counts += np.bincount(_joint_codes(levels, first, stop).ravel(),
                              minlength=256 * 256)
    p = counts[counts > 0] / levels.size
    return float(-(p * np.log2(p)).sum())
