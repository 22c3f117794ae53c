from . import reconstruction, representations  # noqa: F401  (registers)
from .data_preprocessor import SpikeSegDataPreProcessor
from .wgse import WGSE, BandNetwork

__all__ = ['WGSE', 'BandNetwork', 'SpikeSegDataPreProcessor']
