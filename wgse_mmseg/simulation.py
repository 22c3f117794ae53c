"""Spike-camera simulation: integrate-and-fire on per-readout light intensity.

The model of the paper (Eq. 1): each pixel integrates ``gain * I(t)`` per
readout step (25 us at 40 kHz); when the charge reaches ``threshold`` the
pixel fires one spike at that readout and the threshold is subtracted, so no
charge is lost. The initial charge is uniform in ``[0, threshold)``, as on a
camera that has been running. A pixel fires at most once per readout.

A light intensity of 1.0 (white) with the default gain fires on average
``1 / threshold`` spikes per step; the REDS convention (white fires 0.6 per
step) is ``threshold = 1 / 0.6``.

Video frames are resampled to readout steps by linear interpolation in
time; a single frame is a static scene.
"""
from typing import Dict, Tuple

import numpy as np
import torch

__all__ = ['simulate_spikes', 'frames_to_intensity']

_LUMA = (0.299, 0.587, 0.114)


def frames_to_intensity(frames) -> torch.Tensor:
    """``(N, H, W)`` or ``(N, H, W, 3)`` frames to ``(N, H, W)`` float64 in [0, 1].

    ``uint8`` frames are divided by 255; float frames must lie in [0, 1].
    Colour frames become luma (ITU-R BT.601 weights).
    """
    array = np.asarray(frames)
    intensity = torch.from_numpy(array.astype(np.float64))
    if intensity.dim() == 4 and intensity.shape[-1] == 3:
        intensity = intensity @ torch.tensor(_LUMA, dtype=torch.float64)
    if intensity.dim() != 3:
        raise ValueError(
            f'frames must be (N, H, W) or (N, H, W, 3), got {array.shape}')
    if array.dtype == np.uint8:
        return intensity / 255.0
    if intensity.numel() and (intensity.min() < 0 or intensity.max() > 1):
        raise ValueError('float frames must lie in [0, 1]')
    return intensity


def _resample(intensity: torch.Tensor, num_steps: int) -> torch.Tensor:
    """Linear interpolation of ``(N, H, W)`` frames to ``num_steps`` steps."""
    count = intensity.shape[0]
    if count == 1:
        return intensity.expand(num_steps, *intensity.shape[1:])
    position = torch.linspace(0, count - 1, num_steps, dtype=torch.float64)
    lower = position.floor().long().clamp(max=count - 2)
    frac = (position - lower).view(-1, 1, 1)
    return intensity[lower] * (1 - frac) + intensity[lower + 1] * frac


def simulate_spikes(frames, num_steps: int, threshold: float = 1.0,
                    gain: float = 1.0, seed: int = 0,
                    device: str = 'cpu') -> Tuple[np.ndarray, Dict]:
    """Simulate a spike stream from video frames.

    Args:
        frames: ``(N, H, W)`` or ``(N, H, W, 3)``, ``uint8`` or float in
            [0, 1]; ``N >= 1`` frames spread evenly over the stream.
        num_steps: readout steps ``T`` to simulate.
        threshold: firing threshold in units of full-scale light per step.
        gain: the ``alpha`` of Eq. 1 (charge per step at intensity 1).
        seed: seeds the random initial charge; same seed, same stream.
        device: torch device for the integration.

    Returns:
        ``(spikes, meta)``: ``(T, H, W)`` ``uint8`` 0/1 spikes and a dict
        describing the simulation that ran.
    """
    if num_steps < 1:
        raise ValueError(f'num_steps must be >= 1, got {num_steps}')
    if threshold <= 0 or gain < 0:
        raise ValueError(
            f'threshold must be > 0 and gain >= 0, got {threshold}, {gain}')
    intensity = _resample(frames_to_intensity(frames), num_steps).to(device)
    generator = torch.Generator(device='cpu').manual_seed(seed)
    charge = (torch.rand(intensity.shape[1:], generator=generator,
                         dtype=torch.float64) * threshold).to(device)
    spikes = torch.empty(intensity.shape, dtype=torch.uint8, device=device)
    for step in range(num_steps):
        charge += gain * intensity[step]
        fired = charge >= threshold
        charge -= threshold * fired
        spikes[step] = fired
    meta = dict(model='integrate-and-fire', num_steps=num_steps,
                threshold=threshold, gain=gain, seed=seed,
                num_frames=int(np.shape(frames)[0]), effects={})
    return spikes.cpu().numpy(), meta
