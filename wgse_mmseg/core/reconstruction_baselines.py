"""Classical image reconstruction from a spike window: TFP and TFI.

Both read a window of spikes ``(T, H, W)`` (0/1) and return the grey image
``(H, W)`` float64 in [0, 1] at the window's centre frame ``T // 2``.

The intensity scale follows the REDS convention of the reconstruction
literature (``../shared/README.md``): a white pixel fires ``white_rate = 0.6``
spikes per readout step, so "spike rate / 0.6 is the image". The package's
simulator produces the same scale with ``threshold = 1 / white_rate``.

* TFP (texture from playback): the window's spike rate / ``white_rate``.
* TFI (texture from inter-spike intervals): ``1 / (ISI * white_rate)``,
  where ISI is the interval between the last spike at or before the centre
  frame and the first spike after it.
"""
import numpy as np

from .constants import REDS_WHITE_RATE

__all__ = ['tfp', 'tfi']


def _check(spikes, white_rate: float) -> np.ndarray:
    spikes = np.asarray(spikes)
    if spikes.ndim != 3 or 0 in spikes.shape:
        raise ValueError(
            f'spikes must be a non-empty (T, H, W) array, got shape '
            f'{spikes.shape}')
    if white_rate <= 0:
        raise ValueError(f'white_rate must be > 0, got {white_rate}')
    return spikes


def tfp(spikes, white_rate: float = REDS_WHITE_RATE) -> np.ndarray:
    """Window average: ``(T, H, W)`` spikes -> ``(H, W)`` image in [0, 1].

    ``mean_t(spikes) / white_rate``, clipped to [0, 1].
    """
    spikes = _check(spikes, white_rate)
    rate = spikes.mean(axis=0, dtype=np.float64)
    return np.clip(rate / white_rate, 0.0, 1.0)


def tfi(spikes, white_rate: float = REDS_WHITE_RATE) -> np.ndarray:
    """Inter-spike interval at the centre: ``(T, H, W)`` -> ``(H, W)``.

    With ``c = T // 2``, ``prev`` the last spike frame ``<= c`` and ``next``
    the first spike frame ``> c``, the image is
    ``1 / ((next - prev) * white_rate)``, clipped to [0, 1]. A pixel with no
    spike before (after) the centre inside the window takes ``prev = -1``
    (``next = T``): the interval is at least that long, so the value is an
    upper bound (0 spikes in the window gives ``1 / ((T + 1) * white_rate)``).
    """
    spikes = _check(spikes, white_rate).astype(bool)
    steps = spikes.shape[0]
    center = steps // 2
    frames = np.arange(steps).reshape(-1, 1, 1)
    before = spikes[:center + 1]
    after = spikes[center + 1:]
    prev = np.where(before, frames[:center + 1], -1).max(axis=0)
    if after.shape[0]:
        nxt = np.where(after, frames[center + 1:], steps).min(axis=0)
    else:
        nxt = np.full(prev.shape, steps)
    interval = (nxt - prev).astype(np.float64)
    return np.clip(1.0 / (interval * white_rate), 0.0, 1.0)
