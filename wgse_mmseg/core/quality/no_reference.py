"""All no-reference measures of one image, for the reports of real
recordings (``tools/misc/reconstruct.py``, the reconstruction benchmark)."""
from typing import Dict, Optional

from .brisque import brisque
from .entropy import entropy_2d
from .grey import as_unit_grey
from .niqe import niqe

__all__ = []

#: name -> measure; NIQE and BRISQUE: lower is better, Entropy2D: higher
NO_REFERENCE_METRICS = {'NIQE': niqe, 'BRISQUE': brisque,
                        'Entropy2D': entropy_2d}


def no_reference_scores(image) -> Dict[str, Optional[float]]:
    """``{'NIQE', 'BRISQUE', 'Entropy2D'}`` of an ``(H, W)`` grey image;
    ``None`` for a measure the image is too small or too flat for (the
    measure's ``ValueError`` says which). A malformed image (not ``(H, W)``,
    not finite) raises ``ValueError``."""
    as_unit_grey(image)  # a malformed image is an error, not a None
    scores = {}
    for name, measure in NO_REFERENCE_METRICS.items():
        try:
            scores[name] = measure(image)
        except ValueError:
            scores[name] = None
    return scores
