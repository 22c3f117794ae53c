"""All no-reference measures of one image, for the reports of real
recordings (``tools/misc/reconstruct.py``, the reconstruction benchmark)."""
from typing import Dict, Optional

from .brisque import brisque
from .entropy import entropy_2d
from ...core.image_values import as_grey_levels
from .niqe import niqe

__all__ = []

#: name -> measure; NIQE and BRISQUE: lower is better, Entropy2D: higher
NO_REFERENCE_METRICS = {'NIQE': niqe, 'BRISQUE': brisque,
                        'Entropy2D': entropy_2d}


def no_reference_scores(image) -> Dict[str, Optional[float]]:
    """``{'NIQE', 'BRISQUE', 'Entropy2D'}`` of an ``(H, W)`` grey image;
    ``None`` for a measure the image is too small or too flat for (the
    measure's ``ValueError`` says which). A malformed image (not ``(H, W)``,
    not an accepted kind: :mod:`wgse_mmseg.core.image_values`) raises
    ``ValueError``."""
    levels = as_grey_levels(image)  # a malformed image is an error, not
    scores = {}  # a None; each measure scores these 8 bits
    for name, measure in NO_REFERENCE_METRICS.items():
        try:
            scores[name] = measure(levels)
        except ValueError:
            scores[name] = None
    return scores
