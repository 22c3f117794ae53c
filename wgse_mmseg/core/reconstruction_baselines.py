"""Classical image reconstruction from a spike window: TFP and TFI images.

Both read a window of spikes ``(T, H, W)`` (0/1) and return the grey image
``(H, W)`` float64 in [0, 1] at the window's centre frame ``T // 2``. They
are the representations of :mod:`wgse_mmseg.core.representations` (one
definition of each) read at that frame and put on the REDS intensity scale
of the reconstruction literature (``../shared/README.md``): a white pixel
fires ``white_rate = 0.6`` spikes per readout step, so "spike rate / 0.6 is
the image". The package's simulator produces the same scale with
``threshold = 1 / white_rate``.

* :func:`tfp`: :class:`~wgse_mmseg.core.representations.TFP` over the whole
  window (its spike rate) / ``white_rate``;
* :func:`tfi`: :class:`~wgse_mmseg.core.representations.TFI` at the centre
  frame (``1 / ISI``, with its conventions where the window cuts the
  interval) / ``white_rate``;
* :func:`tfi_spatial_mean`, :func:`tfi_temporal_mean`: TFI denoised by the
  mean filters (:class:`~wgse_mmseg.core.representations.SpatialMeanFilter`
  over ``k x k`` pixels at the centre frame,
  :class:`~wgse_mmseg.core.representations.TemporalMeanFilter` over the
  ``k`` steps around it): sharper than TFP, less noisy than TFI.
"""
import numpy as np
import torch

from ..argument_checks import check_integer, check_number
from .constants import REDS_WHITE_RATE
from .representations import (TFI, TFP, SpatialMeanFilter,
                              TemporalMeanFilter)

__all__ = ['tfp', 'tfi']


def _check(entry: str, spikes, white_rate) -> torch.Tensor:
    """``(1, T, H, W)`` float64 from ``entry``'s ``(T, H, W)`` array, and
    its white rate checked."""
    check_number(entry, 'white_rate', white_rate, 0, strict_minimum=True)
    spikes = np.asarray(spikes)
    if spikes.ndim != 3 or 0 in spikes.shape:
        raise ValueError(
            f'{entry}: spikes must be a non-empty (T, H, W) array, got shape '
            f'{spikes.shape}')
    return torch.from_numpy(spikes.astype(np.float64))[None]


def _image(rates: torch.Tensor, white_rate: float) -> np.ndarray:
    """The centre frame of ``(1, T, H, W)`` rates on the REDS scale."""
    centre = rates[0, rates.shape[1] // 2].numpy()
    return np.clip(centre / white_rate, 0.0, 1.0)


def tfp(spikes, white_rate: float = REDS_WHITE_RATE) -> np.ndarray:
    """Window average: ``(T, H, W)`` spikes -> ``(H, W)`` image in [0, 1].

    ``mean_t(spikes) / white_rate``, clipped to [0, 1]: TFP with a window
    that covers the whole clip at its centre frame.
    """
    stream = _check('tfp', spikes, white_rate)
    steps = stream.shape[1]
    window = steps if steps % 2 else steps + 1  # odd, reaches both ends
    return _image(TFP(window=window)(stream), white_rate)


def tfi(spikes, white_rate: float = REDS_WHITE_RATE) -> np.ndarray:
    """Inter-spike interval at the centre: ``(T, H, W)`` -> ``(H, W)``.

    :class:`~wgse_mmseg.core.representations.TFI` at frame ``T // 2`` over
    ``white_rate``, clipped to [0, 1]: ``1 / (ISI * white_rate)`` where the
    interval runs from the last spike at or before the centre to the first
    after it. Where the window cuts that interval, TFI's conventions hold:
    the nearest complete interval stands in; a pixel with fewer than two
    spikes in the window takes its spike count / ``T`` as its rate.
    """
    return _image(TFI()(_check('tfi', spikes, white_rate)), white_rate)


def tfi_spatial_mean(spikes, kernel_size: int = 3,
                     white_rate: float = REDS_WHITE_RATE) -> np.ndarray:
    """TFI, then the mean over ``kernel_size x kernel_size`` pixels:
    ``(T, H, W)`` -> ``(H, W)`` in [0, 1].

    :class:`~wgse_mmseg.core.representations.SpatialMeanFilter` of the TFI
    rates (at the borders, the mean of the pixels inside the image) at frame
    ``T // 2``, over ``white_rate``, clipped.
    """
    check_integer('tfi_spatial_mean', 'kernel_size', kernel_size, 1,
                  odd=True)
    rates = TFI()(_check('tfi_spatial_mean', spikes, white_rate))
    return _image(SpatialMeanFilter(kernel_size)(rates), white_rate)


def tfi_temporal_mean(spikes, kernel_size: int = 9,
                      white_rate: float = REDS_WHITE_RATE) -> np.ndarray:
    """TFI, then the mean over the ``kernel_size`` steps centred on frame
    ``T // 2`` (cut to the window): ``(T, H, W)`` -> ``(H, W)`` in [0, 1].

    :class:`~wgse_mmseg.core.representations.TemporalMeanFilter` of the TFI
    rates at frame ``T // 2``, over ``white_rate``, clipped.
    """
    check_integer('tfi_temporal_mean', 'kernel_size', kernel_size, 1,
                  odd=True)
    rates = TFI()(_check('tfi_temporal_mean', spikes, white_rate))
    return _image(TemporalMeanFilter(kernel_size)(rates), white_rate)
