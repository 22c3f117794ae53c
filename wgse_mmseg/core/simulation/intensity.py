"""Input frames to light intensity in [0, 1]."""
import numpy as np
import torch

__all__ = []

# ITU-R BT.601 luma weights of R, G, B.
_LUMA = (0.299, 0.587, 0.114)


def frames_to_intensity(frames, dtype: torch.dtype = torch.float64,
                        device='cpu') -> torch.Tensor:
    """``(N, H, W)`` or ``(N, H, W, 3)`` frames to ``(N, H, W)`` intensity.

    Args:
        frames: ``uint8`` (divided by 255) or float in [0, 1]; colour
            frames are RGB and become luma (BT.601 weights). A NumPy array,
            a CPU tensor or anything ``np.asarray`` takes.
        dtype: floating dtype of the result.
        device: device of the result.

    Returns:
        ``(N, H, W)`` tensor in [0, 1]. Colour frames are converted one at a
        time, so no float copy of all ``3 N`` planes is made.

    Raises:
        ValueError: for another shape or dtype, an empty array, or float
            values outside [0, 1] (NaN included).
    """
    array = np.asarray(frames)
    shape = array.shape
    if not (array.ndim == 3 or (array.ndim == 4 and shape[-1] == 3)) \
            or 0 in shape:
        raise ValueError(
            f'frames must be a non-empty (N, H, W) or (N, H, W, 3) array '
            f'(a single image needs a leading axis of 1), got shape {shape}')
    if array.dtype != np.uint8 and not np.issubdtype(array.dtype,
                                                     np.floating):
        raise ValueError(
            f'frames must be uint8 or float in [0, 1], got dtype '
            f'{array.dtype}')
    full_scale = 255 if array.dtype == np.uint8 else 1
    if full_scale == 1:
        low, high = array.min(), array.max()
        if not (low >= 0 and high <= 1):  # also catches NaN
            raise ValueError(
                f'float frames must lie in [0, 1], got values in '
                f'[{low:g}, {high:g}]')
    intensity = torch.empty(shape[:3], dtype=dtype, device=device)
    luma = torch.tensor(_LUMA, dtype=dtype, device=device)
    for index, frame in enumerate(array):
        plane = torch.from_numpy(np.ascontiguousarray(frame)).to(
            device=device, dtype=dtype)
        if plane.dim() == 3:  # the weights sum to 1 up to rounding
            plane = (plane @ luma).clamp_(max=full_scale)
        torch.div(plane, full_scale, out=intensity[index])
    return intensity
