"""Input frames to light intensity in [0, 1]."""
import numpy as np
import torch

from ..image_values import check_unit_range, full_scale

__all__ = []

# ITU-R BT.601 luma weights of R, G, B.
_LUMA = (0.299, 0.587, 0.114)


def frames_to_intensity(frames, dtype: torch.dtype = torch.float64,
                        device='cpu') -> torch.Tensor:
    """``(N, H, W)`` or ``(N, H, W, 3)`` frames to ``(N, H, W)`` intensity.

    Args:
        frames: any image kind :mod:`wgse_mmseg.core.image_values` accepts
            (``bool``, ``uint8``, ``uint16``, float in [0, 1]); colour
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
    white = full_scale(array.dtype, 'frames')
    if np.issubdtype(array.dtype, np.floating):
        check_unit_range(array, 'frames')
    intensity = torch.empty(shape[:3], dtype=dtype, device=device)
    luma = torch.tensor(_LUMA, dtype=dtype, device=device)
    for index, frame in enumerate(array):
        plane = torch.from_numpy(np.ascontiguousarray(frame)).to(
            device=device, dtype=dtype)
        if plane.dim() == 3:  # the weights sum to 1 up to rounding
            plane = (plane @ luma).clamp_(max=white)
        torch.div(plane, white, out=intensity[index])
    return intensity
